"""Record a flight log (CSV + JSON) from the simulator, with measurement noise: :func:`fly`.

The command ``wall-inspector fly`` (:mod:`wall_inspector.fly`) reads its options and calls :func:`fly`::

    wall-inspector fly --env WallInspector/WallSweep-v0 --policy pid \\
        --effects "wall_suction:k_s=4.1,d_thr=0.132" --seed 0 --out flight.csv

What is flown and what is written:

- ``--effects SPEC`` (the effects library's string form, e.g.
  ``"ground_effect:radius=0.08;constant_force:F=0.3/0/0"``) is exactly what the
  simulator adds to the vehicle's nominal drag: the env's default wall suction is
  switched off unless ``wall_suction`` is named, and ``linear_drag`` is extra drag
  added to the vehicle's.
- The JSON's vehicle block holds only the nominal vehicle (mass, rotor positions,
  drag); the effects flown stay out of it, so a log says nothing about what is
  missing. The scene block is the env's scene.
- Each CSV row holds the measured state at its time and the command the policy sent
  for the step that follows. The command is the policy's, before the simulator's
  command noise (paper Sec. 4.1.1), as a flight controller would log it.
- Measurement noise (:class:`MeasurementNoise`, seeded by ``--seed``) is added to
  position, velocity, attitude and body rates (and to acceleration and rotor thrusts
  when ``--with-acceleration`` / ``--with-rotor-thrusts`` write them).
- A third file, ``<name>.scenario.json``, records the ground truth of the simulated
  flight (env id and arguments, effects flown, policy, seed). It is not part of the
  log format; discovery reads it only to run its closed-loop check in the same world.

``--scenario NAME`` picks a ready-made flight from :data:`discovery.scenarios.SCENARIOS`
(its env id and keyword arguments, and the survey reference where it has one).
The log rate ``--rate`` is the env's control rate, 50 Hz to 1 kHz (the env's
``control_dt`` range); the policy runs at ``--control-rate`` (default 100 Hz) and its
command is held in between.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from scipy.spatial.transform import Rotation

import wall_env  # noqa: F401  (registers the environments)
from discovery.flight_log import (
    FlightLog,
    NominalVehicle,
    csv_output_problem,
    file_sha256,
    scenario_path,
    write_log,
)
from discovery.scenarios import SCENARIOS, Retarget, survey_for
from wall_env.effects import Effect, effects_from_spec
from wall_env.vehicle import VehicleParams

__all__ = ["MeasurementNoise", "FlightSetup", "prepare_flight", "make_policy", "record_flight", "fly",
           "scenario_path"]


@dataclass(frozen=True)
class MeasurementNoise:
    """Standard deviations of the measurement noise written into a log (SI).

    Defaults are those of a motion-capture or good visual-inertial state estimate:
    2 mm position, 2 cm/s velocity, 0.3 deg attitude, 0.02 rad/s gyro; an
    accelerometer-grade 0.2 m/s^2 and 0.05 N per rotor thrust estimate.
    """

    position: float = 0.002  # m
    velocity: float = 0.02  # m/s
    attitude: float = 0.005  # rad, per axis, applied in the body frame
    body_rate: float = 0.02  # rad/s
    acceleration: float = 0.2  # m/s^2
    rotor_thrust: float = 0.05  # N

    def scaled(self, factor: float) -> MeasurementNoise:
        return MeasurementNoise(**{k: v * factor for k, v in asdict(self).items()})


@dataclass
class FlightSetup:
    """A ready env plus what the log and the scenario file need to know about it."""

    env: gym.Env
    nominal_vehicle: VehicleParams
    effects: list[Effect]
    scenario: dict[str, Any]


def _effects_list(spec: Any) -> list[Effect]:
    if spec is None or (isinstance(spec, str) and not spec.strip()):
        return []
    return effects_from_spec(spec)


def prepare_flight(env_id: str, effects: Any = None, env_kwargs: dict[str, Any] | None = None, *,
                   survey: dict[str, Any] | None = None, duration: float | None = None,
                   rate_hz: float = 100.0) -> FlightSetup:
    """Build the env that flies ``effects`` on top of the nominal vehicle.

    ``env_kwargs`` are the env's keyword arguments except those that set effects
    (``effects``, ``k_s``, ``d_thr``, ``model``); ``vehicle`` there is the nominal vehicle.
    With ``survey`` (keywords of :func:`discovery.scenarios.survey_for`: ``amplitude``,
    ``period``, ``centre``) the env flies that survey instead of its task's reference.
    """
    kwargs = dict(env_kwargs or {})
    clashing = sorted({"effects", "k_s", "d_thr", "model"} & set(kwargs))
    if clashing:
        raise ValueError(f"env keyword argument(s) {clashing} set effects; give the effects with --effects instead")
    if not 50.0 <= rate_hz <= 1000.0:
        raise ValueError(f"--rate must be in [50, 1000] Hz (the env's control_dt range), got {rate_hz:g}")
    vehicle_arg = kwargs.pop("vehicle", None)
    nominal = (vehicle_arg if isinstance(vehicle_arg, VehicleParams)
               else VehicleParams.from_dict(vehicle_arg) if isinstance(vehicle_arg, dict)
               else VehicleParams.from_file(vehicle_arg) if vehicle_arg is not None else VehicleParams())
    flown = _effects_list(effects)
    names = [e.name for e in flown]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"each effect may be flown once; repeated: {duplicates}")
    true_vehicle = nominal
    env_effects = []
    for effect in flown:
        if effect.name == "linear_drag":  # extra drag on top of the nominal
            true_vehicle = nominal.replace(drag=tuple(np.asarray(nominal.drag) + effect.values["D"]))
        else:
            env_effects.append(effect)
    if "wall_suction" not in names:
        kwargs["k_s"] = 0.0  # only the effects named are flown
    kwargs["control_dt"] = 1.0 / rate_hz
    if duration is not None:
        kwargs["duration"] = float(duration)
    env = gym.make(env_id, vehicle=true_vehicle, effects=env_effects or None, **kwargs)
    if survey is not None:
        unknown = sorted(set(survey) - {"amplitude", "period", "centre"})
        if unknown:
            raise ValueError(f"unknown survey key(s) {unknown}; allowed: amplitude, period, centre")
        env = Retarget(env, survey_for(env, **survey))
        survey = {k: list(v) for k, v in survey.items()}
    public_kwargs = {k: v for k, v in kwargs.items() if k not in ("k_s",)}
    if vehicle_arg is not None:
        public_kwargs["vehicle"] = nominal.to_dict()
    scenario = {"env_id": env_id, "env_kwargs": public_kwargs, "effects": [e.to_dict() for e in flown],
                "survey": survey}
    return FlightSetup(env, nominal, flown, scenario)


def make_policy(policy: str, env: gym.Env, model: str | Path | None = None,
                policy_kwargs: dict[str, Any] | None = None) -> Any:
    """``pid``, ``mpc``, ``scmpc`` (from :mod:`controllers`) or the path of a saved Stable-Baselines3 agent.

    ``policy_kwargs`` go to the controller's ``from_env`` (e.g. ``{"kp": [20, 20, 10]}`` for the PID).
    The controllers start from the authors' settings (``preset="paper"``), around which the
    scenarios' gains were chosen, so that a log does not change when a tuned preset does;
    ``{"preset": "tuned"}`` flies the task's tuned preset instead.
    """
    name = str(policy).lower()
    kwargs = dict(policy_kwargs or {})
    if name in ("pid", "mpc", "scmpc"):
        import controllers

        cls: Any = {"pid": controllers.PID, "mpc": controllers.MPC, "scmpc": controllers.SCMPC}[name]
        if model is not None:
            if name != "scmpc":
                raise ValueError("--policy-model is for --policy scmpc")
            kwargs["model"] = str(model)
        kwargs.setdefault("preset", "paper")
        return cls.from_env(env, **kwargs)
    if kwargs:
        raise ValueError("--policy-kwargs is for pid, mpc and scmpc")
    path = Path(policy)
    if not path.exists():
        raise FileNotFoundError(f"--policy must be pid, mpc, scmpc or the path of a saved agent; {path} does not exist")
    from agents.policy import load_policy  # a checkpoint folder or its model.zip, with its VecNormalize statistics

    return load_policy(path, env=env)


def record_flight(env: gym.Env, policy: Any, *, seed: int, nominal_vehicle: VehicleParams,
                  noise: MeasurementNoise | None = MeasurementNoise(), control_every: int = 1,
                  with_acceleration: bool = False, with_rotor_thrusts: bool = False,
                  progress: bool = False) -> tuple[FlightLog, dict[str, Any]]:
    """Fly one episode and return the log and a summary (steps, collisions, how it ended, truth).

    Row ``k`` holds the measured state before step ``k``, the command of step ``k`` and (optionally)
    the rotor thrusts that command produced over the step.
    """
    base: Any = env.unwrapped
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x10C]))
    obs, info = env.reset(seed=int(seed))
    states, commands, thrusts, effect_forces = [], [], [], []
    action = np.zeros(4)
    state = None
    terminated = truncated = False
    step = 0
    n_steps = base.n_steps
    iterator: Any = range(n_steps)
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc="fly", unit="step", leave=False)
    for step in iterator:
        if step % control_every == 0:
            action, state = policy.predict(obs, state=state, episode_start=np.array([step == 0]), deterministic=True)
        action = np.asarray(action, dtype=float).reshape(4)
        command = base.action_mapping.to_physical(action)
        states.append((info["time"], info["p_world"], info["v_world"], info["q_body_to_world"], info["omega_body"]))
        commands.append(command)
        obs, _, terminated, truncated, info = env.step(action)
        thrusts.append(info["rotor_thrusts"])  # what this step's command made the rotors produce
        effect_forces.append(info["effect_forces_world"])
        if terminated or truncated:
            break
    final_v = info["v_world"]
    n = len(states)
    t = np.array([s[0] for s in states])
    p = np.array([s[1] for s in states])
    v = np.array([s[2] for s in states])
    q = np.array([s[3] for s in states])
    w = np.array([s[4] for s in states])
    u = np.array(commands)
    f = np.array(thrusts)
    dt = base.control_dt
    a = None
    if with_acceleration:
        v_all = np.vstack([v, final_v])
        a = np.gradient(v_all, dt, axis=0)[:n]
    noise = noise or MeasurementNoise().scaled(0.0)
    p_m = p + rng.normal(0.0, noise.position, p.shape)
    v_m = v + rng.normal(0.0, noise.velocity, v.shape)
    rot = Rotation.from_quat(np.column_stack([q[:, 1:], q[:, :1]])) * Rotation.from_rotvec(
        rng.normal(0.0, noise.attitude, (n, 3)))
    q_xyzw = rot.as_quat()
    q_m = np.column_stack([q_xyzw[:, 3:], q_xyzw[:, :3]])
    q_m *= np.sign(q_m[:, :1] + 1e-300)  # scalar part >= 0
    w_m = w + rng.normal(0.0, noise.body_rate, w.shape)
    a_m = None if a is None else a + rng.normal(0.0, noise.acceleration, a.shape)
    f_m = np.clip(f + rng.normal(0.0, noise.rotor_thrust, f.shape), 0.0, None) if with_rotor_thrusts else None
    log = FlightLog(t=t, p_world=p_m, v_world=v_m, q_body_to_world=q_m, omega_body=w_m, thrust_cmd=u[:, 0],
                    omega_cmd_body=u[:, 1:], vehicle=NominalVehicle.from_vehicle_params(nominal_vehicle),
                    scene=base.scene, gravity=9.81, a_world=a_m, rotor_thrusts=f_m, source="<flown>")
    names = list(effect_forces[0]) if effect_forces else []
    summary = {
        "steps": n,
        "duration_s": float(n * dt),
        "terminated": bool(terminated),
        "collisions": int(info.get("collisions", 0)),
        "strayed": bool(info.get("strayed", False)),
        "effect_forces_world": {k: np.array([e[k] for e in effect_forces]) for k in names},
    }
    return log, summary


def fly(env_id: str | None = None, policy: str = "pid", effects: Any = None, seed: int = 0,
        out: str | Path | None = None, *, scenario: str | None = None, env_kwargs: dict[str, Any] | None = None,
        survey: dict[str, Any] | None = None, duration: float | None = None, rate_hz: float = 100.0,
        control_rate_hz: float | None = None, noise: MeasurementNoise | None = MeasurementNoise(),
        policy_model: str | Path | None = None, policy_kwargs: dict[str, Any] | None = None,
        with_acceleration: bool = False, with_rotor_thrusts: bool = False, overwrite: bool = False,
        progress: bool = False) -> tuple[FlightLog, dict[str, Any]]:
    """Fly and (if ``out`` is given) write ``out`` (CSV), its JSON sidecar and the scenario file.

    ``scenario`` names a preset of :data:`~discovery.scenarios.SCENARIOS` whose env id, env
    keywords, survey and (for the PID) controller keywords are the defaults of the
    other arguments. Returns the log and a summary (steps, collisions, the true effect
    forces per step, the scenario record).
    """
    if out is not None:
        problem = csv_output_problem(out, overwrite, (scenario_path(out),))
        if problem:
            raise (FileExistsError if "exists" in problem else ValueError)(problem)
    env_kwargs = dict(env_kwargs or {})
    policy_kwargs = dict(policy_kwargs or {})
    if scenario is not None:
        if scenario not in SCENARIOS:
            raise ValueError(f"unknown scenario {scenario!r}; known: {sorted(SCENARIOS)}")
        preset = SCENARIOS[scenario]
        env_id = env_id or preset.env_id
        env_kwargs = {**preset.env_kwargs, **env_kwargs}
        if str(policy).lower() == "pid":
            policy_kwargs = {**preset.policy_kwargs, **policy_kwargs}
        survey = survey if survey is not None else preset.survey
    env_id = env_id or "WallInspector/WallSweep-v0"
    setup = prepare_flight(env_id, effects, env_kwargs, survey=survey, duration=duration, rate_hz=rate_hz)
    control_rate = min(rate_hz, 100.0) if control_rate_hz is None else float(control_rate_hz)
    every = rate_hz / control_rate
    if every < 1 - 1e-9 or abs(every - round(every)) > 1e-6:
        raise ValueError(f"--rate ({rate_hz:g} Hz) must be a whole multiple of --control-rate ({control_rate:g} Hz)")
    try:
        controller = make_policy(policy, setup.env, policy_model, policy_kwargs)
        log, summary = record_flight(setup.env, controller, seed=seed, nominal_vehicle=setup.nominal_vehicle,
                                     noise=noise, control_every=int(round(every)), with_acceleration=with_acceleration,
                                     with_rotor_thrusts=with_rotor_thrusts, progress=progress)
    finally:
        setup.env.close()
    record = {
        **setup.scenario,
        "policy": str(policy),
        "policy_model": None if policy_model is None else str(policy_model),
        "policy_kwargs": dict(policy_kwargs or {}),
        "scenario": scenario,
        "seed": int(seed),
        "rate_hz": float(rate_hz),
        "control_rate_hz": control_rate,
        "measurement_noise": asdict(noise) if noise is not None else None,
        "note": "ground truth of a simulated flight; not part of the log format. Discovery reads it only to "
                "run the closed-loop check in the same world.",
    }
    summary["scenario"] = record
    if out is not None:
        csv_path, json_path = write_log(log, out, overwrite=overwrite)
        truth = scenario_path(csv_path)
        if truth.exists() and not overwrite:
            raise FileExistsError(f"{truth} exists; pass overwrite=True (or --overwrite) to replace it")
        record["log_sha256"] = file_sha256(csv_path)  # the closed-loop check calls this world ground truth of that log
        truth.write_text(json.dumps(record, indent=2) + "\n")
        summary["files"] = [str(csv_path), str(json_path), str(truth)]
        log.source = str(csv_path)
    return log, summary
