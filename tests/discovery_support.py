"""Helpers for the discovery tests: the hidden-effect protocol and a 1 kHz log straight from the simulator."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from discovery.flight_log import FlightLog, NominalVehicle
from discovery.fly import MeasurementNoise, prepare_flight
from discovery.scenarios import SCENARIOS
from wall_env.dynamics import Simulator, StateIndex
from wall_env.effects import effects_from_spec
from wall_env.model_file import FlightModel
from wall_env.observation import OBSERVATION_FIELDS, OBSERVATION_SIZE
from wall_env.vehicle import VehicleParams

ARM = 0.1 / math.sqrt(2.0)  # the default vehicle's rotor offset along body x (m)


def effect_spec(name: str, params: dict) -> str:
    """The command-line form of one effect, e.g. ``wall_suction:k_s=4.1,d_thr=0.132``."""
    def value(v):
        return "/".join(f"{x:.9g}" for x in v) if isinstance(v, (list, tuple, np.ndarray)) else f"{v:.9g}"

    return name + ":" + ",".join(f"{k}={value(v)}" for k, v in params.items())


def draw_hidden_effect(name: str, rng: np.random.Generator) -> tuple[dict, dict]:
    """Parameters in a realistic range for effect ``name`` and a flight that excites it.

    Returns ``(params, fly keyword arguments)``. The ranges: wall suction k_s 3.5-8 N/m,
    d_thr 0.11-0.15 m (paper: 4.1 N/m, 0.132 m; simulation 1-10 N/m, 0.10 m); ground and
    ceiling effective radius 6-10 cm and 5-8 cm (rotor radius 3.3 cm plus the multirotor
    gain); thrust error 5-15 % either way; steady force 0.15-0.5 N per axis; extra linear
    drag 0.1-0.4 N s/m per axis (nominal 0.3, 0.3, 0.2); quadratic drag 0.05-0.15
    N s^2/m^2 per axis.
    """
    if name == "wall_suction":
        k_s, d_thr = rng.uniform(3.5, 8.0), rng.uniform(0.11, 0.15)
        # near rotors from 3 cm outside the zone to where the pull is at most ~0.5 N (never nearer than 7.5 cm)
        d_min = max(0.075, d_thr - min(0.06, 0.5 / (2 * k_s)))
        d_max = d_thr + 0.03
        survey = {"amplitude": ((d_max - d_min) / 2, 0.6, 0.3), "period": (6.0, 9.0, 5.0),
                  "centre": ((d_max + d_min) / 2 + ARM, 0.0, 1.0)}
        return {"k_s": k_s, "d_thr": d_thr}, {"scenario": "wall-survey", "survey": survey}
    if name == "ground_effect":
        return {"radius": rng.uniform(0.06, 0.10)}, {"scenario": "ground-survey"}
    if name == "ceiling_effect":
        return {"radius": rng.uniform(0.05, 0.08)}, {"scenario": "ceiling-survey"}
    if name == "thrust_scale":
        return {"scale": 1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.05, 0.15)}, {"scenario": "survey"}
    if name == "constant_force":
        return {"F": list(rng.choice([-1.0, 1.0], 3) * rng.uniform(0.15, 0.5, 3))}, {"scenario": "survey"}
    if name == "linear_drag":
        return {"D": list(rng.uniform(0.1, 0.4, 3))}, {"scenario": "survey"}
    if name == "quadratic_drag":
        return {"C": list(rng.uniform(0.05, 0.15, 3))}, {"scenario": "survey"}
    raise ValueError(name)


def relative_errors(fitted: dict, truth: dict) -> list[float]:
    """|fitted - true| / |true| for every parameter entry."""
    out = []
    for key, value in truth.items():
        f, v = np.atleast_1d(np.asarray(fitted[key], float)), np.atleast_1d(np.asarray(value, float))
        out += list(np.abs(f - v) / np.abs(v))
    return out


def simulate_1khz_log(effects: str, scenario: str, duration: float, seed: int,
                      noise: MeasurementNoise = MeasurementNoise()) -> FlightLog:
    """A 1 kHz log of ``scenario`` flown by the PID (at 100 Hz, held) in the compiled simulator.

    The env's control step cannot go below 2 ms, so this steps :class:`wall_env.dynamics.Simulator`
    at 1 ms directly: the same dynamics and effects, the env only supplies the scene and the
    reference. Command noise as in the env (0.2 N, 0.2 rad/s per 10 ms control step).
    """
    from controllers import PID
    from controllers.env_description import describe_env

    preset = SCENARIOS[scenario]
    setup = prepare_flight(preset.env_id, None, preset.env_kwargs, survey=preset.survey, duration=duration)
    env = setup.env
    env.reset(seed=seed)
    description = describe_env(env)
    reference, scene, mapping = description.reference, env.unwrapped.scene, description.action_mapping
    env.close()
    vehicle = VehicleParams()
    truth = FlightModel(vehicle, effects_from_spec(effects)).aero_model()
    simulator = Simulator(vehicle, truth, scene, 0.001, 1)
    pid = PID(description, **preset.policy_kwargs)
    rng = np.random.default_rng(seed)
    n = int(round(duration / 0.001))
    x = simulator.hover_state(reference.position(0.0)[0], np.roll(Rotation.from_euler("z", reference.yaw).as_quat(), 1))
    rows = np.empty((n, 18))
    command = np.zeros(4)
    noisy = np.zeros(4)
    f = OBSERVATION_FIELDS
    for k in range(n):
        t = k * 0.001
        R = Rotation.from_quat(np.roll(x[StateIndex.q_body_to_world], -1)).as_matrix()
        if k % 10 == 0:
            p_ref, v_ref, _ = reference.sample(t)
            obs = np.zeros(OBSERVATION_SIZE)
            obs[f["p_world"]], obs[f["v_world"]] = x[StateIndex.p_world], x[StateIndex.v_world]
            obs[f["R_body_to_world"]] = R.ravel()
            obs[f["omega_body"]] = x[StateIndex.omega_body]
            obs[f["p_error"]] = x[StateIndex.p_world] - p_ref[0]
            obs[f["v_error"]] = x[StateIndex.v_world] - v_ref[0]
            obs[f["time"]] = t
            action, _ = pid.predict(obs, episode_start=np.array([k == 0]))
            command = mapping.to_physical(np.asarray(action, dtype=float))
            noisy = command + rng.normal(0.0, 1.0, 4) * np.array([0.2, 0.2, 0.2, 0.2])
        rows[k, 0] = t
        rows[k, 1:4], rows[k, 4:7] = x[StateIndex.p_world], x[StateIndex.v_world]
        rows[k, 7:11], rows[k, 11:14] = x[StateIndex.q_body_to_world], x[StateIndex.omega_body]
        rows[k, 14:18] = command
        x = simulator.step(x, noisy)[0]
    tilt = Rotation.from_rotvec(rng.normal(0, noise.attitude, (n, 3)))
    q = Rotation.from_quat(np.roll(rows[:, 7:11], -1, axis=1)) * tilt
    q_wxyz = np.roll(q.as_quat(), 1, axis=1)
    return FlightLog(t=rows[:, 0], p_world=rows[:, 1:4] + rng.normal(0, noise.position, (n, 3)),
                     v_world=rows[:, 4:7] + rng.normal(0, noise.velocity, (n, 3)),
                     q_body_to_world=q_wxyz * np.sign(q_wxyz[:, :1]),
                     omega_body=rows[:, 11:14] + rng.normal(0, noise.body_rate, (n, 3)), thrust_cmd=rows[:, 14],
                     omega_cmd_body=rows[:, 15:18], vehicle=NominalVehicle.from_vehicle_params(vehicle), scene=scene)
