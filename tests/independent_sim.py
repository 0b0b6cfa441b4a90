"""A second quadrotor simulator, written apart from the project's physics, for checking discovery.

Nothing here comes from ``wall_env``: plain numpy, RK4 at 500 Hz, a cascaded PID unlike the
project's (acceleration feedback to a thrust vector, attitude to rate commands, body rates
following their commands with a 30 ms lag), a 1.3 kg vehicle, a white force disturbance and
measurement noise, and optionally rotors whose thrust follows the command with a first-order
lag (integrated as a state). The hidden effects are written from the literature forms: wall
suction per rotor (Yang et al., Eq. 6, 10), quadratic drag on the air-relative velocity in a
steady wind, linear body drag, a steady force, and a thrust scale (the rotors produce a fixed
share of the thrust they are commanded, lag and all). The log is written as the flight-log format's CSV and sidecar,
directly, without the project's writer.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

GRAVITY = 9.81
MASS = 1.3
_ARM = 0.125 / math.sqrt(2.0)
ROTORS_BODY = np.array([[_ARM, -_ARM, 0.0], [-_ARM, _ARM, 0.0], [_ARM, _ARM, 0.0], [-_ARM, -_ARM, 0.0]])
_DT = 0.002  # s, integration step
_RATE_LAG = 0.03  # s, body-rate response


def _R(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def hidden_force(effects: dict, p: np.ndarray, v: np.ndarray, R: np.ndarray) -> np.ndarray:
    """World force (N) of ``effects``: ``suction`` (k_s, d_thr) of a wall at x = 0 with normal +x,
    ``wind_force`` (3,), ``quadratic_drag`` (C (3,), wind (3,)) and ``linear_drag`` (D (3,), body axes)."""
    force = np.zeros(3)
    if "suction" in effects:
        k_s, d_thr = effects["suction"]
        for rotor in ROTORS_BODY:
            distance = (p + R @ rotor)[0]
            force[0] -= k_s * max(0.0, d_thr - max(distance, 0.0))
    if "wind_force" in effects:
        force += np.asarray(effects["wind_force"], dtype=float)
    if "quadratic_drag" in effects:
        C, wind = (np.asarray(x, dtype=float) for x in effects["quadratic_drag"])
        v_air_body = R.T @ (v - wind)
        force += R @ (-C * np.abs(v_air_body) * v_air_body)
    if "linear_drag" in effects:
        force += R @ (-np.asarray(effects["linear_drag"], dtype=float) * (R.T @ v))
    return force


def _derivative(state: tuple, effects: dict, thrust: float, w_cmd: np.ndarray, disturbance: np.ndarray,
                motor_lag: float) -> tuple:
    """d/dt of (p, v, q, w, produced thrust) with the thrust and rate command held and a disturbance force (N)."""
    p, v, q, w, produced = state
    R = _R(q / np.linalg.norm(q))
    if motor_lag > 0:
        thrust_dot = (thrust - produced) / motor_lag
    else:
        produced, thrust_dot = thrust, 0.0
    force = effects.get("thrust_scale", 1.0) * produced * R[:, 2] + hidden_force(effects, p, v, R) + disturbance
    return (v, force / MASS - np.array([0, 0, GRAVITY]), 0.5 * _qmul(q, np.array([0.0, *w])), (w_cmd - w) / _RATE_LAG,
            thrust_dot)


def fly(effects: dict, centre, amplitude, period, duration: float, rate_hz: float, seed: int,
        force_noise: float = 0.25, motor_lag: float = 0.0) -> list[tuple]:
    """Track ``centre + amplitude sin(2 pi t / period + phase)``; rows ``(t, p, v, q, w, T_cmd, w_cmd)``
    at ``rate_hz``, each with the command applied from then on; the rotors lag it by ``motor_lag`` s."""
    rng = np.random.default_rng(seed)
    centre, amplitude, period = (np.asarray(x, dtype=float) for x in (centre, amplitude, period))
    phase = np.array([0.0, 1.0, 2.0])
    omega_ref = 2 * math.pi / period

    def reference(t):
        s, c = np.sin(omega_ref * t + phase), np.cos(omega_ref * t + phase)
        return centre + amplitude * s, amplitude * omega_ref * c, -amplitude * omega_ref**2 * s

    p, v = reference(0.0)[0].copy(), np.zeros(3)
    q, w = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3)
    integral = np.zeros(3)
    kp, kd, ki = np.array([6.0, 6.0, 12.0]), np.array([4.0, 4.0, 6.0]), np.array([1.0, 1.0, 4.0])
    every = int(round(1.0 / (rate_hz * _DT)))
    thrust, w_cmd = MASS * GRAVITY, np.zeros(3)
    produced = thrust
    rows = []
    for i in range(int(round(duration / _DT))):
        t = i * _DT
        if i % every == 0:
            p_ref, v_ref, a_ref = reference(t)
            integral += (p_ref - p) * _DT * every
            f_des = MASS * (a_ref + kp * (p_ref - p) + kd * (v_ref - v) + ki * integral + np.array([0, 0, GRAVITY]))
            R = _R(q)
            thrust = float(max(0.0, f_des @ R[:, 2]))
            w_cmd = 8.0 * (R.T @ np.cross(R[:, 2], f_des / np.linalg.norm(f_des)))
            w_cmd[2] = -2.0 * math.atan2(R[1, 0], R[0, 0])  # yaw held at 0
            rows.append((t, p.copy(), v.copy(), q.copy(), w.copy(), thrust, w_cmd.copy()))
        inputs = (effects, thrust, w_cmd, rng.normal(0.0, force_noise, 3), motor_lag)
        state = (p, v, q, w, produced)
        k1 = _derivative(state, *inputs)
        k2 = _derivative(tuple(x + _DT / 2 * k for x, k in zip(state, k1)), *inputs)
        k3 = _derivative(tuple(x + _DT / 2 * k for x, k in zip(state, k2)), *inputs)
        k4 = _derivative(tuple(x + _DT * k for x, k in zip(state, k3)), *inputs)
        p, v, q, w, produced = (x + _DT / 6 * (a + 2 * b + 2 * c + d) for x, a, b, c, d in zip(state, k1, k2, k3, k4))
        q = q / np.linalg.norm(q)
    return rows


def write(rows: list[tuple], path: Path, seed: int, wall: bool = True) -> Path:
    """The rows with measurement noise as ``path`` (CSV) and its sidecar; returns ``path``."""
    rng = np.random.default_rng(seed + 1)
    lines = ["t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz,thrust_cmd,wx_cmd,wy_cmd,wz_cmd"]
    for t, p, v, q, w, thrust, w_cmd in rows:
        q = _qmul(q, np.array([1.0, *rng.normal(0.0, 0.001, 3)]))
        values = [t, *(p + rng.normal(0.0, 0.001, 3)), *(v + rng.normal(0.0, 0.01, 3)), *(q / np.linalg.norm(q)),
                  *(w + rng.normal(0.0, 0.005, 3)), thrust, *w_cmd]
        lines.append(",".join(f"{x:.9g}" for x in values))
    path.write_text("\n".join(lines) + "\n")
    walls = [{"point": [0.0, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]}] if wall else []
    sidecar = {"vehicle": {"mass": MASS, "rotor_positions": ROTORS_BODY.tolist()},
               "scene": {"walls": walls, "ground_z": 0.0, "ceiling_z": None}, "gravity": GRAVITY}
    path.with_suffix(".json").write_text(json.dumps(sidecar))
    return path
