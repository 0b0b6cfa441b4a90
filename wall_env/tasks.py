"""The tasks: scene and reference of each environment id, as functions of the stand-off.

All wall tasks put one wall in the plane x = 0 with its outward normal +x (free space
at x > 0); the vehicle faces the wall (yaw = pi, body x toward the wall), so rotors 0
and 3 are the near pair. ``standoff`` is the distance from the wall to the reference
position of the centre of mass; with the default vehicle the near rotor centres are
``standoff - 0.0707`` m from the wall and the ducts touch the wall at
``standoff - 0.0707 - 0.04`` m.

The corridor has two walls at y = -standoff and y = +standoff, normals pointing
inward; the vehicle flies along +x with yaw 0, its left and right rotor pairs each
near one wall.

Two tasks fly along real structures, built of boxes and a cylinder (:mod:`wall_env.bodies`),
whose suction each rotor reads from its nearest surfaces (:mod:`wall_env.surfaces`):

* **Facade**: a 7 m wide, 4.5 m high facade, its face in the plane x = 0 (outward +x),
  with two window recesses (0.9 m wide, 1.2 m high, 0.2 m deep, centred at y = -1.2 and
  +1.2 m, sills at 0.9 m) and a ledge along its whole width (0.15 m deep, 0.12 m thick,
  its top at 2.72 m). The inspection path faces the facade (yaw = pi): along +y at the
  stand-off and ``altitude`` past both windows, out by 0.3 m, up to 0.09 m above the ledge,
  in to the stand-off, and back along -y over the ledge, each leg rest to rest. Over a
  window the near rotors lose the facade; at the jambs they feel the edges; over the ledge
  they feel the facade and the ledge top at once, and the far rotors are past the ledge's
  front edge.
* **Pier**: a bridge pier, a vertical cylinder of 0.5 m radius and 8 m height on the
  ground at the origin; the path is a horizontal circle about its axis at the stand-off
  from its surface (a lap in ``period``), the heading fixed (yaw = pi), so the rotors that
  face the pier change around the circle (a pair, then one on the diagonal).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wall_env.bodies import Box, Cylinder
from wall_env.references import CircleReference, CorridorReference, HoverReference, Reference, SweepReference, WaypointReference
from wall_env.scene import Scene, Wall
from wall_env.validation import check_range
from wall_env.vehicle import VehicleParams

__all__ = ["TaskSpec", "TaskParameter", "TASKS", "min_standoff", "task_name", "task_env_id", "task_slug"]

_WALL = Wall(point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0))
_FACE_WALL = math.pi


def min_standoff(vehicle: VehicleParams, body_axis: int | None, margin: float = 0.005) -> float:
    """Smallest centre-of-mass distance (m) at which no duct touches a wall that body axis
    ``body_axis`` (0 = x, 1 = y; ``None``: any horizontal direction) points at, with the vehicle level."""
    rotors = vehicle.rotor_positions_array
    if body_axis is None:
        reach = float(np.max(np.linalg.norm(rotors[:, :2], axis=1)))
    else:
        reach = float(np.max(np.abs(rotors[:, body_axis])))
    return reach + vehicle.duct_radius + margin


@dataclass(frozen=True)
class TaskParameter:
    """A named shape parameter of a task's reference (the env's ``task_params`` keyword sets it)."""

    name: str
    default: float
    low: float
    high: float
    unit: str
    description: str


@dataclass(frozen=True)
class TaskSpec:
    """How one task builds its scene and reference.

    ``closest_approach`` is how much nearer to a wall than ``standoff`` the reference
    goes (the sweep's approach, the corridor's weave); the stand-off is checked so
    that even then the ducts stay off the wall.
    """

    name: str
    description: str
    standoff: float  # m, default
    altitude: float  # m, default height of the reference
    duration: float  # s, default episode length
    closest_approach: float  # m
    wall_axis: int | None  # body axis (0 = x, 1 = y) that points at the wall(s) on the reference heading; None: any
    start_position_noise: float  # m, half-width of the uniform start perturbation per axis
    start_velocity_noise: float  # m/s
    start_attitude_noise: float  # rad, roll/pitch/yaw
    build: Callable[..., tuple[Scene, Reference]]  # (standoff, altitude, duration, base scene, **parameters)
    parameters: tuple[TaskParameter, ...] = ()
    altitude_range: tuple[float, float] = (0.1, 100.0)  # m, the altitudes the task's path allows

    def check_params(self, values: dict[str, float] | None) -> dict[str, float]:
        """Every parameter of the task, ``values`` over the defaults; ``ValueError`` naming a bad one."""
        known = {p.name: p for p in self.parameters}
        if values is not None and not isinstance(values, dict):
            raise ValueError(f"task_params must be a dict, got {type(values).__name__}")
        unknown = sorted(set(values or {}) - set(known))
        if unknown:
            raise ValueError(f"unknown task_params key(s) {unknown} for {self.name}; allowed: {sorted(known)}")
        out = {}
        for name, p in known.items():
            out[name] = check_range(f"task_params[{name!r}]", (values or {}).get(name, p.default), p.low, p.high)
        return out

    def scene_and_reference(self, standoff: float, altitude: float, duration: float, base: Scene,
                            params: dict[str, float] | None = None) -> tuple[Scene, Reference]:
        return self.build(standoff, altitude, duration, base, **self.check_params(params))


def _single_wall(ground_scene: Scene) -> Scene:
    return Scene((_WALL,), ground_scene.ground_z, ground_scene.ceiling_z)


def _hover(standoff: float, altitude: float, duration: float, base: Scene) -> tuple[Scene, Reference]:
    return _single_wall(base), HoverReference((standoff, 0.0, altitude), duration, _FACE_WALL)


def _circle(standoff: float, altitude: float, duration: float, base: Scene, radius: float,
            period: float) -> tuple[Scene, Reference]:
    ref = CircleReference((standoff, 0.0, altitude), duration, _FACE_WALL, radius=radius, period=period,
                          axis_u=(0.0, 1.0, 0.0), axis_w=(0.0, 0.0, 1.0), ramp_time=1.0)
    return _single_wall(base), ref


def _sweep(standoff: float, altitude: float, duration: float, base: Scene) -> tuple[Scene, Reference]:
    ref = SweepReference((standoff, 0.0, altitude), duration, _FACE_WALL, wall_normal=(1.0, 0.0, 0.0),
                         approach=0.1, leg_speeds=(0.25, -0.5, 0.5, -0.25), leg_duration=4.0, settle=1.0)
    return _single_wall(base), ref


def _corridor(standoff: float, altitude: float, duration: float, base: Scene) -> tuple[Scene, Reference]:
    walls = (Wall((0.0, -standoff, 0.0), (0.0, 1.0, 0.0)), Wall((0.0, standoff, 0.0), (0.0, -1.0, 0.0)))
    ref = CorridorReference((-2.0, 0.0, altitude), duration, 0.0, direction=(1.0, 0.0, 0.0),
                            lateral=(0.0, 1.0, 0.0), speed=0.4, weave_amplitude=0.05, weave_period=4.0,
                            ramp_time=1.0)
    return Scene(walls, base.ground_z, base.ceiling_z), ref


# ---------------------------------------------------------------- structures (bodies)
FACADE_THICKNESS = 0.3  # m
FACADE_WIDTH = 7.0  # m, along y, centred on y = 0
FACADE_HEIGHT = 4.5  # m
WINDOW_CENTRES = (-1.2, 1.2)  # m, along y
WINDOW_SIZE = (0.9, 1.2)  # m, width (y) and height (z)
WINDOW_SILL = 0.9  # m
WINDOW_DEPTH = 0.2  # m, face to glass
LEDGE_DEPTH = 0.15  # m, out of the face
LEDGE_THICKNESS = 0.12  # m
LEDGE_TOP = 2.72  # m
LEDGE_CLEARANCE = 0.09  # m, centre of mass above the ledge top on the upper pass
FACADE_PASS = 2.2  # m, the passes run from y = -FACADE_PASS to +FACADE_PASS
FACADE_STEP_OUT = 0.3  # m, how far the path leaves the stand-off to pass the ledge's front
PIER_RADIUS = 0.5  # m
PIER_HEIGHT = 8.0  # m


def _box(x: tuple[float, float], y: tuple[float, float], z: tuple[float, float]) -> Box:
    """An axis-aligned box between the given ranges (m)."""
    return Box((x[1] - x[0], y[1] - y[0], z[1] - z[0]), ((x[0] + x[1]) / 2, (y[0] + y[1]) / 2, (z[0] + z[1]) / 2))


def facade_bodies() -> tuple[Box, ...]:
    """The facade of ``Facade-v0`` as boxes: wall bands around two window recesses, the recesses' backs, a ledge."""
    x_wall = (-FACADE_THICKNESS, 0.0)
    half = FACADE_WIDTH / 2
    top = WINDOW_SILL + WINDOW_SIZE[1]
    edges = [-half]
    for centre in WINDOW_CENTRES:
        edges += [centre - WINDOW_SIZE[0] / 2, centre + WINDOW_SIZE[0] / 2]
    edges.append(half)
    bodies = [_box(x_wall, (-half, half), (0.0, WINDOW_SILL)), _box(x_wall, (-half, half), (top, FACADE_HEIGHT))]
    bodies += [_box(x_wall, (edges[k], edges[k + 1]), (WINDOW_SILL, top)) for k in range(0, len(edges), 2)]
    bodies += [_box((-FACADE_THICKNESS, -WINDOW_DEPTH), (edges[k], edges[k + 1]), (WINDOW_SILL, top))
               for k in range(1, len(edges) - 1, 2)]
    bodies.append(_box((0.0, LEDGE_DEPTH), (-half, half), (LEDGE_TOP - LEDGE_THICKNESS, LEDGE_TOP)))
    return tuple(bodies)


