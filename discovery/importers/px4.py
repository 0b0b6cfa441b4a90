"""PX4 ULog files (``.ulg``) as flight logs, read with ``pyulog``.

Topics used (the first one present wins; older PX4 names in brackets):

=======================  ==========================================================  =====================
what                     topic and fields                                            frame
=======================  ==========================================================  =====================
position, velocity       ``vehicle_local_position`` x, y, z, vx, vy, vz              NED
attitude                 ``vehicle_attitude`` q (body to world, scalar first)        FRD to NED
body rates               ``vehicle_angular_velocity`` xyz (``vehicle_attitude``      FRD
                         rollspeed, pitchspeed, yawspeed; ``sensor_combined``
                         gyro_rad)
body-rate commands       ``vehicle_rates_setpoint`` roll, pitch, yaw                 FRD
collective command       ``vehicle_thrust_setpoint`` -xyz[2] (``vehicle_rates_      normalised, 0..1
                         setpoint`` -thrust_body[2] or thrust;
                         ``actuator_controls_0`` control[3])
motor commands           ``actuator_motors`` control[0..3] (``actuator_outputs``     normalised, 0..1
                         output[0..3], PWM scaled by PWM_MAIN_MINn/MAXn,
                         PWM_MAIN_MIN/MAX or PWM_MIN/MAX,
                         default 1000..2000 us)
=======================  ==========================================================  =====================

Signals are resampled onto one clock (:mod:`discovery.importers.resample`; default
rate: the fastest of attitude, body rates and rate commands, clipped to 50..1000 Hz),
gaps stay gaps, frames are converted (:mod:`discovery.importers.frames`), and the
commands become newtons through the nominal thrust map
(:mod:`discovery.importers.thrust_map`): the vehicle file's ``thrust_map`` if it has
one, else one fitted on the log's hover samples (per motor when the log has motor
commands, which are then written as rotor thrusts, else collective), else the
hover-thrust parameter ``MPC_THR_HOVER`` (``k = m g / MPC_THR_HOVER``). Motor ``j``
of the log is rotor ``j`` of the vehicle file: list ``rotor_positions`` in PX4's
motor order, in the FLU body frame. Time starts at 0 at the log's start.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from discovery.flight_log import FlightLog, LogFormatError, NominalVehicle, ThrustMap
from discovery.importers.frames import attitude_frd_ned_to_flu_enu, frd_to_flu, ned_to_enu
from discovery.importers.resample import (
    Signal,
    gap_free_clock,
    hold,
    interpolate,
    interpolate_attitude,
)
from discovery.importers.thrust_map import apply_thrust_map, fit_thrust_map
from wall_env.scene import Scene

__all__ = ["read_ulog", "MIN_RATE_HZ", "MAX_RATE_HZ"]

MIN_RATE_HZ, MAX_RATE_HZ = 50.0, 1000.0
_MOTORS = 4


class _Topics:
    """The ULog's topics by name (first instance), with field lookup."""

    def __init__(self, path: Path):
        try:
            from pyulog import ULog
        except ImportError:  # pragma: no cover - a declared dependency
            raise ImportError("reading PX4 logs needs pyulog (pip install pyulog)") from None
        try:
            self.ulog = ULog(str(path))
        except Exception as exc:  # noqa: BLE001 - pyulog raises assorted errors on damaged files
            raise LogFormatError(f"{path}: not a readable PX4 ULog file ({type(exc).__name__}: {exc})") from None
        self.path = path
        self.start = self.ulog.start_timestamp
        self.data: dict[str, dict[str, np.ndarray]] = {}
        for d in sorted(self.ulog.data_list, key=lambda d: d.multi_id):
            self.data.setdefault(d.name, d.data)

    def has(self, topic: str, *fields: str) -> bool:
        return topic in self.data and all(f in self.data[topic] for f in fields)

    def signal(self, name: str, topic: str, fields: list[str], scale: float = 1.0) -> Signal:
        data = self.data[topic]
        stamp = data["timestamp_sample"] if "timestamp_sample" in data else data["timestamp"]
        t = (stamp.astype(np.float64) - float(self.start)) * 1e-6
        values = scale * np.column_stack([data[f].astype(float) for f in fields])
        inside = (t >= 0) & (t <= (float(self.ulog.last_timestamp) - float(self.start)) * 1e-6)  # no stale stamps
        return Signal(name, t[inside], values[inside])

    def parameter(self, *names: str, positive: bool = False) -> float | None:
        """The first of ``names`` the log sets (with ``positive``, the first above 0: PX4 writes -1 for unset)."""
        for name in names:
            if name in self.ulog.initial_parameters:
                value = float(self.ulog.initial_parameters[name])
                if value > 0 or not positive:
                    return value
        return None


