"""Scene geometry: wall planes, ground and ceiling.

A wall is an infinite plane given by a point on its surface and its outward unit
normal, which points away from the wall into the free space where the vehicle flies.
The signed distance of a world point ``p_world`` from the wall is
``normal . (p_world - point)``: positive in free space, zero on the surface.

The same geometry serves three users: the simulator (numeric vector), the effects'
symbolic definitions (:meth:`Scene.symbols`) and PyBullet (collision and pictures).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from wall_env.validation import check_finite_array, check_range

__all__ = ["Wall", "Scene", "SceneSymbols"]


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


@dataclass(frozen=True)
class SceneSymbols:
    """Symbolic view of a scene for the effects' CasADi definitions."""

    wall_points: list[ca.SX]  # each 3x1, world
    wall_normals: list[ca.SX]  # each 3x1 unit, outward
    ground_z: ca.SX | None
    ceiling_z: ca.SX | None


@dataclass(frozen=True)
class Scene:
    """Walls, the ground plane height and an optional ceiling height (m, world z up)."""

    walls: tuple[Wall, ...] = ()
    ground_z: float | None = 0.0
    ceiling_z: float | None = None

    def __post_init__(self) -> None:
        walls = tuple(w if isinstance(w, Wall) else Wall.from_dict(w) for w in self.walls)
        object.__setattr__(self, "walls", walls)
        if self.ground_z is not None:
            object.__setattr__(self, "ground_z", check_range("ground_z", self.ground_z, -1e4, 1e4))
        if self.ceiling_z is not None:
            ceiling = check_range("ceiling_z", self.ceiling_z, -1e4, 1e4)
            if self.ground_z is not None and ceiling <= self.ground_z:
                raise ValueError(f"ceiling_z must be above ground_z={self.ground_z}, got {ceiling}")
            object.__setattr__(self, "ceiling_z", ceiling)

    # ----------------------------------------------------------- structure
    @property
    def structure(self) -> tuple[int, bool, bool]:
        """What symbolic functions depend on: wall count and whether ground and ceiling exist."""
        return (len(self.walls), self.ground_z is not None, self.ceiling_z is not None)

    @property
    def vector_size(self) -> int:
        n_walls, has_ground, has_ceiling = self.structure
        return 6 * n_walls + int(has_ground) + int(has_ceiling)

    def to_vector(self) -> np.ndarray:
        """Numeric values in the order of :meth:`symbols`: each wall's point and normal, ground, ceiling."""
        values: list[float] = []
        for wall in self.walls:
            values.extend(wall.point)
            values.extend(wall.normal)
        if self.ground_z is not None:
            values.append(self.ground_z)
        if self.ceiling_z is not None:
            values.append(self.ceiling_z)
        return np.asarray(values, dtype=float)

    def symbols(self) -> tuple[SceneSymbols, ca.SX]:
        """Symbols with this scene's structure and the flat vector they are read from."""
        vector = ca.SX.sym("scene", self.vector_size)
        points, normals = [], []
        for k in range(len(self.walls)):
            points.append(vector[6 * k : 6 * k + 3])
            normals.append(vector[6 * k + 3 : 6 * k + 6])
        index = 6 * len(self.walls)
        ground = ceiling = None
        if self.ground_z is not None:
            ground = vector[index]
            index += 1
        if self.ceiling_z is not None:
            ceiling = vector[index]
        return SceneSymbols(points, normals, ground, ceiling), vector

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
        return Scene(walls, self.ground_z, self.ceiling_z)

    # ----------------------------------------------------------- I/O
    def to_dict(self) -> dict[str, Any]:
        return {
            "walls": [w.to_dict() for w in self.walls],
            "ground_z": self.ground_z,
            "ceiling_z": self.ceiling_z,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scene:
        unknown = sorted(set(data) - {"walls", "ground_z", "ceiling_z"})
        if unknown:
            raise ValueError(f"unknown scene key(s) {unknown}; allowed: walls, ground_z, ceiling_z")
        return cls(
            walls=tuple(Wall.from_dict(w) for w in data.get("walls", [])),
            ground_z=data.get("ground_z", 0.0),
            ceiling_z=data.get("ceiling_z"),
        )
