"""The settings of a Wall Inspector environment, checked once for the single and the batched env.

:class:`EnvConfig` takes the keywords of ``gym.make("WallInspector/<Task>-v0", ...)`` and
``gym.make_vec(...)``, checks every one (errors name the argument and its allowed range)
and derives what an episode needs: the simulator's effect model, the action mapping, the
reference sampled at the control rate and how scene and reference move with the
stand-off. Building one is cheap (no PyBullet, no compiled code), so it is also the
place to check settings before any work is done.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wall_env.actions import ActionMapping
from wall_env.aero import AeroModel
from wall_env.conditions import MAX_LATENCY, FlightConditions
from wall_env.effects import effects_from_spec, make_effect
from wall_env.model_file import FlightModel, nominal_aero_model
from wall_env.motor_lag import MAX_TIME_CONSTANT, MIN_LAG_STEPS
from wall_env.observation import PREVIEW_DT, PREVIEW_STEPS
from wall_env.references import Reference
from wall_env.scene import Scene
from wall_env.tasks import TASKS, TaskSpec, min_standoff
from wall_env.validation import check_positive, check_range
from wall_env.vehicle import GRAVITY, VehicleParams

__all__ = ["EnvConfig", "DEFAULT_REWARD_WEIGHTS", "RANDOMIZABLE", "RENDER_MODES", "MAX_EPISODE_STEPS"]

# per step: alive bonus; per metre of position error, per m/s of velocity error; per squared action change and
# (rad/s)^2 of body rate; per metre of position error along the outward normal of the surface nearest to a rotor
# (wall_normal: on top of position, the wall-normal part weighed again; zero, or no surface known, adds nothing)
DEFAULT_REWARD_WEIGHTS = {"alive": 1.0, "position": 2.0, "velocity": 0.2, "smoothness": 0.1, "body_rate": 0.01,
                          "wall_normal": 0.0}
# per-episode settings the envs can draw, in the order of the random draws at reset: the suction's k_s (N/m)
# and d_thr (m), the stand-off (m) and mass (kg); a steady horizontal push (N, its direction uniform in the
# horizontal plane: one more draw), the rotors' time constant (s), the latency (s, the round trip, split
# evenly between command and observation, in whole physics steps), factors on the configured sensing
# error and turbulence intensity, and the time along the reference at which the episode starts (s; a start-state
# curriculum: every part of a long path is met from the first updates on, not only once the agent survives to it)
RANDOMIZABLE = ("k_s", "d_thr", "standoff", "mass", "push", "motor_time_constant", "latency", "sensing_scale",
                "gust_scale", "start_time")
RENDER_MODES = ("human", "rgb_array")
MAX_EPISODE_STEPS = 1_000_000  # the longest episode (duration / control_dt) any settings allow


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


def _check_bool(name: str, value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


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


def _truth_model(vehicle: VehicleParams, k_s: Any, d_thr: Any, effects: Any) -> AeroModel:
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


DRAG_EFFECTS = ("linear_drag", "quadratic_drag")


def _with_conditions(truth: AeroModel, conditions: FlightConditions, push: bool) -> AeroModel:
    """The simulator's model under ``conditions``: in wind, every drag effect acts on the air-relative velocity
    (its ``wind`` parameter, which the envs set from the wind at every step); a randomised ``push`` needs a
    ``constant_force`` to draw into."""
    if not conditions.wind.is_still:
        for effect in truth.effects:
            if effect.name in DRAG_EFFECTS and not effect.option_values["wind"]:
                truth = truth.with_effect(make_effect(effect.name, **effect.params_dict(), wind=True))
    if push and truth.get("constant_force") is None:
        truth = truth.with_effect(make_effect("constant_force"))
    return truth


@dataclass(frozen=True)
class StandoffGeometry:
    """Scene vector and reference of a task as affine functions of the stand-off ``s``:
    ``scene(s) = scene0 + (s - s0) scene_rate``, ``p_ref(s, t) = p_ref0(t) + (s - s0) p_rate``,
    ``v_ref`` independent of ``s``; the reference sampled at the control rate."""

    standoff: float  # s0
    scene_vector: np.ndarray  # (S,)
    scene_rate: np.ndarray  # (S,)
    p_ref: np.ndarray  # (T, 3), at times k * control_dt
    v_ref: np.ndarray  # (T, 3)
    p_rate: np.ndarray  # (3,)


@dataclass(frozen=True, eq=False)
class EnvConfig:
    """Checked settings of one environment (see :class:`wall_env.env.WallInspectorEnv` for each keyword)."""

    task: TaskSpec
    vehicle: VehicleParams
    truth: AeroModel
    nominal_model: AeroModel
    action_mapping: ActionMapping
    control_dt: float
    physics_substeps: int
    noise: bool
    noise_std: np.ndarray  # (4,): thrust (N), body rates (rad/s); zeros without noise
    terminate_on_collision: bool
    collision_penalty: float
    restitution: float
    max_tracking_error: float
    reward_weights: dict[str, float]
    standoff: float
    altitude: float
    duration: float
    base_scene: Scene
    task_params: dict[str, float]
    randomize: dict[str, tuple[float, float]]
    render_mode: str | None
    render_size: tuple[int, int]
    min_standoff: float
    geometry: StandoffGeometry = field(repr=False)
    conditions: FlightConditions = field(default_factory=FlightConditions)
    user_scene: Scene | None = None  # the ``scene`` keyword: walls and bodies instead of the task's

    @classmethod
    def from_kwargs(
        cls,
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
        conditions: Any = None,
        ground_z: float | None = 0.0,
        ceiling_z: float | None = None,
        scene: Scene | dict[str, Any] | str | Path | None = None,
        render_mode: str | None = None,
        render_size: tuple[int, int] = (480, 360),
    ) -> EnvConfig:
        if not isinstance(task, str) or task not in TASKS:
            raise ValueError(f"task must be one of {sorted(TASKS)}, got {task!r}")
        spec = TASKS[task]
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be None or one of {list(RENDER_MODES)}, got {render_mode!r}")
        if render_mode == "human" and not os.environ.get("DISPLAY"):
            raise ValueError("render_mode='human' opens a window and needs a display (DISPLAY is not set); "
                             "use render_mode='rgb_array' for pictures without one")
        try:
            width, height = (int(v) for v in render_size)
        except (TypeError, ValueError):
            raise ValueError(f"render_size must be (width, height) in pixels, got {render_size!r}") from None
        check_range("render_size width", width, 16, 4096), check_range("render_size height", height, 16, 4096)

        # ------------------------------------------------------------------ vehicle and effects
        if model is not None:
            clashing = [n for n, v in (("vehicle", vehicle), ("k_s", k_s), ("d_thr", d_thr), ("effects", effects))
                        if v is not None]
            if clashing:
                raise ValueError(f"model sets the vehicle and every effect; do not also pass {clashing}")
            flight_model = model if isinstance(model, FlightModel) else FlightModel.load(model)
            vehicle_params = flight_model.vehicle
            truth = flight_model.aero_model()
        else:
            vehicle_params = _load_vehicle(vehicle)
            truth = _truth_model(vehicle_params, k_s, d_thr, effects)
        flight_conditions = FlightConditions.from_spec(conditions)
        if motor_time_constant is not None and flight_conditions.motor_time_constant is not None:
            raise ValueError("the motor lag is given twice: as motor_time_constant and in conditions; give one")
        if flight_conditions.motor_time_constant is not None:
            motor_time_constant = flight_conditions.motor_time_constant
        if motor_time_constant is not None:
            vehicle_params = vehicle_params.replace(
                motor_time_constant=check_range("motor_time_constant", motor_time_constant, 0.0, MAX_TIME_CONSTANT))

        # ------------------------------------------------------------------ timing, noise, reward
        control_dt = check_range("control_dt", control_dt, 0.001, 0.05)
        if isinstance(physics_substeps, bool) or not isinstance(physics_substeps, (int, np.integer)) \
                or not 1 <= physics_substeps <= 100:
            raise ValueError(f"physics_substeps must be an integer in [1, 100], got {physics_substeps!r}")
        noise = _check_bool("noise", noise)
        noise_std = np.array([
            check_range("thrust_noise_std", thrust_noise_std, 0.0, 10.0),
            *[check_range("rate_noise_std", rate_noise_std, 0.0, 10.0)] * 3,
        ]) * float(noise)
        if reward_weights is not None and not isinstance(reward_weights, dict):
            raise ValueError(f"reward_weights must be a dict with keys among {sorted(DEFAULT_REWARD_WEIGHTS)}, "
                             f"got {reward_weights!r}")
        unknown = sorted(map(str, set(reward_weights or {}) - set(DEFAULT_REWARD_WEIGHTS)))
        if unknown:
            raise ValueError(f"unknown reward_weights key(s) {unknown}; allowed: {sorted(DEFAULT_REWARD_WEIGHTS)}")
        weights = {**DEFAULT_REWARD_WEIGHTS, **{k: check_range(f"reward_weights[{k!r}]", v, -1e6, 1e6)
                                                for k, v in (reward_weights or {}).items()}}

        # ------------------------------------------------------------------ geometry
        lowest = min_standoff(vehicle_params, spec.wall_axis) + spec.closest_approach
        try:
            standoff = check_range("standoff", spec.standoff if standoff is None else standoff, lowest, 5.0)
        except ValueError as exc:
            if model is None or spec.wall_axis is None:
                raise
            raise ValueError(f"{exc}; {flight_model.behind_standoff(spec.wall_axis, spec.closest_approach)}") from None
        altitude = check_range("altitude", spec.altitude if altitude is None else altitude, *spec.altitude_range)
        duration = check_range("duration", spec.duration if duration is None else duration, 0.05, 3600.0)
        if round(duration / control_dt) > MAX_EPISODE_STEPS:
            raise ValueError(f"duration / control_dt must be at most {MAX_EPISODE_STEPS:,} steps, "
                             f"got {duration / control_dt:,.0f}")
        if ground_z is not None:
            ground_z = check_range("ground_z", ground_z, -100.0, altitude - 0.3)
        if ceiling_z is not None:
            ceiling_z = check_range("ceiling_z", ceiling_z, altitude + 0.1, 1000.0)
        user_scene = _load_scene(scene, ground_z, ceiling_z)
        base_scene = Scene((), ground_z, ceiling_z)
        params = spec.check_params(task_params)
        truth = _with_conditions(truth, flight_conditions, push=isinstance(randomize, dict) and "push" in randomize)
        ranges = _check_randomize(randomize, truth, vehicle_params, lowest, flight_conditions,
                                  duration - control_dt)
        physics_dt = control_dt / int(physics_substeps)
        flight_conditions.latency.physics_steps(physics_dt)  # whole physics steps, or a ValueError
        lags = [vehicle_params.motor_time_constant, *ranges.get("motor_time_constant", ())]
        if any(0 < tau < MIN_LAG_STEPS * physics_dt for tau in lags):
            raise ValueError(f"motor_time_constant must be 0 or at least one physics step, {physics_dt * 1e3:g} ms "
                             f"(control_dt / physics_substeps), got {min(t for t in lags if t > 0) * 1e3:g} ms")
        geometry = _standoff_geometry(spec, standoff, altitude, duration, base_scene, params, control_dt,
                                      randomized="standoff" in ranges, user_scene=user_scene)

        return cls(
            task=spec, vehicle=vehicle_params, truth=truth, nominal_model=nominal_aero_model(vehicle_params),
            action_mapping=ActionMapping.for_vehicle(vehicle_params), control_dt=control_dt,
            physics_substeps=int(physics_substeps), noise=noise, noise_std=noise_std,
            terminate_on_collision=_check_bool("terminate_on_collision", terminate_on_collision),
            collision_penalty=check_range("collision_penalty", collision_penalty, 0.0, 1e6),
            restitution=check_range("restitution", restitution, 0.0, 1.0),
            max_tracking_error=check_positive("max_tracking_error", max_tracking_error, high=100.0),
            reward_weights=weights, standoff=standoff, altitude=altitude, duration=duration,
            base_scene=base_scene, task_params=params, randomize=ranges, render_mode=render_mode,
            render_size=(width, height),
            min_standoff=lowest, geometry=geometry, conditions=flight_conditions, user_scene=user_scene,
        )

    # ------------------------------------------------------------------ derived
    @property
    def n_steps(self) -> int:
        """Control steps per episode (the reference's length)."""
        return int(round(self.duration / self.control_dt))

    @property
    def preview_stride(self) -> int:
        """Control steps between the reference-preview points of the observation."""
        return _preview_stride(self.control_dt)

    def build(self, standoff: float | None = None) -> tuple[Scene, Reference]:
        """Scene and reference for ``standoff`` (default: the configured one)."""
        return _scene_and_reference(self.task, self.standoff if standoff is None else standoff, self.altitude,
                                    self.duration, self.base_scene, self.task_params, self.user_scene)

    @property
    def surface_reach(self) -> float:
        """How far (m) from a rotor the scene's bodies are queried for its local surfaces
        (:mod:`wall_env.surfaces`): the largest suction threshold an episode can have, plus what a vehicle
        moves in a step (:data:`~wall_env.surfaces.REACH_MARGIN`)."""
        from wall_env.surfaces import REACH_MARGIN

        suction = self.truth.get("wall_suction")
        d_thr = float(suction.values["d_thr"][0]) if suction is not None else 0.0
        d_thr = max(d_thr, self.randomize.get("d_thr", (0.0, 0.0))[1])
        return d_thr + REACH_MARGIN

    @property
    def suction_columns(self) -> dict[str, int]:
        """Columns of ``k_s`` and ``d_thr`` in the simulator's parameter vector ``theta``."""
        labels = self.truth.param_labels()
        return {name: labels.index(f"wall_suction.{name}") for name in ("k_s", "d_thr")
                if f"wall_suction.{name}" in labels}

    @property
    def hover_rotor_thrust(self) -> float:
        return self.vehicle.mass * GRAVITY / 4.0

    @property
    def physics_dt(self) -> float:
        """Seconds per physics step (RK4 substep)."""
        return self.control_dt / self.physics_substeps

    @property
    def lagged(self) -> bool:
        """Whether any episode's rotors lag (rotor thrusts are then state of the compiled step)."""
        return self.vehicle.motor_time_constant > 0 or max(self.randomize.get("motor_time_constant", (0, 0))) > 0

    def parameter_columns(self, effect: str, name: str) -> slice | None:
        """Columns of parameter ``name`` of ``effect`` (all its entries) in the simulator's vector ``theta``;
        ``None`` if the simulator has no such parameter."""
        labels = self.truth.param_labels()
        columns = [i for i, label in enumerate(labels) if label.split("[")[0] == f"{effect}.{name}"]
        return slice(columns[0], columns[-1] + 1) if columns else None


def _preview_stride(control_dt: float) -> int:
    return max(1, int(round(PREVIEW_DT / control_dt)))


def _check_randomize(ranges: Any, truth: AeroModel, vehicle: VehicleParams, lowest_standoff: float,
                     conditions: FlightConditions, last_start: float) -> dict[str, tuple[float, float]]:
    if ranges is None:
        return {}
    if not isinstance(ranges, dict):
        raise ValueError(f"randomize must be a dict of (low, high) ranges for keys among {list(RANDOMIZABLE)}, "
                         f"got {ranges!r}")
    unknown = sorted(map(str, set(ranges) - set(RANDOMIZABLE)))
    if unknown:
        raise ValueError(f"randomize keys must be among {list(RANDOMIZABLE)}, got {unknown}")
    suction = truth.get("wall_suction")
    limits = {p.name: (p.low, p.high) for p in suction.parameters if p.name in ("k_s", "d_thr")} if suction else {}
    checked = {}
    for key in RANDOMIZABLE:  # a fixed order: the order of the random draws at reset
        if key not in ranges:
            continue
        bounds = ranges[key]
        try:
            low, high = (float(b) for b in bounds)
        except (TypeError, ValueError):
            raise ValueError(f"randomize[{key!r}] must be a (low, high) pair, got {bounds!r}") from None
        if not low <= high:
            raise ValueError(f"randomize[{key!r}] must have low <= high, got ({low}, {high})")
        name = f"randomize[{key!r}]"
        if key == "standoff":
            lo, hi = lowest_standoff, 5.0
        elif key == "mass":
            lo, hi = 0.05, vehicle.thrust_max / GRAVITY * 0.9
        elif key == "push":
            lo, hi = 0.0, 50.0
        elif key == "motor_time_constant":
            if conditions.motor_time_constant is not None or vehicle.motor_time_constant > 0:
                raise ValueError("randomize['motor_time_constant'] draws the motor lag; do not also give one")
            lo, hi = 0.0, MAX_TIME_CONSTANT
        elif key == "latency":
            if conditions.latency.seconds > 0:
                raise ValueError("randomize['latency'] draws the latency; do not also give it in conditions")
            lo, hi = 0.0, 2 * MAX_LATENCY
        elif key == "sensing_scale":
            if conditions.sensing.is_zero:
                raise ValueError("randomize['sensing_scale'] scales the sensing error of conditions, which has none; "
                                 "give conditions={'sensing': 'motion_capture'} or another")
            lo, hi = 0.0, 10.0
        elif key == "gust_scale":
            if conditions.wind.turbulence is None:
                raise ValueError("randomize['gust_scale'] scales the turbulence of conditions, which has none; "
                                 "give conditions={'wind': 'light'} or another")
            lo, hi = 0.0, 10.0
        elif key == "start_time":  # s along the reference; the last start leaves one control step to fly
            lo, hi = 0.0, max(0.0, last_start)
        else:
            if key not in limits:
                raise ValueError(f"{name} needs the wall_suction effect in the simulator")
            lo, hi = limits[key]
        check_range(name, low, lo, hi), check_range(name, high, lo, hi)
        checked[key] = (low, high)
    return checked


def _load_scene(scene: Any, ground_z: float | None, ceiling_z: float | None) -> Scene | None:
    """The ``scene`` keyword as a :class:`Scene` (a scene, its dict or a scene file), its ground and ceiling
    checked against ``ground_z`` and ``ceiling_z``."""
    if scene is None:
        return None
    if isinstance(scene, Scene):
        loaded = scene
    elif isinstance(scene, dict):
        loaded = Scene.from_dict(scene)
    elif isinstance(scene, (str, Path)):
        loaded = Scene.from_file(scene)
    else:
        raise ValueError(f"scene must be a wall_env.Scene, a dict or a scene file (.yaml/.json), got {scene!r}")
    if loaded.ground_z != ground_z or loaded.ceiling_z != ceiling_z:
        raise ValueError(f"scene has ground_z={loaded.ground_z}, ceiling_z={loaded.ceiling_z} but the env's "
                         f"ground_z={ground_z}, ceiling_z={ceiling_z}; give the same to both (the keywords set the "
                         "ground and ceiling)")
    return loaded


def _scene_and_reference(spec: TaskSpec, standoff: float, altitude: float, duration: float, base: Scene,
                         params: dict[str, float], user_scene: Scene | None) -> tuple[Scene, Reference]:
    """The task's scene and reference; with a ``scene`` keyword, its walls and bodies replace the task's."""
    scene, reference = spec.scene_and_reference(standoff, altitude, duration, base, params)
    if user_scene is not None:
        scene = Scene(user_scene.walls, scene.ground_z, scene.ceiling_z, user_scene.bodies)
    return scene, reference


def _standoff_geometry(spec: TaskSpec, standoff: float, altitude: float, duration: float, base: Scene,
                       params: dict[str, float], control_dt: float, randomized: bool = True,
                       user_scene: Scene | None = None) -> StandoffGeometry:
    """Sample the reference at the control rate and, when the stand-off is ``randomized``, find how scene and
    reference shift with it (checked to be affine with a third stand-off, so a task that is not fails loudly)."""
    n = int(round(duration / control_dt)) + _preview_stride(control_dt) * PREVIEW_STEPS + 1
    times = np.arange(n) * control_dt
    probe = (standoff, standoff + 0.1, standoff + 0.25) if randomized else (standoff,)
    built = [_scene_and_reference(spec, s, altitude, duration, base, params, user_scene) for s in probe]
    scenes = [scene.to_vector() for scene, _ in built]
    samples = [reference.sample(times)[:2] for _, reference in built]
    p, v = samples[0]
    if not randomized:
        return StandoffGeometry(standoff, scenes[0], np.zeros_like(scenes[0]), p, v, np.zeros(3))
    scene_rate = (scenes[1] - scenes[0]) / 0.1
    p_rate = (samples[1][0][0] - samples[0][0][0]) / 0.1
    affine = (np.allclose(scenes[2], scenes[0] + 0.25 * scene_rate, atol=1e-9)
              and np.allclose(samples[2][0], samples[0][0] + 0.25 * p_rate, atol=1e-9)
              and np.allclose(samples[1][1], samples[0][1], atol=1e-9)
              and all(scene.bodies == built[0][0].bodies for scene, _ in built))
    if not affine:
        raise ValueError(f"randomize['standoff']: task {spec.name!r} cannot randomise it (its scene and reference "
                         "must shift with the stand-off by a fixed direction, and its bodies stay in place)")
    return StandoffGeometry(standoff, scenes[0], scene_rate, p, v, p_rate)


def episode_length_warning(config: EnvConfig, max_episode_steps: int | None) -> str | None:
    """A message when a time limit would end episodes before the reference does."""
    if max_episode_steps is not None and max_episode_steps < config.n_steps:
        return (f"max_episode_steps={max_episode_steps} ends episodes before duration={config.duration:g} s "
                f"({config.n_steps} steps); pass max_episode_steps={config.n_steps} with the duration")
    return None