def _first(topics: _Topics, options: list[tuple[str, list[str], float]], what: str) -> tuple[Signal, str]:
    for topic, fields, scale in options:
        if topics.has(topic, *fields):
            signal = topics.signal(what, topic, fields, scale)
            if len(signal.t) >= 2:
                return signal, f"{topic}." + ",".join(fields)
    tried = "; ".join(f"{t} ({', '.join(f)})" for t, f, _ in options)
    raise LogFormatError(f"{topics.path}: no {what} in the log; looked for topics {tried}")


def _motor_signal(topics: _Topics) -> tuple[Signal, str] | None:
    """The motor commands (0..1) and their source, or None when no motor topic has 2 samples in the log."""
    fields = [f"control[{j}]" for j in range(_MOTORS)]
    if topics.has("actuator_motors", *fields):
        signal = topics.signal("motor commands", "actuator_motors", fields)
        if len(signal.t) >= 2:
            return signal, "actuator_motors.control[0..3]"
    fields = [f"output[{j}]" for j in range(_MOTORS)]
    if topics.has("actuator_outputs", *fields):
        raw = topics.signal("motor commands", "actuator_outputs", fields)
        if len(raw.t) < 2:
            return None
        limits = np.array([_pwm_limits(topics, j + 1) for j in range(_MOTORS)])  # (motors, 2) us
        scaled = np.clip((raw.values - limits[:, 0]) / (limits[:, 1] - limits[:, 0]), 0.0, 1.0)
        ranges = {f"{low:g}..{high:g}" for low, high in limits}
        return (Signal("motor commands", raw.t, scaled),
                f"actuator_outputs.output[0..3] (PWM {', '.join(sorted(ranges))} us)")
    return None


def _pwm_limits(topics: _Topics, channel: int) -> tuple[float, float]:
    """PWM range (us) of output ``channel`` (1-based): its own limits, else the shared ones, else 1000..2000."""
    low = topics.parameter(f"PWM_MAIN_MIN{channel}", "PWM_MAIN_MIN", "PWM_MIN", positive=True) or 1000.0
    high = topics.parameter(f"PWM_MAIN_MAX{channel}", "PWM_MAIN_MAX", "PWM_MAX", positive=True) or 2000.0
    return (low, high) if high > low else (1000.0, 2000.0)


