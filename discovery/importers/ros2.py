"""ROS 2 bags (SQLite3 or MCAP storage) as flight logs, read with ``rosbags``.

Which topic holds what comes from a small topic map (a YAML file or a dict). Each
entry is a topic name, or ``{topic: NAME, field: PATH, scale: NUMBER}`` to pick a field
of the message (``field`` a dotted path with optional indices, e.g. ``xyz[2]``, or a
list of paths, e.g. ``[roll, pitch, yaw]``; ``scale`` multiplies the values; the default
field depends on the message type, see :data:`DEFAULT_FIELDS`)::

    odometry: /vehicle/odom         # nav_msgs/msg/Odometry: pose (world) and twist (body frame)
    # or, from motion capture:
    pose: /mocap/vehicle/pose       # geometry_msgs/msg/PoseStamped (velocity from the positions)
    body_rates: /imu                # optional: sensor_msgs/msg/Imu (default: the odometry's angular twist)
    thrust: /cmd/thrust             # collective thrust command (std_msgs Float32/Float64 or a message field)
    rates_setpoint: /cmd/rates      # body-rate command (geometry_msgs Vector3Stamped, Vector3 or a field)
    thrust_unit: newton             # or normalised (0..1: the thrust map is fitted on hover)
    frame: enu                      # or ned (world NED and body FRD, as px4_msgs write them)
    odometry_twist_frame: body      # or world

PX4 through its ROS 2 bridge (``px4_msgs``, with the message definitions the bag
carries, as MCAP and recent SQLite3 bags do) needs only the topics::

    odometry: /fmu/out/vehicle_odometry              # px4_msgs/msg/VehicleOdometry
    thrust: /fmu/out/vehicle_thrust_setpoint         # px4_msgs/msg/VehicleThrustSetpoint: -xyz[2]
    rates_setpoint: /fmu/out/vehicle_rates_setpoint  # px4_msgs/msg/VehicleRatesSetpoint

With a ``px4_msgs`` odometry ``frame`` defaults to ``ned``, its velocity is taken in the
frame its ``velocity_frame`` names, and with a ``px4_msgs`` thrust setpoint
``thrust_unit`` defaults to ``normalised``.

Times are the messages' header stamps where they have one, else the bag's receive
times, relative to the first sample; when every topic is a ``px4_msgs`` message, their
``timestamp_sample`` (else ``timestamp``, PX4's clock) is used instead. Signals are
resampled onto one clock (default: the odometry or pose rate, clipped to 50..1000 Hz);
gaps stay gaps.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from discovery.flight_log import FlightLog, LogFormatError, NominalVehicle, ThrustMap, quaternions_to_matrices
from discovery.importers.frames import attitude_frd_ned_to_flu_enu, frd_to_flu, ned_to_enu
from discovery.importers.resample import (
    Signal,
    gap_free_clock,
    hold,
    interpolate,
    interpolate_attitude,
)
from discovery.importers.thrust_map import apply_thrust_map, fit_thrust_map

__all__ = ["DEFAULT_FIELDS", "TOPIC_KEYS", "read_bag", "read_topic_map", "is_bag"]

DEFAULT_FIELDS: dict[str, tuple[str | list[str], float]] = {  # message type: (field path(s), scale)
    "std_msgs/msg/Float32": ("data", 1.0),
    "std_msgs/msg/Float64": ("data", 1.0),
    "geometry_msgs/msg/Vector3Stamped": ("vector", 1.0),
    "geometry_msgs/msg/Vector3": ("", 1.0),
    "geometry_msgs/msg/TwistStamped": ("twist.angular", 1.0),
    "sensor_msgs/msg/Imu": ("angular_velocity", 1.0),
    "px4_msgs/msg/VehicleThrustSetpoint": ("xyz[2]", -1.0),  # FRD: upward thrust is -z
    "px4_msgs/msg/VehicleRatesSetpoint": (["roll", "pitch", "yaw"], 1.0),
    "px4_msgs/msg/VehicleAngularVelocity": ("xyz", 1.0),
}
TOPIC_KEYS = ("odometry", "pose", "body_rates", "thrust", "rates_setpoint")
_OPTIONS = {"thrust_unit": ("newton", "normalised"), "frame": ("enu", "ned"),
            "odometry_twist_frame": ("body", "world")}
_AUTO = {"thrust_unit", "frame"}  # left out, these follow the message types (px4_msgs: normalised, ned)
_PX4 = "px4_msgs/"
_PX4_ODOMETRY = "px4_msgs/msg/VehicleOdometry"
_PX4_BODY_FRD = 3  # VehicleOdometry.velocity_frame of a body-frame velocity
MIN_RATE_HZ, MAX_RATE_HZ = 50.0, 1000.0
_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?")


def is_bag(path: str | Path) -> bool:
    """A ROS 2 bag: a folder with ``metadata.yaml``, or an ``.mcap`` / ``.db3`` file."""
    path = Path(path)
    return (path.is_dir() and (path / "metadata.yaml").is_file()) or path.suffix.lower() in (".mcap", ".db3")


def read_topic_map(source: str | Path | dict | None) -> dict[str, Any]:
    """A checked topic map (see the module text) from a YAML file, a dict, or None for ``odometry: /odom`` etc."""
    if source is None:
        data: dict[str, Any] = {"odometry": "/odom", "thrust": "/thrust", "rates_setpoint": "/rates_setpoint"}
    elif isinstance(source, dict):
        data = dict(source)
    else:
        from wall_env.validation import read_mapping

        data = read_mapping(source, "topic map")
    unknown = sorted(set(data) - set(TOPIC_KEYS) - set(_OPTIONS))
    if unknown:
        raise ValueError(f"topic map: unknown key(s) {unknown}; allowed: {list(TOPIC_KEYS) + list(_OPTIONS)}")
    out: dict[str, Any] = {k: None if k in _AUTO else default[0] for k, default in _OPTIONS.items()}
    for key, allowed in _OPTIONS.items():
        if key in data:
            if data[key] not in allowed:
                raise ValueError(f"topic map: {key} must be one of {list(allowed)}, got {data[key]!r}")
            out[key] = data[key]
    for key in TOPIC_KEYS:
        entry = data.get(key)
        if entry is None:
            continue
        if isinstance(entry, str):
            entry = {"topic": entry}
        field = entry.get("field", "") if isinstance(entry, dict) else None
        fields_ok = isinstance(field, str) or (isinstance(field, list) and field and
                                               all(isinstance(f, str) for f in field))
        if not isinstance(entry, dict) or not isinstance(entry.get("topic"), str) or \
                not set(entry) <= {"topic", "field", "scale"} or not fields_ok:
            raise ValueError(f"topic map: {key} must be a topic name or {{topic: NAME, field: PATH or [PATH, ...], "
                             f"scale: NUMBER}}, got {entry!r}")
        if "scale" in entry:
            scale = entry["scale"]
            if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale == 0:
                raise ValueError(f"topic map: {key}.scale must be a finite non-zero number, got {scale!r}")
        out[key] = entry
    if ("odometry" in out) == ("pose" in out):
        raise ValueError("topic map: give exactly one of 'odometry' and 'pose'")
    for key in ("thrust", "rates_setpoint"):
        if key not in out:
            raise ValueError(f"topic map: '{key}' is required")
    return out


def _field(message: Any, path: str) -> Any:
    """``message``'s field at a dotted ``path`` whose parts may be indexed (``xyz[2]``)."""
    for part in filter(None, path.split(".")):
        match = _PART.fullmatch(part)
        if match is None:
            raise AttributeError(f"field path {path!r}: {part!r} is not a name or name[index]")
        message = getattr(message, match.group(1))
        if match.group(2) is not None:
            try:
                message = message[int(match.group(2))]
            except (IndexError, TypeError):
                raise AttributeError(f"field path {path!r}: {match.group(1)} has no index {match.group(2)}") from None
    return message


