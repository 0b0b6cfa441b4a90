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
    - body_rate * |omega|^2 - wall_normal * |p_error . n|`` (``n``: outward normal of the
    surface nearest to a rotor; ``wall_normal`` is 0 unless set), minus ``collision_penalty``
    on a collision and when the vehicle strays more than ``max_tracking_error`` from the reference.
Reset options
    ``{"perturb_start": False}`` starts exactly on the reference (default: a uniform
    perturbation of position, velocity and attitude whose size each task sets; a start
    it would bring within ``wall_env.batch.START_CLEARANCE`` (1 cm) of a wall, the ground
    or the ceiling is mirrored back out along the plane's normal, so no episode starts
    touching a surface).
Episode end
    terminated on a collision (unless ``terminate_on_collision=False``, when the vehicle
    bounces off and the collision is counted) or when straying; truncated at the
    reference's end (``duration``).
Info
    true state (``p_world``, ``q_body_to_world`` [w, x, y, z], ``v_world``, ``omega_body``,
    ``rotor_thrusts``), reference (``p_ref``, ``v_ref``), ``suction_force_world`` (N,
    mean over the step), ``rotor_suction_world`` (``(4, 3)``, N: each rotor's share of it),
    ``effect_forces_world`` (per effect), ``collision`` (bool),
    ``collision_surface``, ``collisions`` (count this episode), ``wall_clearance``
    (m, nearest duct edge to a wall), ``command`` (the noisy physical command), ``time``,
    ``strayed`` (bool).
Conditions
    ``conditions="realistic"`` adds state-estimate error, latency, motor lag and turbulence
    (:mod:`wall_env.conditions`); the observation then holds the estimated state.
Contact
    closed form against the scene's planes (:mod:`wall_env.contact`), the same code as the
    batched env; PyBullet holds the scene for pictures (``render``) and the human viewer.
Lifecycle
    ``step`` before ``reset``, after the episode's end and after ``close`` raise a
    ``RuntimeError`` saying what to do; ``reset`` after ``close`` too.

Public attributes that controllers may read (never the simulator's effect settings):
``vehicle``, ``scene``, ``reference``, ``action_mapping``, ``nominal_model``,
``control_dt``, ``time``, ``task``, ``config`` (the checked settings, :class:`~wall_env.config.EnvConfig`).
Pictures follow the vehicle; set ``camera_target`` (a world point, m) and ``camera_distance``
(a factor on the usual distance) for a fixed camera.

Many vehicles at once: ``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``
gives :class:`~wall_env.vector_env.WallInspectorVectorEnv`, the same code on N rows.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from wall_env.batch import EnvBatch, check_actions, info_row
from wall_env.bullet_world import BulletWorld
from wall_env.config import DEFAULT_REWARD_WEIGHTS, RENDER_MODES, EnvConfig, episode_length_warning
from wall_env.observation import OBSERVATION_SIZE, observation_bounds

__all__ = ["WallInspectorEnv", "DEFAULT_REWARD_WEIGHTS", "check_reset_options"]

_DEFAULT_CONTROL_DT = 0.01


def check_reset_options(options: Any, allowed: tuple[str, ...] = ("perturb_start",)) -> float:
    """The start-perturbation scale (1 or 0) from ``reset`` options, or a ``ValueError``."""
    if options is None:
        return 1.0
    if not isinstance(options, dict):
        raise ValueError(f"reset options must be a dict, got {options!r}")
    unknown = sorted(map(str, set(options) - set(allowed)))
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; allowed: {list(allowed)}")
    perturb = options.get("perturb_start", True)
    if not isinstance(perturb, (bool, np.bool_)):
        raise ValueError(f"reset option perturb_start must be True or False, got {perturb!r}")
    return 1.0 if perturb else 0.0


class WallInspectorEnv(gym.Env):
    """Quadrotor near walls. See the module docstring for spaces, reward and info.

    Parameters (checked by :class:`~wall_env.config.EnvConfig`)
    ----------
    task: ``"WallHover"``, ``"WallCircle"``, ``"WallSweep"`` or ``"Corridor"``.
    k_s, d_thr: wall-suction scale (N/m, default 4.1) and threshold (m, default 0.132).
    standoff: wall to reference centre of mass (m; corridor: half-width). Task default if None.
    altitude, duration: reference height (m) and episode length (s). Task defaults if None.
    task_params: shape parameters of the task's reference (:class:`~wall_env.tasks.TaskParameter`),
        e.g. ``{"radius": 0.3, "period": 6.0}`` for ``WallCircle``; defaults for those not given.
    noise: add command noise (True/False); ``thrust_noise_std`` (N) and ``rate_noise_std`` (rad/s) set it.
    effects: further effects in the simulator, e.g. ``{"ground_effect": {"radius": 0.08}}``, or
        options of the suction, ``{"wall_suction": {"thrust_scaling": True}}``.
    vehicle: :class:`VehicleParams`, a dict of its fields or a JSON/YAML file.
    model: a model file (:class:`~wall_env.model_file.FlightModel`) that sets the vehicle and
        every effect of the simulator; then ``vehicle``, ``k_s``, ``d_thr`` and ``effects`` must be unset.
    randomize: per-episode uniform ranges, e.g. ``{"k_s": (2, 8), "mass": (0.9, 1.1)}``, for
        ``k_s``, ``d_thr``, ``standoff``, ``mass``, ``push`` (N, a steady horizontal force in a random
        direction), ``motor_time_constant`` (s), ``latency`` (s, the round trip), ``sensing_scale`` and
        ``gust_scale`` (factors on the sensing error and turbulence of ``conditions``), and ``start_time``
        (s: the episode starts that far along the reference, at its position and velocity there, and its
        ``time`` observation starts there; a start-state curriculum for long paths).
    conditions: flight conditions (:mod:`wall_env.conditions`): ``"ideal"`` (default), ``"realistic"``
        (motion-capture sensing, 20 ms latency, 30 ms motor lag, light turbulence) or a dict of
        ``sensing``, ``latency``, ``motor_time_constant`` and ``wind``. The observation then carries the
        estimated state (late and with the sensing error); reward, termination and info the true one.
    terminate_on_collision, collision_penalty, restitution: what a collision does.
    max_tracking_error: distance from the reference (m) that ends the episode.
    reward_weights: overrides of :data:`DEFAULT_REWARD_WEIGHTS` (finite numbers).
    control_dt: control period (s, default 0.01 = 100 Hz); physics_substeps: RK4 steps per control step.
    motor_time_constant: first-order rotor lag (s), overriding the vehicle's.
    ground_z, ceiling_z: heights of ground and ceiling planes (m); ``ceiling_z=None`` for none.
    render_mode: ``"rgb_array"`` (headless) or ``"human"`` (PyBullet's window; needs a display).
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": round(1.0 / _DEFAULT_CONTROL_DT)}

    def __init__(self, task: str = "WallHover", **kwargs: Any):
        super().__init__()
        self._world: BulletWorld | None = None
        self._phase = "closed"
        config = EnvConfig.from_kwargs(task, **kwargs)
        self.config = config
        if config.control_dt != _DEFAULT_CONTROL_DT:
            self.metadata = {**self.metadata, "render_fps": 1.0 / config.control_dt}
        self.task = config.task
        self.render_mode = config.render_mode
        self.render_size = config.render_size
        self.vehicle = config.vehicle
        self.nominal_model = config.nominal_model
        self.action_mapping = config.action_mapping
        self.control_dt = config.control_dt
        self.noise = config.noise
        self.terminate_on_collision = config.terminate_on_collision
        self.collision_penalty = config.collision_penalty
        self.restitution = config.restitution
        self.max_tracking_error = config.max_tracking_error
        self.reward_weights = dict(config.reward_weights)
        self.standoff, self.altitude, self.duration = config.standoff, config.altitude, config.duration
        self.randomize = dict(config.randomize)
        self.task_params = dict(config.task_params)
        self.n_steps = config.n_steps
        self.scene, self.reference = config.build()
        self.episode_parameters: dict[str, float] = {}
        # pictures: the camera looks at the vehicle (``camera_target=None``) or at a fixed world point,
        # from ``camera_distance`` times its usual distance
        self.camera_target: np.ndarray | None = None
        self.camera_distance = 1.0

        self._batch = EnvBatch(config, 1)
        # PyBullet holds the picture only: its world is made at the first render (at once for the human
        # viewer's window), so flights without pictures never start it
        if self.render_mode == "human":
            self._world = BulletWorld(config.vehicle, self.scene, gui=True)
        self._phase = "new"
        self._warned_length = False

        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self.observation_space = spaces.Box(*observation_bounds(), shape=(OBSERVATION_SIZE,), dtype=np.float32)

    @property
    def time(self) -> float:
        """Seconds since the episode's start."""
        return float(self._batch.step_index[0]) * self.control_dt

    # ================================================================== gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if self._phase == "closed":
            raise RuntimeError("reset() after close(): this environment is closed; make a new one")
        spread = check_reset_options(options)
        super().reset(seed=seed)
        if seed is not None or self._phase == "new":
            self._batch.streams.seed([0], [seed])
        self._check_episode_length()
        batch = self._batch
        batch.reset(np.zeros(1, dtype=np.intp), spread)
        self.episode_parameters = {k: float(v[0]) for k, v in batch.episode_parameters.items()}
        if "standoff" in self.episode_parameters:
            scene, self.reference = self.config.build(self.episode_parameters["standoff"])
            if scene != self.scene and self._world is not None:
                self._world.close()
                self._world = BulletWorld(self.vehicle, scene, gui=self.render_mode == "human")
            self.scene = scene
            if self._world is not None and self._world._markers:
                self._world.show_reference(self.reference.position(np.linspace(0, self.duration,
                                                                                len(self._world._markers))))
        self._phase = "running"
        return batch.observations()[0], info_row(batch.infos(), 0)

    def step(self, action):
        if self._phase != "running":
            raise RuntimeError({
                "new": "step() before reset(): call reset() first",
                "ended": "step() after the episode ended (terminated or truncated): call reset() first",
                "closed": "step() after close(): this environment is closed; make a new one",
            }[self._phase])
        a = check_actions(action, None)
        batch = self._batch
        reward, terminated, truncated = batch.step(a[None, :])
        terminated, truncated = bool(terminated[0]), bool(truncated[0])
        if terminated or truncated:
            self._phase = "ended"
        obs, info = batch.observations()[0], info_row(batch.infos(), 0)
        if self.render_mode == "human":
            self.render()
        return obs, float(reward[0]), terminated, truncated, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to gym.make")
            return None
        if self._phase == "closed":
            raise RuntimeError("render() after close(): this environment is closed")
        if self._world is None:
            self._world = BulletWorld(self.vehicle, self.scene, gui=self.render_mode == "human")
        if not self._world._markers:
            self._world.show_reference(self.reference.position(np.linspace(0, self.duration, 60)))
        x = self._batch.simulator.x[0]
        p = x[0:3]
        self._world.place_vehicle(p, x[3:7])
        if self.render_mode == "rgb_array":
            width, height = self.render_size
            target = p if self.camera_target is None else np.asarray(self.camera_target, dtype=float)
            return self._world.render(target, width, height, self.camera_distance)
        return None

    def close(self):
        if self._world is not None:
            self._world.close()
            self._world = None
        if hasattr(self, "_batch"):
            self._batch.close()
        self._phase = "closed"
        super().close()

    # ================================================================== internals
    def _check_episode_length(self) -> None:
        spec = self.spec
        message = episode_length_warning(self.config, spec.max_episode_steps if spec is not None else None)
        if message and not self._warned_length:
            gym.logger.warn(message)
            self._warned_length = True