def read_ulog(path: str | Path, vehicle: NominalVehicle, scene: Scene, gravity: float, *,
              rate_hz: float | None = None, thrust_map_kind: str | None = None) -> tuple[FlightLog, dict[str, Any]]:
    """The ULog at ``path`` as a :class:`FlightLog` in the project's frames, and what the import did.

    ``thrust_map_kind`` (``motor_command``, ``motor_command_squared`` or ``collective``)
    chooses the map to fit when the vehicle has none; default ``motor_command`` when
    the log has motor commands, else ``collective``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"flight log {path} does not exist")
    topics = _Topics(path)
    position, position_src = _first(topics, [("vehicle_local_position", ["x", "y", "z"], 1.0)], "position")
    velocity, _ = _first(topics, [("vehicle_local_position", ["vx", "vy", "vz"], 1.0)], "velocity")
    attitude, attitude_src = _first(topics, [("vehicle_attitude", ["q[0]", "q[1]", "q[2]", "q[3]"], 1.0)], "attitude")
    attitude = Signal(attitude.name, attitude.t, attitude.values)
    good_q = np.abs(np.linalg.norm(attitude.values, axis=1) - 1.0) < 0.1
    attitude = Signal(attitude.name, attitude.t[good_q], attitude.values[good_q])
    rates, rates_src = _first(topics, [
        ("vehicle_angular_velocity", ["xyz[0]", "xyz[1]", "xyz[2]"], 1.0),
        ("vehicle_attitude", ["rollspeed", "pitchspeed", "yawspeed"], 1.0),
        ("sensor_combined", ["gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]"], 1.0)], "body rates")
    rates_cmd, rates_cmd_src = _first(topics, [("vehicle_rates_setpoint", ["roll", "pitch", "yaw"], 1.0)],
                                      "body-rate commands")
    collective, collective_src = _first(topics, [
        ("vehicle_thrust_setpoint", ["xyz[2]"], -1.0),
        ("vehicle_rates_setpoint", ["thrust_body[2]"], -1.0),
        ("vehicle_rates_setpoint", ["thrust"], 1.0),
        ("vehicle_attitude_setpoint", ["thrust"], 1.0),
        ("actuator_controls_0", ["control[3]"], 1.0)], "collective thrust command")
    motors = _motor_signal(topics)

    states = [position, velocity, attitude, rates]
    if rate_hz is None:
        rate_hz = float(np.clip(max(attitude.rate_hz, rates.rate_hz, rates_cmd.rate_hz), MIN_RATE_HZ, MAX_RATE_HZ))
    if not MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ:
        raise ValueError(f"--rate must be in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {rate_hz:g}")
    commands = [rates_cmd, collective] + ([motors[0]] if motors else [])
    t, dropped = gap_free_clock(states, commands, rate_hz)
    if len(t) < 2:
        raise LogFormatError(f"{path}: the topics never overlap without gaps; nothing to import")

    p_world = ned_to_enu(interpolate(position, t))
    v_world = ned_to_enu(interpolate(velocity, t))
    q = attitude_frd_ned_to_flu_enu(interpolate_attitude(attitude, t))
    omega = frd_to_flu(interpolate(rates, t))
    omega_cmd = frd_to_flu(hold(rates_cmd, t))
    u_collective = np.clip(hold(collective, t)[:, 0], 0.0, None)
    u_motors = None if motors is None else np.clip(hold(motors[0], t), 0.0, None)

    from discovery.flight_log import quaternions_to_matrices

    R = quaternions_to_matrices(q)
    thrust_map, map_note = _thrust_map(topics, vehicle, gravity, t, p_world, v_world, R, u_collective, u_motors,
                                       thrust_map_kind)
    rotor_thrusts = None
    if thrust_map.kind == "collective" or u_motors is None:
        thrust = apply_thrust_map(thrust_map, u_collective)
    else:
        rotor_thrusts = apply_thrust_map(thrust_map, u_motors)
        thrust = rotor_thrusts.sum(axis=1)
    vehicle = replace(vehicle, thrust_map=thrust_map)
    log = FlightLog(t=t, p_world=p_world, v_world=v_world, q_body_to_world=q, omega_body=omega, thrust_cmd=thrust,
                    omega_cmd_body=omega_cmd, vehicle=vehicle, scene=scene, gravity=gravity,
                    rotor_thrusts=rotor_thrusts, source=str(path))
    info = {
        "format": "PX4 ULog",
        "file": str(path),
        "rate_hz": round(rate_hz, 3),
        "samples": int(len(t)),
        "dropped_in_gaps": dropped,
        "frames": "NED world / FRD body converted to ENU world / FLU body",
        "signals": {"position": position_src, "attitude": attitude_src, "body_rates": rates_src,
                    "body_rate_commands": rates_cmd_src, "collective_command": collective_src,
                    "motor_commands": None if motors is None else motors[1]},
        "signal_rates_hz": {s.name: round(s.rate_hz, 2) for s in states + commands},
        "thrust_map": {**thrust_map.to_dict(), "note": map_note},
    }
    return log, info


def _thrust_map(topics: _Topics, vehicle: NominalVehicle, gravity: float, t: np.ndarray, p_world: np.ndarray,
                v_world: np.ndarray,
                R: np.ndarray, u_collective: np.ndarray, u_motors: np.ndarray | None,
                kind: str | None) -> tuple[ThrustMap, str]:
    if vehicle.thrust_map is not None:
        if vehicle.thrust_map.kind != "collective" and u_motors is None:
            raise LogFormatError(f"{topics.path}: the vehicle's thrust map is per motor "
                                 f"({vehicle.thrust_map.kind}) but the log has no motor commands")
        return vehicle.thrust_map, "from the vehicle file"
    kind = kind or ("motor_command" if u_motors is not None else "collective")
    if kind != "collective" and u_motors is None:
        raise LogFormatError(f"{topics.path}: thrust map kind {kind!r} needs motor commands; the log has none")
    command = u_collective if kind == "collective" or u_motors is None else u_motors
    airborne = None
    if topics.has("vehicle_land_detected", "landed"):
        landed = topics.signal("landed", "vehicle_land_detected", ["landed"])
        if len(landed.t):  # its only sample may be stamped before the log starts
            airborne = hold(landed, t)[:, 0] < 0.5
    fit = fit_thrust_map(t, p_world, v_world, R, command, kind, vehicle.mass, gravity, airborne)
    if fit.thrust_map is not None:
        return fit.thrust_map, fit.note
    hover = topics.parameter("MPC_THR_HOVER")
    if hover is None or not 0.0 < hover < 1.0:
        raise LogFormatError(f"{topics.path}: cannot set the thrust map: {fit.note}, and the log has no "
                             "MPC_THR_HOVER parameter; give vehicle.thrust_map in the vehicle file")
    weight = vehicle.mass * gravity
    coefficient = {"collective": weight / hover, "motor_command": weight / (4 * hover),
                   "motor_command_squared": weight / (4 * hover**2)}[kind]
    source = f"PX4 parameter MPC_THR_HOVER = {hover:g} (no hover to fit: {fit.note})"
    return ThrustMap(kind, coefficient, source), source