def _facade(standoff: float, altitude: float, duration: float, base: Scene, leg_time: float
            ) -> tuple[Scene, Reference]:
    upper = LEDGE_TOP + LEDGE_CLEARANCE
    out = FACADE_STEP_OUT
    waypoints = ((0.0, -FACADE_PASS, altitude), (0.0, FACADE_PASS, altitude), (out, FACADE_PASS, altitude),
                 (out, FACADE_PASS, upper), (0.0, FACADE_PASS, upper), (0.0, -FACADE_PASS, upper))
    ref = WaypointReference((standoff, 0.0, 0.0), duration, _FACE_WALL, waypoints=waypoints,
                            leg_times=(leg_time, 2.0, 3.0, 2.0, leg_time), settle=1.0)
    return Scene(base.walls, base.ground_z, base.ceiling_z, facade_bodies()), ref


def pier_bodies() -> tuple[Cylinder]:
    """The pier of ``Pier-v0``: a vertical cylinder standing on the ground at the origin."""
    return (Cylinder(PIER_RADIUS, PIER_HEIGHT, (0.0, 0.0, PIER_HEIGHT / 2)),)


def _pier(standoff: float, altitude: float, duration: float, base: Scene, period: float) -> tuple[Scene, Reference]:
    ref = CircleReference((0.0, 0.0, altitude), duration, _FACE_WALL, radius=PIER_RADIUS + standoff, period=period,
                          axis_u=(1.0, 0.0, 0.0), axis_w=(0.0, 1.0, 0.0), ramp_time=1.0)
    return Scene(base.walls, base.ground_z, base.ceiling_z, pier_bodies()), ref


