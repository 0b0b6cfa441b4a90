"""Flight logs from other tools, converted to the project's format.

:func:`import_log` reads a PX4 ULog (``.ulg``, :mod:`discovery.importers.px4`) or a
ROS 2 bag (a bag folder, ``.mcap`` or ``.db3``, :mod:`discovery.importers.ros2`)
together with the nominal vehicle and the scene (YAML files holding the sidecar's
``vehicle`` and ``scene`` blocks, :func:`discovery.flight_log.read_vehicle_and_scene`)
and returns a :class:`~discovery.flight_log.FlightLog` in the project's frames and
units, plus a record of what the import did (topics used, rates, gaps, thrust map).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from discovery.flight_log import FlightLog, read_vehicle_and_scene

__all__ = ["import_log", "is_importable", "FORMATS"]

FORMATS = {".ulg": "PX4 ULog", ".mcap": "ROS 2 bag (MCAP)", ".db3": "ROS 2 bag (SQLite3)",
           "folder": "ROS 2 bag folder (with metadata.yaml)"}


def is_importable(path: str | Path) -> bool:
    """Whether ``path`` is a log :func:`import_log` reads (by suffix, or a bag folder)."""
    from discovery.importers.ros2 import is_bag

    return Path(path).suffix.lower() == ".ulg" or is_bag(path)


def import_log(path: str | Path, vehicle_file: str | Path, scene_file: str | Path, *,
               topics: str | Path | dict | None = None, rate_hz: float | None = None,
               thrust_map_kind: str | None = None) -> tuple[FlightLog, dict[str, Any]]:
    """Read a PX4 ULog or a ROS 2 bag as a flight log (see the module text)."""
    vehicle, scene, gravity = read_vehicle_and_scene(vehicle_file, scene_file)
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"flight log {path} does not exist")
    if path.suffix.lower() == ".ulg":
        if topics is not None:
            raise ValueError("--topics is for ROS 2 bags; a PX4 ULog's topics are fixed")
        from discovery.importers.px4 import read_ulog

        return read_ulog(path, vehicle, scene, gravity, rate_hz=rate_hz, thrust_map_kind=thrust_map_kind)
    if is_importable(path):
        if thrust_map_kind not in (None, "collective"):
            raise ValueError("a ROS 2 bag's thrust is collective; --thrust-map must be 'collective'")
        from discovery.importers.ros2 import read_bag

        return read_bag(path, vehicle, scene, gravity, topic_map=topics, rate_hz=rate_hz)
    raise ValueError(f"{path}: not a format import reads; it reads {', '.join(FORMATS.values())}")
