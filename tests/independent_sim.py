"""A second quadrotor simulator, written apart from the project's physics, for checking discovery.

Nothing here comes from ``wall_env``: plain numpy, RK4 at 500 Hz, a cascaded PID unlike the
project's (acceleration feedback to a thrust vector, attitude to rate commands, body rates
following their commands with a 30 ms lag), a 1.3 kg vehicle, a white force disturbance and
measurement noise, and optionally rotors whose thrust follows the command with a first-order
lag (integrated as a state). The hidden effects are written from the literature forms: wall
suction per rotor (Yang et al., Eq. 6, 10), quadratic drag on the air-relative velocity in a
steady wind, linear body drag, a steady force, a thrust scale (the rotors produce a fixed
share of the thrust they are commanded, lag and all) and an affine thrust map (a scale and an
offset), the image-rotor gain near the ground (Cheeseman and Bennett) and under a ceiling with
Sanchez-Cuevas et al.'s distance offset. Beyond the project's library of effects it flies what
a researcher's data hold: a wall that ends at some height while the sidecar says an infinite
plane, a periodic gust and a zero-mean random one (a force that varies in time), a force that
grows with height, and a take-off from the ground and a landing on it (the vehicle rests on a
stiff, damped contact while the rotors spin up and down). The log is written as the flight-log
format's CSV and sidecar, directly, without the project's writer; the sidecar's scene can be
written wrong (a wall normal pointing into the wall).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

GRAVITY = 9.81
MASS = 1.3
ROTOR_RADIUS = 0.125  # m, the rotors' distance from the centre


def rotor_layout(radius: float, plus: bool = False) -> np.ndarray:
    """Four rotor centres (body frame, m) ``radius`` from the centre: on the diagonals (an x layout) or, with
    ``plus``, on the body axes."""
    if plus:
        return np.array([[radius, 0.0, 0.0], [-radius, 0.0, 0.0], [0.0, radius, 0.0], [0.0, -radius, 0.0]])
    arm = radius / math.sqrt(2.0)
    return np.array([[arm, -arm, 0.0], [-arm, arm, 0.0], [arm, arm, 0.0], [-arm, -arm, 0.0]])


ROTORS_BODY = rotor_layout(ROTOR_RADIUS)


def reach_toward_wall() -> float:
    """m: how far the rotor centres reach toward the wall at x = 0 (along -x), at the heading of the
    :data:`YAW_SWING` that brings them farthest (at yaw 0 when the heading is held)."""
    amplitude = YAW_SWING[0]
    headings = np.linspace(-amplitude, amplitude, 181) if amplitude else np.zeros(1)
    x_body, y_body = ROTORS_BODY[:, 0], ROTORS_BODY[:, 1]
    x_world = np.cos(headings)[:, None] * x_body - np.sin(headings)[:, None] * y_body
    return -float(x_world.min())


_DT = 0.002  # s, integration step
_RATE_LAG = 0.03  # s, body-rate response
REST_HEIGHT = 0.06  # m, height of the centre of mass (and the rotors) resting on the ground's landing gear
_CONTACT_STIFFNESS = 3000.0  # N/m
_CONTACT_DAMPING = 80.0  # N s/m
_CONTACT_FRICTION = 20.0  # N s/m, along the surface, while in contact
#: with a number, the wall at x = 0 (below its ``wall_top`` when one is flown) stops the vehicle: each rotor's guard
#: (this radius, m, around the rotor centre) meets it through the ground's spring, damper and friction; None (the
#: default) lets the vehicle through it
WALL_GUARD_RADIUS: float | None = None
#: the same for the ceiling (when a ceiling effect is flown): the guards meet it at CEILING_Z
CEILING_GUARD_RADIUS: float | None = None
CEILING_Z = 2.0  # m, the ceiling's height when a ceiling effect is flown
#: radii (distance plus offset) at which the image-rotor gain levels off; the library's form levels off at 0.5
GAIN_FLOOR_RADII = 0.6
#: the frame the log and its sidecar are written in: the simulator's world turned by WORLD_TURN (rad) about z, then
#: shifted by WORLD_SHIFT (x, y; m); the flight is the same, only its description moves (the wall's point and normal,
#: a world-frame wind, the vehicle's heading)
WORLD_TURN = 0.0
WORLD_SHIFT = (0.0, 0.0)
#: with a number, a second wall at x = SECOND_WALL_X facing -x (a corridor): the same suction as the first (and
#: ending where it ends), in the sidecar too wherever the first wall is
SECOND_WALL_X: float | None = None
#: the measurement noise's standard deviations (position 1 mm, velocity 1 cm/s, attitude 1 mrad, rates 5 mrad/s,
#: acceleration 0.1 m/s^2) times this
NOISE_SCALE = 1.0
#: the log also has the world-frame acceleration (``ax, ay, az``) as an accelerometer feels it at each row's instant
ACCELEROMETER = False
#: the heading's swing (amplitude rad, period s): the vehicle yaws ``A sin(2 pi t / P)`` about the wall's normal
#: instead of holding yaw 0 (A = 0, the default)
YAW_SWING: tuple[float, float] = (0.0, 0.0)
#: position-loop gains that beat wall suction's pull (its negative stiffness, 2 k_s for two near rotors, reaches
#: 14 N/m at k_s = 7 N/m; the default loop's 1.3 kg x 6 /s^2 = 7.8 N/m let the vehicle through the wall, which this
#: simulator does not stop)
NEAR_WALL = {"kp": [20.0, 6.0, 12.0], "kd": [8.0, 4.0, 6.0], "ki": [2.0, 1.0, 4.0]}


def _R(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q.tolist()  # Python floats: the same arithmetic as numpy's scalars, without their overhead
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a.tolist()
    w2, x2, y2, z2 = b.tolist()
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _turn() -> np.ndarray:
    c, s = math.cos(WORLD_TURN), math.sin(WORLD_TURN)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def from_log_world(vector) -> np.ndarray:
    """A world-frame vector of the log's frame (a fitted wind, a steady force) in the simulator's frame."""
    return _turn().T @ np.asarray(vector, dtype=float)


def _image_gain(radius: float, distance: float, offset: float) -> float:
    """Thrust in ground (or ceiling) effect over thrust far from it: ``1 / (1 - (rho / 4 (d + k2))^2)``, levelling off
    at :data:`GAIN_FLOOR_RADII` radii."""
    d = max(distance + offset, GAIN_FLOOR_RADII * radius)
    return 1.0 / (1.0 - (radius / (4.0 * d)) ** 2)


def _yaw_reference(t: float) -> tuple[float, float]:
    """The heading (rad) and its rate (rad/s) the loop tracks at ``t``: :data:`YAW_SWING`."""
    amplitude, period = YAW_SWING
    if not amplitude:
        return 0.0, 0.0
    omega = 2 * math.pi / period
    return amplitude * math.sin(omega * t), amplitude * omega * math.cos(omega * t)


def _on_wall(effects: dict, at: np.ndarray) -> bool:
    """Whether the point ``at`` faces the wall: below its ``wall_top`` and short of its ``wall_side`` (y)."""
    return bool(at[2] <= effects.get("wall_top", math.inf) and at[1] <= effects.get("wall_side", math.inf))


def _rotor_centres(p: np.ndarray, R: np.ndarray) -> list[list[float]]:
    """The rotor centres ``p + R r`` (world, m) of :data:`ROTORS_BODY`, each as ``R @ r`` computes it (a batched
    ``matmul`` agrees with it bit for bit; ``ROTORS_BODY @ R.T`` does not), as Python floats: only their coordinates
    are read."""
    return (p + np.matmul(R, ROTORS_BODY[:, :, None])[:, :, 0]).tolist()


def hidden_force(effects: dict, p: np.ndarray, v: np.ndarray, R: np.ndarray, t: float = 0.0,
                 produced: float = 0.0, rotors_world: list[list[float]] | None = None) -> np.ndarray:
    """World force (N) of ``effects`` besides the thrust map:

    ``suction`` (k_s, d_thr) of a wall at x = 0 with normal +x (``wall_top``: the wall ends at that height, a rotor
    above it feels nothing; ``wall_side``: it ends at that y, a rotor beyond it feels nothing), and of a second one
    facing it at :data:`SECOND_WALL_X` when there is one;
    ``wind_force`` (3,); ``gust`` (amplitude (3,), frequency Hz): a periodic force; ``quadratic_drag`` (C (3,), wind
    (3,)); ``linear_drag`` (D (3,), body axes); ``height_force`` k (N/m): ``-k z`` along world z, growing with
    height; ``ground`` (radius, offset) and ``ceiling`` (radius, offset): the image-rotor gain of each rotor's share
    of the ``produced`` thrust near the ground (z = 0) and under the ceiling (z = :data:`CEILING_Z`).
    ``rotors_world``: the rotor centres (:func:`_rotor_centres`) when the caller has them already."""
    if rotors_world is None:
        rotors_world = _rotor_centres(p, R)
    force = np.zeros(3)
    if "suction" in effects:
        k_s, d_thr = effects["suction"]
        for at in rotors_world:
            if _on_wall(effects, at):
                force[0] -= k_s * max(0.0, d_thr - max(at[0], 0.0))
                if SECOND_WALL_X is not None:
                    force[0] += k_s * max(0.0, d_thr - max(SECOND_WALL_X - at[0], 0.0))
    if "wind_force" in effects:
        force += np.asarray(effects["wind_force"], dtype=float)
    if "gust" in effects:
        amplitude, frequency = effects["gust"]
        force += np.asarray(amplitude, dtype=float) * math.sin(2 * math.pi * frequency * t)
    if "quadratic_drag" in effects:
        C, wind = (np.asarray(x, dtype=float) for x in effects["quadratic_drag"])
        v_air_body = R.T @ (v - wind)
        force += R @ (-C * np.abs(v_air_body) * v_air_body)
    if "linear_drag" in effects:
        force += R @ (-np.asarray(effects["linear_drag"], dtype=float) * (R.T @ v))
    if "height_force" in effects:
        force[2] -= effects["height_force"] * p[2]
    for key, surface in (("ground", 0.0), ("ceiling", CEILING_Z)):
        if key in effects:
            radius, offset = effects[key]
            extra = 0.0
            for at in rotors_world:
                distance = abs(at[2] - surface)
                extra += (_image_gain(radius, distance, offset) - 1.0) * produced / 4.0
            force += extra * R[:, 2]
    return force


def _pressed_surface(depth: float, v: np.ndarray, axis: int, away: float) -> np.ndarray:
    """Force (N) of a plane pressed ``depth`` m (none when not positive), its normal along world ``axis`` with sign
    ``away``: the contact spring and damper along the normal (never pulling) and friction along the plane."""
    if depth <= 0:
        return np.zeros(3)
    normal = max(0.0, _CONTACT_STIFFNESS * depth - _CONTACT_DAMPING * away * v[axis])
    force = -_CONTACT_FRICTION * v
    force[axis] = away * normal
    return force


_GRAVITY_WORLD = np.array([0.0, 0.0, GRAVITY])


def _derivative(state: np.ndarray, effects: dict, thrust: float, w_cmd: np.ndarray, disturbance: np.ndarray,
                motor_lag: float, t: float, contact: bool) -> np.ndarray:
    """d/dt of the state ``(p, v, q, w, produced thrust)`` (one flat array of 14) with the thrust and rate command
    held and a disturbance force (N)."""
    p, v, q, w, produced = state[0:3], state[3:6], state[6:10], state[10:13], state[13]
    R = _R(q / math.sqrt(q.dot(q)))  # numpy's norm of a vector, without its checks
    if motor_lag > 0:
        thrust_dot = (thrust - produced) / motor_lag
    else:
        produced, thrust_dot = thrust, 0.0
    produced_map = effects.get("thrust_scale", 1.0) * produced + effects.get("thrust_offset", 0.0)
    rotors_world = _rotor_centres(p, R)
    force = produced_map * R[:, 2] + hidden_force(effects, p, v, R, t, produced, rotors_world) + disturbance
    if "turbulence" in effects:
        force = force + effects["turbulence"](t)
    if contact:
        force = force + _pressed_surface(REST_HEIGHT - p[2], v, axis=2, away=1.0)
    if WALL_GUARD_RADIUS is not None:
        # a rotor above a wall's top or beyond its side passes it
        depth = WALL_GUARD_RADIUS - min((at[0] for at in rotors_world if _on_wall(effects, at)), default=math.inf)
        force = force + _pressed_surface(depth, v, axis=0, away=1.0)
    if CEILING_GUARD_RADIUS is not None and "ceiling" in effects:
        depth = CEILING_GUARD_RADIUS - min(CEILING_Z - at[2] for at in rotors_world)
        force = force + _pressed_surface(depth, v, axis=2, away=-1.0)
    derivative = np.empty(14)
    derivative[0:3] = v
    derivative[3:6] = force / MASS - _GRAVITY_WORLD
    derivative[6:10] = 0.5 * _qmul(q, np.array([0.0, *w]))
    derivative[10:13] = (w_cmd - w) / _RATE_LAG
    derivative[13] = thrust_dot
    return derivative


def turbulence(std, time_constant: float, duration: float, seed: int):
    """A zero-mean random force (N) varying over ``time_constant`` s (an Ornstein-Uhlenbeck process per axis,
    stationary standard deviation ``std``), as a function of time; drawn once on a 10 ms grid, interpolated."""
    rng = np.random.default_rng(seed)
    step = 0.01
    n = int(math.ceil(duration / step)) + 2
    decay = math.exp(-step / time_constant)
    values = np.zeros((n, 3))
    values[0] = rng.normal(0.0, 1.0, 3) * std
    kick = np.asarray(std, dtype=float) * math.sqrt(1.0 - decay**2)
    for i in range(1, n):
        values[i] = decay * values[i - 1] + kick * rng.normal(0.0, 1.0, 3)
    values -= values.mean(axis=0)  # zero mean over the flight
    grid = np.arange(n) * step

    def force(t: float) -> np.ndarray:
        return np.array([np.interp(t, grid, values[:, a]) for a in range(3)])

    return force


def _smoothstep(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


#: phases of a flight from the ground (s): rotors stopped, spinning up on the ground, climbing to the survey
IDLE_S, SPIN_UP_S, CLIMB_S = 1.5, 2.0, 3.0
#: and back: descending to the ground, resting on it with the rotors spinning down, stopped again
DESCEND_S, SPIN_DOWN_S = 5.0, 2.0


def fly(effects: dict, centre, amplitude, period, duration: float, rate_hz: float, seed: int,
        force_noise: float = 0.25, motor_lag: float = 0.0, takeoff: bool = False,
        gains: dict | None = None, waypoints: float = 0.0) -> list[tuple]:
    """Track ``centre + amplitude sin(2 pi t / period + phase)``; rows ``(t, p, v, q, w, T_cmd, w_cmd, a)``
    at ``rate_hz``, each with the command applied from then on; the rotors lag it by ``motor_lag`` s.
    ``gains`` (``kp``, ``kd``, ``ki``, each per world axis) replace the position loop's defaults: near a wall or a
    ceiling its pull has a negative stiffness the loop must beat.

    With ``takeoff`` the flight starts and ends resting on the ground below the survey's start: the rotors
    stopped, then spinning up on the ground to 90 % of the weight, a climb to the survey, ``duration`` s of
    survey, a descent onto the ground, and the rotors spinning down and stopped again.

    With ``waypoints`` > 0 the survey holds near ``centre +- amplitude`` and moves briskly between them: the sine is
    replaced by ``tanh(k sin) / tanh(k)`` with ``k = waypoints`` (2: accelerations near 3.3 times the sine's)."""
    rng = np.random.default_rng(seed)
    centre, amplitude, period = (np.asarray(x, dtype=float) for x in (centre, amplitude, period))
    phase = np.array([0.0, 1.0, 2.0])
    omega_ref = 2 * math.pi / period
    start_survey = IDLE_S + SPIN_UP_S if takeoff else 0.0
    end_survey = start_survey + CLIMB_S + duration if takeoff else duration
    total = end_survey + DESCEND_S + 2.0 + SPIN_DOWN_S + IDLE_S if takeoff else duration

    def survey(t):
        s, c = np.sin(omega_ref * t + phase), np.cos(omega_ref * t + phase)
        if not waypoints:
            return centre + amplitude * s, amplitude * omega_ref * c, -amplitude * omega_ref**2 * s
        k = waypoints  # x = tanh(u) / tanh(k), u = k sin: its first and second derivatives by the chain rule
        u, du, ddu = k * s, k * omega_ref * c, -k * omega_ref**2 * s
        x = np.tanh(u)
        slope = (1.0 - x**2) / math.tanh(k)
        return centre + amplitude * x / math.tanh(k), amplitude * slope * du, amplitude * slope * (ddu - 2 * x * du**2)

    ground_point = survey(0.0)[0].copy()
    ground_point[2] = REST_HEIGHT

    def reference(t):
        if not takeoff:
            return survey(t)
        if t < start_survey + CLIMB_S:  # climbing from the ground to the survey's start
            x = (t - start_survey) / CLIMB_S
            target = survey(0.0)[0]
            return ground_point + _smoothstep(x) * (target - ground_point), np.zeros(3), np.zeros(3)
        if t < end_survey:
            return survey(t - start_survey - CLIMB_S)
        x = (t - end_survey) / DESCEND_S  # descending onto the ground (aiming 5 cm into it)
        last = survey(end_survey - start_survey - CLIMB_S)[0]
        below = ground_point - np.array([0.0, 0.0, 0.05])
        return last + _smoothstep(x) * (below - last), np.zeros(3), np.zeros(3)

    # the state (p, v, q, w, produced thrust) as one flat array, read through views of it
    state = np.zeros(14)
    p, v, q, w = state[0:3], state[3:6], state[6:10], state[10:13]
    p[:] = ground_point if takeoff else reference(0.0)[0]
    q[0] = 1.0
    integral = np.zeros(3)
    loop = {"kp": [6.0, 6.0, 12.0], "kd": [4.0, 4.0, 6.0], "ki": [1.0, 1.0, 4.0], **(gains or {})}
    kp, kd, ki = (np.asarray(loop[k], dtype=float) for k in ("kp", "kd", "ki"))
    every = int(round(1.0 / (rate_hz * _DT)))
    thrust, w_cmd = (0.0 if takeoff else MASS * GRAVITY), np.zeros(3)
    state[13] = thrust
    landed_at, landed_thrust = None, 0.0
    rows = []
    for i in range(int(round(total / _DT))):
        t = i * _DT
        if i % every == 0:
            R = _R(q)
            if takeoff and t < start_survey:  # on the ground: stopped, then spinning up
                thrust = 0.9 * MASS * GRAVITY * max(0.0, (t - IDLE_S) / SPIN_UP_S)
                w_cmd = -8.0 * np.array([R[2, 1], -R[2, 0], 0.0])
            elif takeoff and landed_at is not None:  # touched down: spinning down, then stopped
                thrust = max(0.0, landed_thrust * (1.0 - (t - landed_at) / SPIN_DOWN_S))
                w_cmd = -8.0 * np.array([R[2, 1], -R[2, 0], 0.0])
            else:
                p_ref, v_ref, a_ref = reference(t)
                integral += (p_ref - p) * _DT * every
                f_des = MASS * (a_ref + kp * (p_ref - p) + kd * (v_ref - v) + ki * integral + np.array([0, 0, GRAVITY]))
                thrust = float(max(0.0, f_des @ R[:, 2]))
                w_cmd = 8.0 * (R.T @ np.cross(R[:, 2], f_des / np.linalg.norm(f_des)))
                yaw_ref, yaw_rate_ref = _yaw_reference(t)  # yaw held at 0 unless it swings
                yaw_error = math.remainder(math.atan2(R[1, 0], R[0, 0]) - yaw_ref, 2 * math.pi)
                w_cmd[2] = yaw_rate_ref - 2.0 * yaw_error
                if takeoff and t > end_survey + 0.5 * DESCEND_S and p[2] < REST_HEIGHT + 0.003 and abs(v[2]) < 0.05:
                    landed_at, landed_thrust = t, min(thrust, 0.9 * MASS * GRAVITY)
        inputs = (effects, thrust, w_cmd, rng.normal(0.0, force_noise, 3), motor_lag, t, takeoff)
        k1 = _derivative(state, *inputs)
        if i % every == 0:  # the acceleration as an accelerometer feels it at this instant, disturbance and all
            rows.append((t, p.copy(), v.copy(), q.copy(), w.copy(), thrust, w_cmd.copy(), k1[3:6].copy()))
        k2 = _derivative(state + _DT / 2 * k1, *inputs)
        k3 = _derivative(state + _DT / 2 * k2, *inputs)
        k4 = _derivative(state + _DT * k3, *inputs)
        state += _DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        q /= np.linalg.norm(q)
    return rows


def write(rows: list[tuple], path: Path, seed: int, wall: bool = True, *, wall_normal: float = 1.0,
          ceiling: bool = False) -> Path:
    """The rows with measurement noise as ``path`` (CSV) and its sidecar; returns ``path``.

    The sidecar's wall is the plane x = 0 with normal ``(wall_normal, 0, 0)`` (+1 is right: the normal points
    away from the wall, into the flown space; -1 points into the wall, a sidecar error); the ground is z = 0 and
    the ceiling, with ``ceiling``, z = :data:`CEILING_Z`; all in the simulator's frame, written turned and shifted
    by :data:`WORLD_TURN` and :data:`WORLD_SHIFT`."""
    rng = np.random.default_rng(seed + 1)
    turn, shift = _turn(), np.array([*WORLD_SHIFT, 0.0])
    q_turn = np.array([math.cos(WORLD_TURN / 2), 0.0, 0.0, math.sin(WORLD_TURN / 2)])
    lines = ["t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz,thrust_cmd,wx_cmd,wy_cmd,wz_cmd" + (",ax,ay,az" * ACCELEROMETER)]
    for t, p, v, q, w, thrust, w_cmd, a in rows:
        p, v, q = turn @ p + shift, turn @ v, _qmul(q_turn, q)
        q = _qmul(q, np.array([1.0, *rng.normal(0.0, 0.001 * NOISE_SCALE, 3)]))
        values = [t, *(p + rng.normal(0.0, 0.001 * NOISE_SCALE, 3)), *(v + rng.normal(0.0, 0.01 * NOISE_SCALE, 3)),
                  *(q / np.linalg.norm(q)), *(w + rng.normal(0.0, 0.005 * NOISE_SCALE, 3)), thrust, *w_cmd]
        if ACCELEROMETER:
            values += [*(turn @ a + rng.normal(0.0, 0.1 * NOISE_SCALE, 3))]
        lines.append(",".join(f"{x:.9g}" for x in values))
    path.write_text("\n".join(lines) + "\n")
    walls = [{"point": shift.tolist(), "normal": (turn @ [wall_normal, 0.0, 0.0]).tolist()}] if wall else []
    if wall and SECOND_WALL_X is not None:
        walls.append({"point": (turn @ [SECOND_WALL_X, 0.0, 0.0] + shift).tolist(),
                      "normal": (turn @ [-1.0, 0.0, 0.0]).tolist()})
    sidecar = {"vehicle": {"mass": MASS, "rotor_positions": ROTORS_BODY.tolist()},
               "scene": {"walls": walls, "ground_z": 0.0, "ceiling_z": CEILING_Z if ceiling else None},
               "gravity": GRAVITY}
    path.with_suffix(".json").write_text(json.dumps(sidecar))
    return path
