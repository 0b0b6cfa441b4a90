"""The Gymnasium environment: a quadrotor near walls, with the paper's wall-suction dynamics.

One class serves every task (:mod:`wall_env.tasks`); ``gym.make("WallInspector/WallSweep-v0")``
picks the task and any keyword below changes it.

Action
    ``Box(-1, 1, (4,))``: collective thrust and body rates, see :mod:`wall_env.actions`.
    Command noise (paper Sec. 4.1.1: T + N(0, 0.2 N), body rates + N(0, 0.2 rad/s)
    per axis) is added to the physical command, drawn from the env's seeded generator.
Observation
    ``Box((48,), float32)``, see :mod:`wall_env.observation`.
Reward (weights in ``reward_weights``)
    ``alive - position * |p_error| - velocity * |v_error| - smoothness * |a - a_prev|^2
    - body_rate * |omega|^2``, minus ``collision_penalty`` on a collision and when the
    vehicle strays more than ``max_tracking_error`` from the reference.
Reset options
    ``{"perturb_start": False}`` starts exactly on the reference (default: a uniform
    perturbation of position, velocity and attitude whose size each task sets).
Episode end
    terminated on a collision (unless ``terminate_on_collision=False``, when the vehicle
    bounces off and the collision is counted) or when straying; truncated at the
    reference's end (``duration``).
Info
    true state (``p_world``, ``q_body_to_world`` [w, x, y, z], ``v_world``, ``omega_body``,
    ``rotor_thrusts``), reference (``p_ref``, ``v_ref``), ``suction_force_world`` (N,
    mean over the step), ``effect_forces_world`` (per effect), ``collision`` (bool),
    ``collision_surface``, ``collisions`` (count this episode), ``wall_clearance``
    (m, nearest duct edge to a wall), ``command`` (the noisy physical command), ``time``.

Public attributes that controllers may read (never the simulator's effect settings):
``vehicle``, ``scene``, ``reference``, ``action_mapping``, ``nominal_model``,
``control_dt``, ``time``, ``task``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from scipy.spatial.transform import Rotation

from wall_env.actions import ActionMapping
from wall_env.aero import AeroModel
from wall_env.bullet_world import BulletWorld
from wall_env.dynamics import STATE_SIZE, Simulator, StateIndex
from wall_env.effects import effects_from_spec, make_effect
from wall_env.model_file import FlightModel, nominal_aero_model
from wall_env.observation import (
    CLEARANCE_CAP,
    OBSERVATION_FIELDS,
    OBSERVATION_SIZE,
    PREVIEW_DT,
    PREVIEW_STEPS,
    observation_bounds,
)
from wall_env.references import Reference
from wall_env.scene import Scene
from wall_env.tasks import TASKS, TaskSpec, min_standoff
from wall_env.validation import check_positive, check_range
from wall_env.vehicle import VehicleParams

__all__ = ["WallInspectorEnv", "DEFAULT_REWARD_WEIGHTS"]

DEFAULT_REWARD_WEIGHTS = {"alive": 1.0, "position": 2.0, "velocity": 0.2, "smoothness": 0.1, "body_rate": 0.01}
_RANDOMIZABLE = ("k_s", "d_thr", "standoff", "mass")


def _load_vehicle(vehicle: Any) -> VehicleParams:
    if vehicle is None:
        return VehicleParams()
    if isinstance(vehicle, VehicleParams):
        return vehicle
    if isinstance(vehicle, dict):
        return VehicleParams.from_dict(vehicle)
    if isinstance(vehicle, (str, Path)):
        return VehicleParams.from_file(vehicle)
    raise ValueError(f"vehicle must be a VehicleParams, a dict or a JSON/YAML path, got {type(vehicle).__name__}")


class WallInspectorEnv(gym.Env):
    """Quadrotor near walls. See the module docstring for spaces, reward and info.

    Parameters
    ----------
    task: ``"WallHover"``, ``"WallCircle"``, ``"WallSweep"`` or ``"Corridor"``.
    k_s, d_thr: wall-suction scale (N/m, default 4.1) and threshold (m, default 0.132).
    standoff: wall to reference centre of mass (m; corridor: half-width). Task default if None.
    altitude, duration: reference height (m) and episode length (s). Task defaults if None.
    task_params: shape parameters of the task's reference (:class:`~wall_env.tasks.TaskParameter`),
        e.g. ``{"radius": 0.3, "period": 6.0}`` for ``WallCircle``; defaults for those not given.
    noise: add command noise; ``thrust_noise_std`` (N) and ``rate_noise_std`` (rad/s) set it.
    effects: further effects in the simulator, e.g. ``{"ground_effect": {"radius": 0.08}}``, or
        options of the suction, ``{"wall_suction": {"thrust_scaling": True}}``.
    vehicle: :class:`VehicleParams`, a dict of its fields or a JSON/YAML file.
    model: a model file (:class:`~wall_env.model_file.FlightModel`) that sets the vehicle and
        every effect of the simulator; then ``vehicle``, ``k_s``, ``d_thr`` and ``effects`` must be unset.
    randomize: per-episode uniform ranges, e.g. ``{"k_s": (2, 8), "mass": (0.9, 1.1)}``, for
        ``k_s``, ``d_thr``, ``standoff``, ``mass``.
    terminate_on_collision, collision_penalty, restitution: what a collision does.
    max_tracking_error: distance from the reference (m) that ends the episode.
    reward_weights: overrides of :data:`DEFAULT_REWARD_WEIGHTS`.
    control_dt: control period (s, default 0.01 = 100 Hz); physics_substeps: RK4 steps per control step.
    motor_time_constant: first-order rotor lag (s), overriding the vehicle's.
    ground_z, ceiling_z: heights of ground and ceiling planes (m); ``ceiling_z=None`` for none.
    render_mode: ``"rgb_array"`` (headless) or ``"human"`` (needs a display).
    """

    # "human" opens PyBullet's window, so it is offered only where there is a display.
    metadata = {"render_modes": ["rgb_array", *(["human"] if os.environ.get("DISPLAY") else [])], "render_fps": 25}

    def __init__(
        self,
        task: str = "WallHover",
        *,
        k_s: float | None = None,
        d_thr: float | None = None,
        standoff: float | None = None,
        altitude: float | None = None,
        duration: float | None = None,
        task_params: dict[str, float] | None = None,
        noise: bool = True,
        thrust_noise_std: float = 0.2,
        rate_noise_std: float = 0.2,
        effects: Any = None,
        vehicle: Any = None,
        model: str | Path | FlightModel | None = None,
        randomize: dict[str, tuple[float, float]] | None = None,
        terminate_on_collision: bool = True,
        collision_penalty: float = 10.0,
        restitution: float = 0.3,
        max_tracking_error: float = 1.0,
        reward_weights: dict[str, float] | None = None,
        control_dt: float = 0.01,
        physics_substeps: int = 10,
        motor_time_constant: float | None = None,
        ground_z: float | None = 0.0,
        ceiling_z: float | None = None,
        render_mode: str | None = None,
        render_size: tuple[int, int] = (480, 360),
    ):
        super().__init__()
        if task not in TASKS:
            raise ValueError(f"task must be one of {sorted(TASKS)}, got {task!r}")
        if render_mode == "human" and "human" not in self.metadata["render_modes"]:
            raise ValueError("render_mode='human' needs a display (DISPLAY is not set); use render_mode='rgb_array'")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.task: TaskSpec = TASKS[task]
        self.render_mode = render_mode
        self.render_size = (int(render_size[0]), int(render_size[1]))

        # ---------------------------------------------------------- vehicle and effects
        if model is not None:
            clashing = [n for n, v in (("vehicle", vehicle), ("k_s", k_s), ("d_thr", d_thr), ("effects", effects)) if v is not None]
            if clashing:
                raise ValueError(f"model sets the vehicle and every effect; do not also pass {clashing}")
            flight_model = model if isinstance(model, FlightModel) else FlightModel.load(model)
            vehicle_params = flight_model.vehicle
            truth = flight_model.aero_model()
        else:
            vehicle_params = _load_vehicle(vehicle)
            truth = self._truth_model(vehicle_params, k_s, d_thr, effects)
        if motor_time_constant is not None:
            vehicle_params = vehicle_params.replace(
                motor_time_constant=check_range("motor_time_constant", motor_time_constant, 0.0, 1.0))
        self.vehicle: VehicleParams = vehicle_params
        self.nominal_model: AeroModel = nominal_aero_model(vehicle_params)
        self.action_mapping = ActionMapping.for_vehicle(vehicle_params)
        self._truth = truth

        # ---------------------------------------------------------- timing, noise, reward
        self.control_dt = check_range("control_dt", control_dt, 0.001, 0.05)
        if not isinstance(physics_substeps, int) or not 1 <= physics_substeps <= 100:
            raise ValueError(f"physics_substeps must be an integer in [1, 100], got {physics_substeps!r}")
        self.noise = bool(noise)
        self._noise_std = np.array([
            check_range("thrust_noise_std", thrust_noise_std, 0.0, 10.0),
            *[check_range("rate_noise_std", rate_noise_std, 0.0, 10.0)] * 3,
        ]) * float(self.noise)
        self.terminate_on_collision = bool(terminate_on_collision)
        self.collision_penalty = check_range("collision_penalty", collision_penalty, 0.0, 1e6)
        self.restitution = check_range("restitution", restitution, 0.0, 1.0)
        self.max_tracking_error = check_positive("max_tracking_error", max_tracking_error, high=100.0)
        unknown = sorted(set(reward_weights or {}) - set(DEFAULT_REWARD_WEIGHTS))
        if unknown:
            raise ValueError(f"unknown reward_weights key(s) {unknown}; allowed: {sorted(DEFAULT_REWARD_WEIGHTS)}")
        self.reward_weights = {**DEFAULT_REWARD_WEIGHTS, **{k: float(v) for k, v in (reward_weights or {}).items()}}

        # ---------------------------------------------------------- geometry
        self._min_standoff = min_standoff(vehicle_params, self.task.wall_axis) + self.task.closest_approach
        self.standoff = self._check_standoff(self.task.standoff if standoff is None else standoff)
        self.altitude = check_range("altitude", self.task.altitude if altitude is None else altitude, 0.1, 100.0)
        self.duration = check_range("duration", self.task.duration if duration is None else duration, 0.05, 3600.0)
        if ground_z is not None:
            ground_z = check_range("ground_z", ground_z, -100.0, self.altitude - 0.3)
        if ceiling_z is not None:
            ceiling_z = check_range("ceiling_z", ceiling_z, self.altitude + 0.1, 1000.0)
        self._base_scene = Scene((), ground_z, ceiling_z)
        self.randomize = self._check_randomize(randomize or {})
        self.task_params = self.task.check_params(task_params)
        self.scene, self.reference = self.task.scene_and_reference(self.standoff, self.altitude, self.duration,
                                                                   self._base_scene, self.task_params)

        # ---------------------------------------------------------- simulator and PyBullet
        self._simulator = Simulator(vehicle_params, truth, self.scene, self.control_dt, physics_substeps)
        self._suction_index = truth.names.index("wall_suction") if "wall_suction" in truth.names else None
        self._world = BulletWorld(vehicle_params, self.scene, gui=render_mode == "human")

        # ---------------------------------------------------------- spaces
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self.observation_space = spaces.Box(*observation_bounds(), shape=(OBSERVATION_SIZE,), dtype=np.float32)
        self.n_steps = int(round(self.duration / self.control_dt))
        self._preview_stride = max(1, int(round(PREVIEW_DT / self.control_dt)))

        # ---------------------------------------------------------- episode state
        self.time = 0.0
        self._step_index = 0
        self._x = np.zeros(STATE_SIZE)
        self._previous_action = np.zeros(4)
        self._collisions = 0
        self._reference_cache: tuple[Reference, np.ndarray, np.ndarray] | None = None
        self._episode_theta = truth.theta()
        self._rotor_distances = np.zeros((len(self.scene.walls), 4))

    # ================================================================== construction helpers
    @staticmethod
    def _truth_model(vehicle: VehicleParams, k_s, d_thr, effects) -> AeroModel:
        """Nominal drag + wall suction (keywords or ``effects``) + any further effects."""
        extra = effects_from_spec(effects)
        suction = next((e for e in extra if e.name == "wall_suction"), None)
        explicit = _explicit_params(effects, "wall_suction")
        clashing = [n for n, v in (("k_s", k_s), ("d_thr", d_thr)) if v is not None and n in explicit]
        if clashing:
            raise ValueError(f"wall_suction {clashing} given both as keyword and in effects")
        params = suction.params_dict() if suction is not None else {}
        params.update({n: v for n, v in (("k_s", k_s), ("d_thr", d_thr)) if v is not None})
        options = suction.option_values if suction is not None else {}
        model = nominal_aero_model(vehicle)
        for effect in extra:
            if effect.name == "linear_drag":
                raise ValueError("linear_drag is the vehicle's drag: set it with vehicle={'drag': [...]}")
            if effect.name != "wall_suction":
                model = model.with_effect(effect)
        return model.with_effect(make_effect("wall_suction", **params, **options))

    def _check_standoff(self, value: float) -> float:
        return check_range("standoff", value, self._min_standoff, 5.0)

    def _check_randomize(self, ranges: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        unknown = sorted(set(ranges) - set(_RANDOMIZABLE))
        if unknown:
            raise ValueError(f"randomize keys must be among {list(_RANDOMIZABLE)}, got {unknown}")
        suction = self._truth.get("wall_suction")
        limits = {
            "k_s": next(p for p in suction.parameters if p.name == "k_s"),
            "d_thr": next(p for p in suction.parameters if p.name == "d_thr"),
        } if suction is not None else {}
        checked = {}
        for key, bounds in ranges.items():
            try:
                low, high = (float(b) for b in bounds)
            except (TypeError, ValueError):
                raise ValueError(f"randomize[{key!r}] must be a (low, high) pair, got {bounds!r}") from None
            if not low <= high:
                raise ValueError(f"randomize[{key!r}] must have low <= high, got ({low}, {high})")
            if key == "standoff":
                self._check_standoff(low), self._check_standoff(high)
            elif key == "mass":
                check_range("randomize['mass']", low, 0.05, self.vehicle.thrust_max / 9.81 * 0.9)
                check_range("randomize['mass']", high, 0.05, self.vehicle.thrust_max / 9.81 * 0.9)
            else:
                if key not in limits:
                    raise ValueError(f"randomize[{key!r}] needs the wall_suction effect in the simulator")
                for b in (low, high):
                    check_range(f"randomize[{key!r}]", b, limits[key].low, limits[key].high)
            checked[key] = (low, high)
        return checked

    # ================================================================== gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        rng = self.np_random
        sample = {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in self.randomize.items()}
        self.episode_parameters = sample

        theta = self._truth.theta()
        if self._suction_index is not None and ("k_s" in sample or "d_thr" in sample):
            suction = self._truth.effects[self._suction_index]
            values = {**suction.params_dict(), **{k: sample[k] for k in ("k_s", "d_thr") if k in sample}}
            theta[self._truth.slices()[self._suction_index]] = type(suction)(**values, **suction.option_values).param_vector()
        mass = sample.get("mass", self.vehicle.mass)
        standoff = sample.get("standoff", self.standoff)
        scene, reference = self.task.scene_and_reference(standoff, self.altitude, self.duration, self._base_scene,
                                                         self.task_params)
        if scene != self.scene:
            self._world.close()
            self._world = BulletWorld(self.vehicle, scene, gui=self.render_mode == "human")
        self.scene, self.reference = scene, reference
        self._simulator.set_parameters(mass=mass, theta=theta, scene=scene)
        self._episode_theta = theta
        self._prepare_reference(reference)

        unknown = sorted(set(options or {}) - {"perturb_start"})
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: ['perturb_start']")
        spread = 1.0 if (options or {}).get("perturb_start", True) else 0.0
        task = self.task
        p0 = self._ref_p[0] + rng.uniform(-1, 1, 3) * task.start_position_noise * spread
        v0 = self._ref_v[0] + rng.uniform(-1, 1, 3) * task.start_velocity_noise * spread
        tilt = rng.uniform(-1, 1, 3) * task.start_attitude_noise * spread
        attitude = Rotation.from_euler("xyz", [tilt[0], tilt[1], reference.yaw + tilt[2]])
        q_xyzw = attitude.as_quat()
        x = np.zeros(STATE_SIZE)
        x[StateIndex.p_world] = p0
        x[StateIndex.q_body_to_world] = np.roll(q_xyzw, 1)
        x[StateIndex.v_world] = v0
        x[StateIndex.rotor_thrusts] = mass * 9.81 / 4.0
        self._x = x
        self._step_index = 0
        self.time = 0.0
        self._previous_action = np.zeros(4)
        self._collisions = 0
        self._R = attitude.as_matrix()
        rotors_world = p0 + self.vehicle.rotor_positions_array @ self._R.T
        self._rotor_distances = self.scene.wall_distances(rotors_world)
        self._last_info = self._info(np.zeros((3, len(self._truth.effects))), None, np.zeros(4))
        return self._observation(), dict(self._last_info)

    def step(self, action):
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (4,):
            raise ValueError(f"action must have 4 entries (thrust, wx, wy, wz in [-1, 1]), got shape {np.shape(action)}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a.tolist()}")
        a = np.minimum(np.maximum(a, -1.0), 1.0)
        command = self.action_mapping.to_physical(a)
        if self.noise:
            command = command + self.np_random.normal(0.0, 1.0, 4) * self._noise_std

        x_next, effect_forces, distances, R = self._simulator.step(self._x, command)
        self._step_index += 1
        self.time = self._step_index * self.control_dt

        contacts = self._world.contacts(x_next[StateIndex.p_world], x_next[StateIndex.q_body_to_world])
        surface = None
        if contacts:
            surface = contacts[0].surface
            self._collisions += 1
            x_next = self._bounce(x_next, contacts)
            rotors_world = x_next[StateIndex.p_world] + self.vehicle.rotor_positions_array @ R.T
            distances = self.scene.wall_distances(rotors_world)
        self._x = x_next
        self._R = R
        self._rotor_distances = distances

        i = self._step_index
        p_error = x_next[StateIndex.p_world] - self._ref_p[i]
        v_error = x_next[StateIndex.v_world] - self._ref_v[i]
        error = math.sqrt(float(p_error @ p_error))
        w = self.reward_weights
        reward = (
            w["alive"]
            - w["position"] * error
            - w["velocity"] * math.sqrt(float(v_error @ v_error))
            - w["smoothness"] * float(np.sum((a - self._previous_action) ** 2))
            - w["body_rate"] * float(np.sum(x_next[StateIndex.omega_body] ** 2))
        )
        strayed = not error <= self.max_tracking_error  # also catches a NaN state
        if surface is not None or strayed:
            reward -= self.collision_penalty
        terminated = bool(strayed or (surface is not None and self.terminate_on_collision))
        truncated = bool(not terminated and self._step_index >= self.n_steps)
        self._previous_action = a
        info = self._info(effect_forces, surface, command)
        info["strayed"] = bool(strayed)
        self._last_info = info
        obs = self._observation()
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), terminated, truncated, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to gym.make")
            return None
        if not self._world._markers:
            self._world.show_reference(self.reference.position(np.linspace(0, self.duration, 60)))
        p = self._x[StateIndex.p_world]
        self._world.place_vehicle(p, self._x[StateIndex.q_body_to_world])
        if self.render_mode == "rgb_array":
            width, height = self.render_size
            return self._world.render(p, width, height)
        return None

    def close(self):
        world = getattr(self, "_world", None)
        if world is not None:
            world.close()
        super().close()

    # ================================================================== internals
    def _prepare_reference(self, reference: Reference) -> None:
        cached = self._reference_cache
        if cached is not None and cached[0] == reference:
            self._ref_p, self._ref_v = cached[1], cached[2]
            return
        n = self.n_steps + self._preview_stride * PREVIEW_STEPS + 1
        p, v, _ = reference.sample(np.arange(n) * self.control_dt)
        self._ref_p, self._ref_v = p, v
        self._reference_cache = (reference, p, v)
        if self._world._markers:
            self._world.show_reference(reference.position(np.linspace(0, self.duration, len(self._world._markers))))

    def _bounce(self, x: np.ndarray, contacts) -> np.ndarray:
        """Push the vehicle out of the surfaces and remove (restitution) its velocity into them."""
        x = x.copy()
        for contact in contacts:
            n = contact.normal_world
            x[StateIndex.p_world] += n * contact.penetration
            v_n = float(np.dot(x[StateIndex.v_world], n))
            if v_n < 0:
                x[StateIndex.v_world] -= (1.0 + self.restitution) * v_n * n
        return x

    def _observation(self) -> np.ndarray:
        x, i = self._x, self._step_index
        obs = np.empty(OBSERVATION_SIZE)
        f = OBSERVATION_FIELDS
        p_ref = self._ref_p[i]
        obs[f["p_world"]] = x[StateIndex.p_world]
        obs[f["v_world"]] = x[StateIndex.v_world]
        obs[f["R_body_to_world"]] = self._R.ravel()
        obs[f["omega_body"]] = x[StateIndex.omega_body]
        obs[f["p_error"]] = x[StateIndex.p_world] - p_ref
        obs[f["v_error"]] = x[StateIndex.v_world] - self._ref_v[i]
        stride = self._preview_stride
        obs[f["reference_preview"]] = (self._ref_p[i + stride : i + stride * PREVIEW_STEPS + 1 : stride] - p_ref).ravel()
        d = self._rotor_distances
        if d.shape[0]:
            obs[f["rotor_clearance"]] = np.minimum(d.min(axis=0), CLEARANCE_CAP)
            nearest = int(np.argmin(d.min(axis=1)))
            obs[f["wall_normal"]] = self.scene.walls[nearest].normal
        else:
            obs[f["rotor_clearance"]] = CLEARANCE_CAP
            obs[f["wall_normal"]] = 0.0
        obs[f["previous_action"]] = self._previous_action
        obs[f["time"]] = self.time
        return obs.astype(np.float32)

    def _info(self, effect_forces: np.ndarray, surface: str | None, command: np.ndarray) -> dict[str, Any]:
        x, i = self._x, self._step_index
        suction = effect_forces[:, self._suction_index] if self._suction_index is not None else np.zeros(3)
        d = self._rotor_distances
        clearance = float(d.min()) - self.vehicle.duct_radius if d.size else math.inf
        return {
            "time": self.time,
            "p_world": x[StateIndex.p_world].copy(),
            "q_body_to_world": x[StateIndex.q_body_to_world].copy(),
            "v_world": x[StateIndex.v_world].copy(),
            "omega_body": x[StateIndex.omega_body].copy(),
            "rotor_thrusts": x[StateIndex.rotor_thrusts].copy(),
            "p_ref": self._ref_p[i].copy(),
            "v_ref": self._ref_v[i].copy(),
            "suction_force_world": suction.copy(),
            "effect_forces_world": {e.name: effect_forces[:, k].copy() for k, e in enumerate(self._truth.effects)},
            "collision": surface is not None,
            "collision_surface": surface,
            "collisions": self._collisions,
            "wall_clearance": clearance,
            "command": np.asarray(command, dtype=float).copy(),
        }


def _explicit_params(spec: Any, name: str) -> set[str]:
    """Parameter names that a user's ``effects`` specification sets explicitly for effect ``name``."""
    if isinstance(spec, dict):
        return set((spec.get(name) or {}).keys())
    if isinstance(spec, (list, tuple)):
        for item in spec:
            if isinstance(item, dict) and item.get("name") == name:
                return set((item.get("params") or {}).keys())
    if isinstance(spec, str):
        return {e for chunk in spec.split(";") if chunk.split(":")[0].strip() == name
                for e in (p.split("=")[0].strip() for p in chunk.partition(":")[2].split(",") if "=" in p)}
    return set()