_FACADE_PARAMETERS = (
    TaskParameter("leg_time", 14.0, 4.0, 120.0, "s", "time of each pass along the facade (rest to rest)"),
)
_PIER_PARAMETERS = (
    TaskParameter("period", 16.0, 4.0, 120.0, "s", "time of one lap around the pier after the 1 s ramp-up"),
)


# The paper's simulation (Sec. 4.1.1, Table I, Fig. 6) flies "a circular trajectory along a wall"
# and gives neither its size nor its speed. A circle in a vertical plane parallel to the wall keeps
# every rotor's distance to the wall constant, so that only k_s changes between Table I's rows, as in
# the paper; 0.3 m radius and a 6 s period make 0.31 m/s along the wall, the speeds of the paper's own
# flight (0.25 to 0.5 m/s legs, Sec. 4.4).
_CIRCLE_PARAMETERS = (
    TaskParameter("radius", 0.3, 0.02, 2.0, "m", "radius of the circle in the plane parallel to the wall"),
    TaskParameter("period", 6.0, 1.0, 120.0, "s", "time of one lap after the 1 s ramp-up"),
)

TASKS: dict[str, TaskSpec] = {
    spec.name: spec
    for spec in (
        TaskSpec("WallHover", "hold a stand-off point near a wall from a perturbed start",
                 standoff=0.16, altitude=1.0, duration=5.0, closest_approach=0.0, wall_axis=0,
                 start_position_noise=0.05, start_velocity_noise=0.1, start_attitude_noise=0.05, build=_hover),
        TaskSpec("WallCircle", "the paper's simulation study: a vertical circle parallel to the wall",
                 standoff=0.15, altitude=1.0, duration=13.0, closest_approach=0.0, wall_axis=0,
                 start_position_noise=0.01, start_velocity_noise=0.02, start_attitude_noise=0.01, build=_circle,
                 parameters=_CIRCLE_PARAMETERS),
        TaskSpec("WallSweep", "the paper's flight: vertical zig-zag along the wall, approaching 0.1 m and back",
                 standoff=0.23, altitude=1.5, duration=17.0, closest_approach=0.1, wall_axis=0,
                 start_position_noise=0.01, start_velocity_noise=0.02, start_attitude_noise=0.01, build=_sweep),
        TaskSpec("Corridor", "fly along a corridor between two walls that both pull",
                 standoff=0.2, altitude=1.0, duration=10.0, closest_approach=0.05, wall_axis=1,
                 start_position_noise=0.01, start_velocity_noise=0.02, start_attitude_noise=0.01, build=_corridor),
        TaskSpec("Facade", "inspect a facade: past two window recesses, around a ledge and back over it",
                 standoff=0.16, altitude=1.5, duration=37.0, closest_approach=0.0, wall_axis=0,
                 start_position_noise=0.01, start_velocity_noise=0.02, start_attitude_noise=0.01, build=_facade,
                 parameters=_FACADE_PARAMETERS, altitude_range=(0.5, 2.3)),
        TaskSpec("Pier", "circle a bridge pier (a cylinder) at a stand-off from its surface",
                 standoff=0.18, altitude=1.5, duration=18.0, closest_approach=0.0, wall_axis=None,
                 start_position_noise=0.01, start_velocity_noise=0.02, start_attitude_noise=0.01, build=_pier,
                 parameters=_PIER_PARAMETERS),
    )
}


def task_name(name: str) -> str:
    """Canonical task name (``"WallSweep"``) from any accepted spelling."""
    text = str(name).strip()
    text = text.split("/")[-1]
    text = re.sub(r"-v\d+$", "", text)
    if text in TASKS:
        return text
    camel = "".join(part.capitalize() for part in text.split("_"))
    if camel in TASKS:
        return camel
    lowered = {t.lower(): t for t in TASKS}
    if text.lower() in lowered:
        return lowered[text.lower()]
    raise ValueError(f"unknown task {name!r}; choose from {', '.join(f'WallInspector/{t}-v0' for t in TASKS)}")


def task_env_id(name: str) -> str:
    return f"WallInspector/{task_name(name)}-v0"


def task_slug(name: str) -> str:
    """File-system name of a task: ``WallSweep`` -> ``wall_sweep``."""
    return re.sub(r"(?<!^)(?=[A-Z])", "_", task_name(name)).lower()
