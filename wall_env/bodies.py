"""Finite geometry of a scene: boxes, cylinders and meshes (OBJ files or URDF models).

A body is placed in the world by ``position`` (m) and ``rpy`` (roll, pitch, yaw in rad,
applied as ``R = Rz(yaw) Ry(pitch) Rx(roll)``, URDF's convention). Sizes are in metres:

==========  =====================================================================
body        fields
==========  =====================================================================
box         ``size`` (3 full lengths along its own x, y, z)
cylinder    ``radius``, ``length`` (along its own z)
mesh        ``file`` (Wavefront ``.obj``; static, used as its triangles, not a hull),
            ``scale`` (one factor or three)
urdf        ``file`` (``.urdf``; every link's collision geometry, fixed in place),
            ``scale`` (one factor)
==========  =====================================================================

In a scene file (YAML or JSON, :meth:`wall_env.scene.Scene.from_file`) each body is a
mapping with a ``type`` key::

    bodies:
      - {type: box, size: [0.3, 6.0, 4.0], position: [-0.15, 0.0, 2.0]}
      - {type: cylinder, radius: 0.5, length: 6.0, position: [0.0, 0.0, 3.0]}
      - {type: mesh, file: facade.obj, position: [0.0, 0.0, 0.0], rpy: [0.0, 0.0, 1.5708], scale: 0.001}
      - {type: urdf, file: building.urdf, position: [5.0, 0.0, 0.0]}

A relative ``file`` is read relative to the folder of the scene file that names it (the
folder is given to :func:`body_from_dict` as ``base``); the body holds the absolute path.
Files are only ever read.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wall_env.validation import check_positive, check_vector

__all__ = ["Box", "Cylinder", "Mesh", "Urdf", "Body", "BODY_TYPES", "body_from_dict", "rpy_to_rotation"]

_MAX_EXTENT = 1e4  # m, the largest size or coordinate a body may have


def rpy_to_rotation(rpy: Sequence[float] | np.ndarray) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` (body to world) of roll, pitch, yaw (rad)."""
    roll, pitch, yaw = (float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _pose(kind: str, position: Any, rpy: Any) -> tuple[tuple[float, ...], tuple[float, ...]]:
    return (check_vector(f"{kind}.position (m)", position, 3, -_MAX_EXTENT, _MAX_EXTENT),
            check_vector(f"{kind}.rpy (rad)", rpy, 3, -10.0, 10.0))


@dataclass(frozen=True)
class Box:
    """A box of full lengths ``size`` (m) centred at ``position``, turned by ``rpy``."""

    size: tuple[float, float, float]
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    type: str = field(default="box", init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", check_vector("box.size (m)", self.size, 3, 1e-4, _MAX_EXTENT))
        position, rpy = _pose("box", self.position, self.rpy)
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "rpy", rpy)

    def to_dict(self, relative_to: Path | None = None) -> dict[str, Any]:
        return {"type": "box", "size": list(self.size), "position": list(self.position), "rpy": list(self.rpy)}


@dataclass(frozen=True)
class Cylinder:
    """A cylinder of ``radius`` and ``length`` (m, along its own z) centred at ``position``, turned by ``rpy``."""

    radius: float
    length: float
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    type: str = field(default="cylinder", init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "radius", check_positive("cylinder.radius (m)", self.radius, _MAX_EXTENT))
        object.__setattr__(self, "length", check_positive("cylinder.length (m)", self.length, _MAX_EXTENT))
        position, rpy = _pose("cylinder", self.position, self.rpy)
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "rpy", rpy)

    def to_dict(self, relative_to: Path | None = None) -> dict[str, Any]:
        return {"type": "cylinder", "radius": self.radius, "length": self.length, "position": list(self.position),
                "rpy": list(self.rpy)}


