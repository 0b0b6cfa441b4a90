"""Scene geometry: wall planes, ground and ceiling, and finite bodies (boxes, cylinders, meshes).

A wall is an infinite plane given by a point on its surface and its outward unit
normal, which points away from the wall into the free space where the vehicle flies.
The signed distance of a world point ``p_world`` from the wall is
``normal . (p_world - point)``: positive in free space, zero on the surface.

Besides planes a scene may hold *bodies* (:mod:`wall_env.bodies`): boxes, cylinders,
OBJ meshes and URDF models, the geometry of a real structure. Planes keep their closed
form; bodies are loaded into PyBullet, which answers, for each rotor, the nearest points
of their surfaces (:mod:`wall_env.surfaces`). What the effects read of the bodies is
each rotor's *local surfaces*: :data:`SURFACE_SLOTS` tangent planes per rotor, each a
point, an outward normal and a weight (:data:`SURFACE_SIZE` numbers), filled in from
PyBullet's query at every control step and held fixed within it.

The same geometry serves three users: the simulator (numeric vector), the effects'
symbolic definitions (:meth:`Scene.symbols`) and PyBullet (distances, collision and
pictures). The numeric vector (:meth:`Scene.to_vector`) is each wall's point and
normal, the ground height, the ceiling height (those the scene has), then, for a scene
with bodies, the local surfaces of rotor 0 (slot 0, slot 1), rotor 1, ... as placeholders
of weight zero (no surface) until a query fills them in.

A scene file (YAML or JSON, :meth:`Scene.from_file`)::

    walls:                                    # infinite planes
      - {point: [0.0, 0.0, 0.0], normal: [1.0, 0.0, 0.0]}
    ground_z: 0.0                             # or null
    ceiling_z: null
    bodies:                                   # finite geometry (wall_env.bodies)
      - {type: box, size: [0.3, 6.0, 4.0], position: [-0.15, 0.0, 2.0]}
      - {type: mesh, file: facade.obj}
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from wall_env.bodies import Body, body_from_dict
from wall_env.validation import check_finite_array, check_range, read_mapping

__all__ = ["Wall", "Scene", "SceneSymbols", "SceneStructure", "RotorSurface", "scene_symbols", "ROTOR_COUNT",
           "SURFACE_SLOTS", "SURFACE_SIZE", "SURFACES_SIZE"]

ROTOR_COUNT = 4
SURFACE_SLOTS = 2  # local surfaces per rotor: the nearest, and the nearest of another orientation
SURFACE_SIZE = 7  # point (3), outward unit normal (3), weight (1)
SURFACES_SIZE = ROTOR_COUNT * SURFACE_SLOTS * SURFACE_SIZE


@dataclass(frozen=True)
class Wall:
    """A wall plane: ``point`` on the surface (m, world) and outward unit ``normal``."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]

    def __post_init__(self) -> None:
        point = check_finite_array("wall point", self.point, (3,))
        normal = check_finite_array("wall normal", self.normal, (3,))
        norm = float(np.linalg.norm(normal))
        if norm < 1e-9:
            raise ValueError(f"wall normal must be a non-zero vector, got {normal.tolist()}")
        object.__setattr__(self, "point", tuple(float(v) for v in point))
        object.__setattr__(self, "normal", tuple(float(v) for v in normal / norm))

    def distance(self, p_world: np.ndarray) -> np.ndarray:
        """Signed distance (m) of points ``(..., 3)`` from the plane, positive in free space."""
        return (np.asarray(p_world, dtype=float) - np.asarray(self.point)) @ np.asarray(self.normal)

    def to_dict(self) -> dict[str, list[float]]:
        return {"point": list(self.point), "normal": list(self.normal)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Wall:
        unknown = sorted(set(data) - {"point", "normal"})
        if unknown:
            raise ValueError(f"unknown wall key(s) {unknown}; a wall has 'point' and 'normal'")
        return cls(point=tuple(data["point"]), normal=tuple(data["normal"]))


class SceneStructure(NamedTuple):
    """What the symbolic functions depend on: wall count, ground, ceiling and local surface slots per rotor
    (0 for a scene of planes only)."""

    walls: int
    ground: bool
    ceiling: bool
    surface_slots: int = 0

    @property
    def plane_size(self) -> int:
        return 6 * self.walls + int(self.ground) + int(self.ceiling)

    @property
    def vector_size(self) -> int:
        return self.plane_size + ROTOR_COUNT * self.surface_slots * SURFACE_SIZE


class RotorSurface(NamedTuple):
    """One local surface of one rotor, symbolic: a point on it, its outward unit normal, its weight (0 to 1)."""

    point: ca.SX
    normal: ca.SX
    weight: ca.SX


@dataclass(frozen=True)
class SceneSymbols:
    """Symbolic view of a scene for the effects' CasADi definitions."""

    wall_points: list[ca.SX]  # each 3x1, world
    wall_normals: list[ca.SX]  # each 3x1 unit, outward
    ground_z: ca.SX | None
    ceiling_z: ca.SX | None
    #: per rotor, its local surfaces (empty for a scene of planes only)
    rotor_surfaces: tuple[tuple[RotorSurface, ...], ...] = ()


def scene_symbols(structure: tuple) -> tuple[SceneSymbols, ca.SX]:
    """Symbols with ``structure`` (:class:`SceneStructure`, or its first three entries) and the flat vector
    they are read from, in the order of :meth:`Scene.to_vector`."""
    structure = SceneStructure(*structure)
    vector = ca.SX.sym("scene", structure.vector_size)
    points = [vector[6 * k: 6 * k + 3] for k in range(structure.walls)]
    normals = [vector[6 * k + 3: 6 * k + 6] for k in range(structure.walls)]
    index = 6 * structure.walls
    ground = ceiling = None
    if structure.ground:
        ground = vector[index]
        index += 1
    if structure.ceiling:
        ceiling = vector[index]
        index += 1
    rotors = []
    for _ in range(ROTOR_COUNT if structure.surface_slots else 0):
        slots = []
        for _ in range(structure.surface_slots):
            slots.append(RotorSurface(vector[index: index + 3], vector[index + 3: index + 6], vector[index + 6]))
            index += SURFACE_SIZE
        rotors.append(tuple(slots))
    return SceneSymbols(points, normals, ground, ceiling, tuple(rotors)), vector


@dataclass(frozen=True)
class Scene:
    """Walls, the ground plane height, an optional ceiling height (m, world z up) and finite ``bodies``
    (:mod:`wall_env.bodies`)."""

    walls: tuple[Wall, ...] = ()
    ground_z: float | None = 0.0
    ceiling_z: float | None = None
    bodies: tuple[Body, ...] = ()

    def __post_init__(self) -> None:
        walls = tuple(w if isinstance(w, Wall) else Wall.from_dict(w) for w in self.walls)
        object.__setattr__(self, "walls", walls)
        object.__setattr__(self, "bodies", tuple(body_from_dict(b, where=f"scene.bodies[{k}]")
                                                 for k, b in enumerate(self.bodies)))
        if self.ground_z is not None:
            object.__setattr__(self, "ground_z", check_range("ground_z", self.ground_z, -1e4, 1e4))
        if self.ceiling_z is not None:
            ceiling = check_range("ceiling_z", self.ceiling_z, -1e4, 1e4)
            if self.ground_z is not None and ceiling <= self.ground_z:
                raise ValueError(f"ceiling_z must be above ground_z={self.ground_z}, got {ceiling}")
            object.__setattr__(self, "ceiling_z", ceiling)

    # ----------------------------------------------------------- structure
    @property
    def has_bodies(self) -> bool:
        """Whether the scene holds finite bodies (their distances come from PyBullet)."""
        return bool(self.bodies)

    @property
    def structure(self) -> SceneStructure:
        """What symbolic functions depend on: wall count, whether ground and ceiling exist, and the local
        surface slots per rotor (:data:`SURFACE_SLOTS` with bodies, else 0)."""
        return SceneStructure(len(self.walls), self.ground_z is not None, self.ceiling_z is not None,
                              SURFACE_SLOTS if self.bodies else 0)

    @property
    def vector_size(self) -> int:
        return self.structure.vector_size

    @property
    def surfaces_slice(self) -> slice:
        """Where the rotors' local surfaces sit in :meth:`to_vector` (empty without bodies)."""
        structure = self.structure
        return slice(structure.plane_size, structure.vector_size)

    def to_vector(self) -> np.ndarray:
        """Numeric values in the order of :meth:`symbols`: each wall's point and normal, ground, ceiling, and
        with bodies the rotors' local surfaces as placeholders of weight zero."""
        values: list[float] = []
        for wall in self.walls:
            values.extend(wall.point)
            values.extend(wall.normal)
        if self.ground_z is not None:
            values.append(self.ground_z)
        if self.ceiling_z is not None:
            values.append(self.ceiling_z)
        if self.bodies:
            values.extend([0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0] * (ROTOR_COUNT * SURFACE_SLOTS))
        return np.asarray(values, dtype=float)

    def symbols(self) -> tuple[SceneSymbols, ca.SX]:
        """Symbols with this scene's structure and the flat vector they are read from."""
        return scene_symbols(self.structure)

    # ----------------------------------------------------------- queries
    def wall_distances(self, points_world: np.ndarray) -> np.ndarray:
        """Signed distances of points ``(n, 3)`` to every wall, shape ``(n_walls, n)``."""
        points = np.atleast_2d(points_world)
        if not self.walls:
            return np.zeros((0, points.shape[0]))
        normals = np.array([w.normal for w in self.walls])
        offsets = np.array([np.dot(w.normal, w.point) for w in self.walls])
        return normals @ points.T - offsets[:, None]

    def moved(self, wall_offsets: np.ndarray) -> Scene:
        """A copy with each wall shifted along its normal by ``wall_offsets`` (m)."""
        walls = tuple(
            Wall(tuple(np.asarray(w.point) + off * np.asarray(w.normal)), w.normal)
            for w, off in zip(self.walls, wall_offsets)
        )
        return Scene(walls, self.ground_z, self.ceiling_z, self.bodies)

    # ----------------------------------------------------------- I/O
    def to_dict(self, relative_to: str | Path | None = None) -> dict[str, Any]:
        """The scene as plain data (a scene file's content); mesh and URDF paths relative to ``relative_to``
        where they lie below it. ``bodies`` only when there are some."""
        data: dict[str, Any] = {
            "walls": [w.to_dict() for w in self.walls],
            "ground_z": self.ground_z,
            "ceiling_z": self.ceiling_z,
        }
        if self.bodies:
            folder = None if relative_to is None else Path(relative_to)
            data["bodies"] = [b.to_dict(folder) for b in self.bodies]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any], base: str | Path | None = None) -> Scene:
        """A scene from plain data; relative mesh and URDF files are read from folder ``base``."""
        if not isinstance(data, dict):
            raise ValueError(f"a scene must be a mapping of walls, ground_z, ceiling_z and bodies, got {data!r}")
        unknown = sorted(map(str, set(data) - {"walls", "ground_z", "ceiling_z", "bodies"}))
        if unknown:
            raise ValueError(f"unknown scene key(s) {unknown}; allowed: walls, ground_z, ceiling_z, bodies")
        bodies = data.get("bodies") or []
        if not isinstance(bodies, list):
            raise ValueError(f"scene.bodies must be a list of bodies, got {bodies!r}")
        return cls(
            walls=tuple(Wall.from_dict(w) for w in data.get("walls") or []),
            ground_z=data.get("ground_z", 0.0),
            ceiling_z=data.get("ceiling_z"),
            bodies=tuple(body_from_dict(b, base, f"scene.bodies[{k}]") for k, b in enumerate(bodies)),
        )

    @classmethod
    def from_file(cls, path: str | Path) -> Scene:
        """A scene file (``.yaml``, ``.yml`` or ``.json``, the format of the module docstring); relative mesh
        and URDF files are read from the file's folder. Errors name the file."""
        path = Path(path)
        data = read_mapping(path, "scene file")
        try:
            return cls.from_dict(data, base=path.parent)
        except ValueError as exc:
            raise ValueError(f"scene file {path}: {exc}") from None

    def to_file(self, path: str | Path) -> Path:
        """Write the scene as YAML or JSON (by the suffix); mesh and URDF paths relative to the file's folder."""
        import json

        import yaml

        path = Path(path)
        data = self.to_dict(relative_to=path.parent)
        if path.suffix.lower() == ".json":
            path.write_text(json.dumps(data, indent=2) + "\n")
        elif path.suffix.lower() in (".yaml", ".yml"):
            path.write_text(yaml.safe_dump(data, sort_keys=False))
        else:
            raise ValueError(f"scene file {path} must end in .json, .yaml or .yml")
        return path
