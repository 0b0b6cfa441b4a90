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
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wall_env.references import CircleReference, CorridorReference, HoverReference, Reference, SweepReference
from wall_env.scene import Scene, Wall
from wall_env.validation import check_range
from wall_env.vehicle import VehicleParams

__all__ = ["TaskSpec", "TaskParameter", "TASKS", "min_standoff", "task_name", "task_env_id", "task_slug"]

_WALL = Wall(point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0))
_FACE_WALL = math.pi


def min_standoff(vehicle: VehicleParams, body_axis: int, margin: float = 0.005) -> float:
    """Smallest centre-of-mass distance (m) at which no duct touches a wall that body axis
    ``body_axis`` (0 = x, 1 = y) points at, with the vehicle level."""
    reach = float(np.max(np.abs(vehicle.rotor_positions_array[:, body_axis])))
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
    wall_axis: int  # body axis (0 = x, 1 = y) that points at the wall(s) on the reference heading
    start_position_noise: float  # m, half-width of the uniform start perturbation per axis
    start_velocity_noise: float  # m/s
    start_attitude_noise: float  # rad, roll/pitch/yaw
    build: Callable[..., tuple[Scene, Reference]]  # (standoff, altitude, duration, base scene, **parameters)
    parameters: tuple[TaskParameter, ...] = ()

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