def _numbers(value: Any) -> list[float]:
    if hasattr(value, "w") and hasattr(value, "x"):
        return [float(value.w), float(value.x), float(value.y), float(value.z)]
    if hasattr(value, "x"):
        return [float(value.x), float(value.y), float(value.z)]
    return [float(v) for v in np.atleast_1d(np.asarray(value, dtype=float))]


def _stamp(message: Any, receive_ns: int) -> float:
    header = getattr(message, "header", None)
    if header is not None and (header.stamp.sec or header.stamp.nanosec):
        return header.stamp.sec + 1e-9 * header.stamp.nanosec
    return receive_ns * 1e-9


def _px4_stamp(message: Any) -> float | None:
    """A px4_msgs message's sample time on PX4's clock (s), or None."""
    for name in ("timestamp_sample", "timestamp"):
        value = getattr(message, name, 0)
        if value:
            return float(value) * 1e-6
    return None


def _collect(path: Path, topic_map: dict[str, Any]) -> dict[str, tuple[np.ndarray, list[list[float]], str]]:
    """Every wanted topic's (times, value rows, message type)."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:  # pragma: no cover - a declared dependency
        raise ImportError("reading ROS 2 bags needs rosbags (pip install rosbags)") from None
    wanted: dict[str, list[tuple[str, Any, float | None]]] = {}  # topic -> [(key, field, scale)]
    for key in TOPIC_KEYS:
        if key in topic_map:
            entry = topic_map[key]
            wanted.setdefault(entry["topic"], []).append((key, entry.get("field"), entry.get("scale")))
    found: dict[str, tuple[list[float], list[list[float]], str]] = {}
    px4_times: dict[str, list[float | None]] = {}
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            present = {c.topic: c.msgtype for c in reader.connections}
            missing = sorted(set(wanted) - set(present))
            if missing:
                raise LogFormatError(f"{path}: topic(s) {missing} named in the topic map are not in the bag; "
                                     f"it has {sorted(present)}")
            connections = [c for c in reader.connections if c.topic in wanted]
            unknown = sorted({c.msgtype for c in connections} - set(reader.typestore.fielddefs))
            if unknown:
                raise LogFormatError(f"{path}: message type(s) {unknown} are not standard ROS 2 types and the bag "
                                     "does not carry their definitions; record with MCAP storage (or a ROS 2 "
                                     "release from Iron on), which stores them")
            for connection, receive_ns, raw in reader.messages(connections=connections):
                message = reader.deserialize(raw, connection.msgtype)
                t = _stamp(message, receive_ns)
                for key, field, scale in wanted[connection.topic]:
                    rows = _rows(key, field, scale, message, connection.msgtype, path)
                    times, values, _ = found.setdefault(key, ([], [], connection.msgtype))
                    times.append(t)
                    values.append(rows)
                    px4_times.setdefault(key, []).append(
                        _px4_stamp(message) if connection.msgtype.startswith(_PX4) else None)
    except LogFormatError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises assorted errors for damaged or unknown bags
        raise LogFormatError(f"{path}: not a readable ROS 2 bag ({type(exc).__name__}: {exc})") from None
    if found and all(all(x is not None for x in px4_times[k]) for k in found):  # one clock: PX4's
        return {k: (np.asarray(px4_times[k], dtype=float), v, m) for k, (_, v, m) in found.items()}
    return {k: (np.asarray(t), v, m) for k, (t, v, m) in found.items()}


def _rows(key: str, field: str | list[str] | None, scale: float | None, message: Any, msgtype: str,
          path: Path) -> list[float]:
    try:
        if key == "odometry" and msgtype == _PX4_ODOMETRY:
            # position, q (w, x, y, z: FRD body to the NED world), velocity, body rates, and the velocity's frame
            return [float(x) for x in (*message.position, *message.q, *message.velocity, *message.angular_velocity,
                                       message.velocity_frame)]
        if key == "odometry":
            pose, twist = message.pose.pose, message.twist.twist
            return (_numbers(pose.position) + _numbers(pose.orientation) + _numbers(twist.linear)
                    + _numbers(twist.angular))
        if key == "pose":
            if isinstance(field, list):
                raise LogFormatError(f"{path}: topic map 'pose': field must be one path to a geometry_msgs/Pose, "
                                     f"got {field!r}")
            pose = message.pose if field is None else _field(message, field)
            return _numbers(pose.position) + _numbers(pose.orientation)
        if field is None:
            if msgtype not in DEFAULT_FIELDS:
                raise LogFormatError(f"{path}: topic map '{key}': message type {msgtype} has no default field; "
                                     f"give one with {{topic: ..., field: ...}}")
            field, default_scale = DEFAULT_FIELDS[msgtype]
            scale = default_scale if scale is None else scale
        paths = field if isinstance(field, list) else [field]
        numbers = [x for p in paths for x in _numbers(_field(message, p))]
        return numbers if scale is None else [scale * x for x in numbers]
    except AttributeError as exc:
        raise LogFormatError(f"{path}: topic map '{key}' ({msgtype}): {exc}") from None


def read_bag(path: str | Path, vehicle: NominalVehicle, scene: Any, gravity: float, *,
             topic_map: str | Path | dict | None = None, rate_hz: float | None = None) -> tuple[FlightLog, dict]:
    """The ROS 2 bag at ``path`` as a :class:`FlightLog`, and what the import did."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"flight log {path} does not exist")
    topics = read_topic_map(topic_map)
    raw = _collect(path, topics)
    for key in TOPIC_KEYS:
        if key in topics and key not in raw:
            raise LogFormatError(f"{path}: topic {topics[key]['topic']} ('{key}') has no messages")
    t0 = min(float(times.min()) for times, _, _ in raw.values())

    def signal(key: str, columns: slice | None = None, size: int | None = None) -> Signal:
        times, rows, msgtype = raw[key]
        values = np.asarray(rows, dtype=float)
        if size is not None and values.shape[1] != size:
            raise LogFormatError(f"{path}: topic map '{key}' ({msgtype}) gives {values.shape[1]} number(s) per "
                                 f"message, expected {size}")
        return Signal(key, times - t0, values if columns is None else values[:, columns])

    source = "odometry" if "odometry" in topics else "pose"
    px4_odometry = raw[source][2] == _PX4_ODOMETRY
    if topics["frame"] is None:
        topics["frame"] = "ned" if raw[source][2].startswith(_PX4) else "enu"
    elif px4_odometry and topics["frame"] != "ned":
        raise LogFormatError(f"{path}: topic map: {_PX4_ODOMETRY} is in PX4's NED/FRD frames; set frame: ned "
                             "or leave frame out")
    if topics["thrust_unit"] is None:
        topics["thrust_unit"] = "normalised" if raw["thrust"][2].startswith(_PX4) else "newton"
    twist_in_body = source == "odometry" and topics["odometry_twist_frame"] == "body"
    if px4_odometry:  # each message names its velocity's frame
        velocity_frames = sorted({int(row[13]) for row in raw[source][1]})
        if len(velocity_frames) > 1:
            raise LogFormatError(f"{path}: {_PX4_ODOMETRY}.velocity_frame changes within the bag ({velocity_frames})")
        twist_in_body = velocity_frames == [_PX4_BODY_FRD]
    position = signal(source, slice(0, 3))
    attitude = signal(source, slice(3, 7))
    if source == "odometry":
        velocity = signal(source, slice(7, 10))
        rates = signal("body_rates", size=3) if "body_rates" in topics else signal(source, slice(10, 13))
    else:
        velocity = Signal("velocity", position.t, np.gradient(position.values, position.t, axis=0))
        if "body_rates" not in topics:
            raise LogFormatError(f"{path}: with 'pose' the topic map needs 'body_rates' (e.g. an Imu topic)")
        rates = signal("body_rates", size=3)
    thrust = signal("thrust", size=1)
    rates_cmd = signal("rates_setpoint", size=3)
    states = [position, velocity, attitude, rates]
    commands = [thrust, rates_cmd]
    if rate_hz is None:
        rate_hz = float(np.clip(position.rate_hz, MIN_RATE_HZ, MAX_RATE_HZ))
    if not MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ:
        raise ValueError(f"--rate must be in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {rate_hz:g}")
    t, dropped = gap_free_clock(states, commands, rate_hz)
    if len(t) < 2:
        raise LogFormatError(f"{path}: the topics never overlap without gaps; nothing to import")
    p = interpolate(position, t)
    v = interpolate(velocity, t)
    q = interpolate_attitude(attitude, t)
    omega = interpolate(rates, t)
    omega_cmd = hold(rates_cmd, t)
    if topics["frame"] == "ned":
        p, q = ned_to_enu(p), attitude_frd_ned_to_flu_enu(q)
        v = frd_to_flu(v) if twist_in_body else ned_to_enu(v)
        omega, omega_cmd = frd_to_flu(omega), frd_to_flu(omega_cmd)
    R = quaternions_to_matrices(q)
    if twist_in_body:
        v = np.einsum("nij,nj->ni", R, v)
    u = hold(thrust, t)[:, 0]
    note = "thrust logged in newtons"
    if topics["thrust_unit"] == "normalised":
        if vehicle.thrust_map is not None:
            thrust_map, note = vehicle.thrust_map, "from the vehicle file"
        else:
            fit = fit_thrust_map(t, p, v, R, u, "collective", vehicle.mass, gravity)
            if fit.thrust_map is None:
                raise LogFormatError(f"{path}: the thrust is normalised and cannot be mapped to newtons: {fit.note}; "
                                     "give vehicle.thrust_map in the vehicle file")
            thrust_map, note = fit.thrust_map, fit.note
        u = apply_thrust_map(thrust_map, u)
        vehicle = replace(vehicle, thrust_map=thrust_map)
    elif vehicle.thrust_map is None:
        vehicle = replace(vehicle, thrust_map=ThrustMap("collective", 1.0, "thrust logged in newtons"))
    log = FlightLog(t=t, p_world=p, v_world=v, q_body_to_world=q, omega_body=omega, thrust_cmd=np.clip(u, 0.0, None),
                    omega_cmd_body=omega_cmd, vehicle=vehicle, scene=scene, gravity=gravity, source=str(path))
    info = {"format": "ROS 2 bag", "file": str(path), "rate_hz": round(rate_hz, 3), "samples": int(len(t)),
            "dropped_in_gaps": dropped, "frames": "as logged (ENU/FLU)" if topics["frame"] == "enu" else
            "NED world / FRD body converted to ENU world / FLU body",
            "signals": {k: topics[k] for k in TOPIC_KEYS if k in topics},
            "signal_rates_hz": {s.name: round(s.rate_hz, 2) for s in states + commands},
            "thrust_map": {**vehicle.thrust_map.to_dict(), "note": note} if vehicle.thrust_map else None}
    return log, info