def _checked_file(kind: str, file: Any, suffixes: tuple[str, ...], base: Path | None) -> str:
    if not isinstance(file, (str, Path)) or not str(file):
        raise ValueError(f"{kind}.file must be a path to a {'/'.join(suffixes)} file, got {file!r}")
    path = Path(file)
    if not path.is_absolute() and base is not None:
        path = base / path
    if path.suffix.lower() not in suffixes:
        raise ValueError(f"{kind}.file must end in {' or '.join(suffixes)}, got {str(file)!r}")
    if not path.is_file():
        raise ValueError(f"{kind}.file {path} does not exist")
    return str(path.resolve())


def _relative(path: str, relative_to: Path | None) -> str:
    if relative_to is None:
        return path
    try:
        return str(Path(path).relative_to(Path(relative_to).resolve()))
    except ValueError:
        return path


@dataclass(frozen=True)
class Mesh:
    """The triangles of a Wavefront OBJ ``file``, scaled by ``scale`` (one factor or three), placed at
    ``position`` and turned by ``rpy``. Static: collisions and distances use the triangles themselves."""

    file: str
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    type: str = field(default="mesh", init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "file", _checked_file("mesh", self.file, (".obj",), None))
        position, rpy = _pose("mesh", self.position, self.rpy)
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "rpy", rpy)
        scale = (self.scale,) * 3 if np.ndim(self.scale) == 0 else self.scale
        object.__setattr__(self, "scale", check_vector("mesh.scale", scale, 3, 1e-9, 1e6))

    def to_dict(self, relative_to: Path | None = None) -> dict[str, Any]:
        return {"type": "mesh", "file": _relative(self.file, relative_to), "position": list(self.position),
                "rpy": list(self.rpy), "scale": list(self.scale)}


@dataclass(frozen=True)
class Urdf:
    """Every link's collision geometry of the URDF model in ``file``, fixed at ``position`` and ``rpy``,
    scaled by ``scale``."""

    file: str
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: float = 1.0
    type: str = field(default="urdf", init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "file", _checked_file("urdf", self.file, (".urdf",), None))
        position, rpy = _pose("urdf", self.position, self.rpy)
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "rpy", rpy)
        object.__setattr__(self, "scale", check_positive("urdf.scale", self.scale, 1e6))

    def to_dict(self, relative_to: Path | None = None) -> dict[str, Any]:
        return {"type": "urdf", "file": _relative(self.file, relative_to), "position": list(self.position),
                "rpy": list(self.rpy), "scale": self.scale}


Body = Box | Cylinder | Mesh | Urdf
BODY_TYPES: dict[str, type] = {"box": Box, "cylinder": Cylinder, "mesh": Mesh, "urdf": Urdf}
_FIELDS = {"box": ("size", "position", "rpy"), "cylinder": ("radius", "length", "position", "rpy"),
           "mesh": ("file", "position", "rpy", "scale"), "urdf": ("file", "position", "rpy", "scale")}
_REQUIRED = {"box": ("size",), "cylinder": ("radius", "length"), "mesh": ("file",), "urdf": ("file",)}


def body_from_dict(data: Any, base: str | Path | None = None, where: str = "body") -> Body:
    """A body from its mapping (``type`` and the fields of that type); relative files are read from ``base``.

    ``where`` names the mapping in errors (``"scene.bodies[2]"``)."""
    if isinstance(data, (Box, Cylinder, Mesh, Urdf)):
        return data
    if not isinstance(data, dict):
        raise ValueError(f"{where} must be a mapping with a 'type' among {sorted(BODY_TYPES)}, got {data!r}")
    kind = data.get("type")
    if kind not in BODY_TYPES:
        raise ValueError(f"{where}.type must be one of {sorted(BODY_TYPES)}, got {kind!r}")
    unknown = sorted(map(str, set(data) - {"type", *_FIELDS[kind]}))
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {where} ({kind}); allowed: {['type', *_FIELDS[kind]]}")
    missing = [k for k in _REQUIRED[kind] if k not in data]
    if missing:
        raise ValueError(f"{where} ({kind}) needs {missing}")
    values = {k: v for k, v in data.items() if k != "type"}
    if "file" in values:
        values["file"] = _checked_file(f"{where}", values["file"], (".obj",) if kind == "mesh" else (".urdf",),
                                       None if base is None else Path(base))
    try:
        return BODY_TYPES[kind](**values)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
