"""Nominal MPC and SC-MPC as Stable-Baselines3-style policies: one class, two models.

Each control step, for each env of the batch (all of it in one compiled call for the
whole batch, :mod:`controllers.mpc.step`, after the env's reference has been sampled in
NumPy; a single observation is a batch of one):

1. the initial guess: the previous solution shifted by one step (its last block
   repeated), or, at an episode start, the reference states with the flatness
   thrust and zero body rates (a *cold* start, given more iterations);
2. the reference states of the horizon (:mod:`controllers.mpc.reference`) from the
   observation's time and reference position, the attitude reference including a
   model's force at the states the warm start predicts (SC-MPC's ``compensation``
   says whether that force includes the suction);
3. Levenberg-Marquardt on the paper's least-squares problem
   (:mod:`controllers.mpc.cost`, :mod:`controllers.mpc.lm`) from the measured state
   ``x_0 = (p_world, R_body_to_world, v_world)``;
4. the first input ``u_0 = [T, wx, wy, wz]`` is the command, mapped through the
   env's action mapping.

:class:`MPC` predicts with the env's ``nominal_model`` (the vehicle's linear
drag); :class:`SCMPC` is the same class with the nominal model plus the paper's
``wall_suction`` effect (explicit ``k_s``, ``d_thr``) or every effect of a model
file (:class:`wall_env.model_file.FlightModel`). Neither reads the simulator's own
effect settings.

SC-MPC's ``compensation``: ``"dynamics"`` is the paper's formulation (the suction
only in the dynamics factor, Eq. 13 and 15); ``"dynamics+attitude"`` (the default)
also puts the suction into the attitude reference at the predicted states
(:mod:`controllers.mpc.reference` says why). ``from_env`` takes the weights,
horizon and compensation of a preset (:mod:`controllers.presets`): by default
the tuned preset of the env's task.

Among bodies (a scene with boxes, cylinders or meshes, :mod:`wall_env.bodies`) the policy
asks PyBullet (its own :class:`~wall_env.surfaces.SurfaceQuery` of the env's public scene)
for each rotor's local surfaces at the states its warm start predicts over the horizon
(at a cold start: along the reference, with the measured attitude), so that every stage
predicts the suction where the vehicle will be: past a window's jamb, over a ledge, around
a pier (:mod:`controllers.mpc.cost`). A model without wall suction asks nothing.

Timing, one entry per vehicle and step (a batch's call divided by its size):
:attr:`MPC.solve_times` lists the seconds of the compiled call (warm start, reference
states and LM; wall clock), :attr:`MPC.solve_cpu_times` the same in CPU time of the
calling thread (blind to other processes taking the core), :attr:`MPC.step_times` and
:attr:`MPC.cpu_step_times` the controller's whole step (reference sampling, the call,
the checks), :attr:`MPC.iteration_counts` the LM iterations;
:meth:`MPC.clear_statistics` empties them. :attr:`MPC.last_solves` keeps, per batch
index, the data of the latest solve (:class:`SolveRecord`), so a benchmark can hand
the very same problem to another solver.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from controllers.adaptation import ESTIMATED, RESIDUAL_EFFECT, AdaptationSettings, OnlineSuctionEstimator
from controllers.env_description import EnvDescription
from controllers.mpc.cost import InputLimits, MPCProblem, MPCWeights
from controllers.mpc.lm import LevenbergMarquardt, LMInfo, LMResult, LMSettings
from controllers.mpc.manifold import POINT_SIZE, PointIndex
from controllers.mpc.reference import HorizonReference, ReferenceStates
from controllers.mpc.step import CompiledStep, StepInput, StepOptions, StepOutput, StepStatus, cold_start_guess
from controllers.policy import ControllerPolicy
from wall_env.aero import AeroModel
from wall_env.effects import make_effect
from wall_env.model_file import FlightModel
from wall_env.observation import OBSERVATION_FIELDS
from wall_env.surfaces import REACH_MARGIN, SurfaceQuery
from wall_env.validation import check_range
from wall_env.vehicle import VehicleParams

__all__ = ["MPC", "SCMPC", "SolveRecord", "PAPER_SUCTION", "COMPENSATION_MODES"]

_OBS_P, _OBS_V = OBSERVATION_FIELDS["p_world"], OBSERVATION_FIELDS["v_world"]
_OBS_R = OBSERVATION_FIELDS["R_body_to_world"]
_OBS_ERROR = OBSERVATION_FIELDS["p_error"]
_OBS_TIME = OBSERVATION_FIELDS["time"].start

PAPER_SUCTION = {"k_s": 4.1, "d_thr": 0.132}  # the paper's flight-identified values (Sec. 4.4)
COMPENSATION_MODES = ("dynamics", "dynamics+attitude")


@dataclass
class SolveRecord:
    """One MPC solve: initial guess ``Z0`` (19, N), fixed start block, stage and global parameters, result."""

    Z0: np.ndarray
    start: np.ndarray
    stage_params: np.ndarray
    global_params: np.ndarray
    cold: bool
    result: LMResult


class MPC(ControllerPolicy):
    """The paper's on-manifold MPC (Sec. 3.3) with the model ``model``.

    Parameters
    ----------
    description: the env's public description (:func:`controllers.env_description.describe_env`).
    model: the prediction model; default the env's ``nominal_model``.
    vehicle: the vehicle of the prediction model (mass, rotor layout); default the env's.
    horizon, dt: N steps of dt seconds (paper: 20, 0.01 s).
    weights, limits: :class:`MPCWeights`, :class:`InputLimits` (defaults: the authors' release).
    solver: :class:`LMSettings` (iteration limits, tolerances), e.g. ``LMSettings(max_iterations=1)``:
        one iteration per control step, real-time-iteration style. The constructor takes the
        settings object only; :meth:`from_env`, which configuration files feed, also takes a
        mapping of its fields and builds the object from it.
    max_tilt_deg: tilt limit of the flatness attitude reference.
    model_attitude: attitude reference from flatness with the model's force (default;
        see :mod:`controllers.mpc.reference`), or from kinematics alone.
    force_at_prediction: take that force at the warm start's predicted states (default)
        rather than on the reference. The two switches exist to measure what they are
        worth; the defaults are what makes SC-MPC compensate (measured there).
    attitude_model: the model whose force enters the attitude reference; default ``model``.
    threads: threads that solve a batch's rows at once (default 1; more for throughput on
        several cores, e.g. a base controller in training; the CPU-time statistics then
        count the calling thread only).
    """

    name = "MPC"

    def __init__(self, description: EnvDescription, model: AeroModel | None = None, *,
                 vehicle: VehicleParams | None = None, horizon: int = 20, dt: float = 0.01,
                 weights: MPCWeights | None = None, limits: InputLimits | None = None,
                 solver: LMSettings | None = None, max_tilt_deg: float = 80.0, model_attitude: bool = True,
                 force_at_prediction: bool = True, attitude_model: AeroModel | None = None, threads: int = 1):
        super().__init__(description)
        if solver is not None and not isinstance(solver, LMSettings):
            raise ValueError(f"solver must be LMSettings (controllers.mpc.LMSettings), got {type(solver).__name__}; "
                             "from_env also takes a mapping of its fields")
        if model is not None and not isinstance(model, AeroModel):
            raise ValueError(f"model must be a wall_env.AeroModel, got {type(model).__name__}")
        if vehicle is not None and not isinstance(vehicle, VehicleParams):
            raise ValueError(f"vehicle must be a wall_env.VehicleParams, got {type(vehicle).__name__}")
        self.model = model if model is not None else description.nominal_model
        self.model_vehicle = vehicle if vehicle is not None else description.vehicle
        if attitude_model is not None and not isinstance(attitude_model, AeroModel):
            raise ValueError(f"attitude_model must be a wall_env.AeroModel, got {type(attitude_model).__name__}")
        self.problem = MPCProblem(self.model_vehicle, self.model, description.scene, horizon, dt, weights, limits)
        self.solver = LevenbergMarquardt(self.problem, solver)
        max_tilt = math.radians(check_range("max_tilt_deg", max_tilt_deg, 1.0, 89.0))
        self.attitude_model = self.model if attitude_model is None else attitude_model
        self.attitude_problem = (self.problem if self.attitude_model == self.model else
                                 MPCProblem(self.model_vehicle, self.attitude_model, description.scene, horizon, dt,
                                            weights, limits))
        self.horizon_reference = HorizonReference(self.attitude_problem, max_tilt, model_attitude)
        self.force_at_prediction = bool(force_at_prediction)
        self.global_params = self.problem.global_params()  # for the description's scene
        self.shift = max(1, int(round(self.control_dt / self.problem.dt)))
        self.solve_times: list[float] = []
        self.solve_cpu_times: list[float] = []
        self.step_times: list[float] = []
        self.cpu_step_times: list[float] = []
        self.iteration_counts: list[int] = []
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or not 1 <= threads <= 64:
            raise ValueError(f"threads must be an integer in [1, 64], got {threads!r}")
        self.step = CompiledStep(self.problem, self.attitude_problem, self.shift, self.solver.settings, int(threads))
        self._last_ok = np.zeros(0, dtype=bool)
        self.surfaces: SurfaceQuery | None = None  # PyBullet's answers on the scene's bodies, when the model needs them
        if self.problem.surface_size and any(m.get("wall_suction") is not None
                                             for m in (self.model, self.attitude_model)):
            self.surfaces = SurfaceQuery(description.scene, self.model_vehicle, self._surface_reach())

    def _surface_reach(self) -> float:
        """How far from a rotor the predicted stages ask for surfaces: the model's suction threshold (or the
        largest an adaptive model may reach) and what a stage moves."""
        suction = self.model.get("wall_suction") or self.attitude_model.get("wall_suction")
        return float(suction.values["d_thr"][0]) + REACH_MARGIN if suction is not None else REACH_MARGIN

    @classmethod
    def from_env(cls, env: Any, *, preset: str | Path | None = "tuned", **kwargs: Any) -> MPC:
        """Nominal MPC for ``env`` (plain, wrapped or vector env), predicting with its ``nominal_model``.

        ``preset``: weights and horizon from a preset (:mod:`controllers.presets`): ``"tuned"``
        (default: the tuned preset of the env's task), ``"paper"``, ``"paper-sim"``, a file, or
        ``None`` for the constructor's defaults (the authors' release). Keywords override it.
        """
        description = cls._description(env)
        policy = cls(description, **_settings_objects({**_preset_kwargs(preset, "mpc", description), **kwargs}))
        policy.follow(env)
        return policy

    # ------------------------------------------------------------------ statistics
    def clear_statistics(self) -> None:
        self.solve_times.clear()
        self.solve_cpu_times.clear()
        self.step_times.clear()
        self.cpu_step_times.clear()
        self.iteration_counts.clear()

    # ------------------------------------------------------------------ control
    def _new_memory(self, scene, reference) -> dict[str, Any]:
        memory = super()._new_memory(scene, reference)
        memory["global"] = self.problem.global_params(scene=scene)
        memory["attitude_global"] = (memory["global"] if self.attitude_problem is self.problem
                                     else self.attitude_problem.global_params(scene=scene))
        memory["fresh"] = True  # the next step copies its parameters into the batch arrays and starts cold
        return memory

    def _before_batch(self, n: int) -> None:
        if self.step.n != n:
            self.step.resize(n)
            self._last_ok = np.zeros(n, dtype=bool)

    def _options(self, yaw: float) -> np.ndarray:
        """The ``options`` row of :func:`~controllers.mpc.step.build_step_function` for a reference heading."""
        settings = self.solver.settings
        options = np.zeros(StepOptions.size)
        options[StepOptions.reference] = self.horizon_reference.options(yaw, False)
        options[StepOptions.force_at_prediction] = float(self.force_at_prediction)
        options[StepOptions.initial_damping] = settings.initial_damping
        options[StepOptions.relative_tolerance] = settings.relative_tolerance
        options[StepOptions.step_tolerance] = settings.step_tolerance
        options[StepOptions.max_iterations] = settings.max_iterations
        options[StepOptions.max_iterations_cold] = settings.max_iterations_cold
        return options

    def initial_guess(self, refs: ReferenceStates) -> np.ndarray:
        """Cold start: the reference states, flatness thrust and zero body rates (as the compiled step
        builds it; for handing a fixed problem to a solver)."""
        N = self.problem.horizon
        R_columns = refs.R_body_to_world.transpose(0, 2, 1).reshape(N, 9).T  # column-major per matrix
        return np.array(cold_start_guess(ca.DM(refs.thrust).T, ca.DM(refs.p_world.T), ca.DM(R_columns),
                                         ca.DM(refs.v_world.T)))

    def _commands(self, batch: np.ndarray) -> np.ndarray:
        t_start, cpu_start = time.perf_counter(), time.thread_time()
        n = len(batch)
        inputs, outputs = self.step.inputs, self.step.outputs
        cold = inputs[StepInput.cold]
        for i, memory in enumerate(self._memory):
            if memory["fresh"]:
                inputs[StepInput.global_params][i] = memory["global"]
                inputs[StepInput.attitude_global][i] = memory["attitude_global"]
                inputs[StepInput.options][i] = self._options(memory["reference"].yaw)
                cold[i] = 1.0
                memory["fresh"] = False
        inputs[StepInput.observation][:] = batch
        self.horizon_reference.sampler([m["reference"] for m in self._memory], batch[:, _OBS_TIME],
                                       out=inputs[StepInput.samples])
        if self.problem.surface_size:
            self._predicted_surfaces(batch)
        t_solve, cpu_solve = time.perf_counter(), time.thread_time()
        self._solve_batch()
        t_end, cpu_end = time.perf_counter(), time.thread_time()
        Z, info = outputs[StepOutput.Z], outputs[StepOutput.info]
        ok = outputs[StepOutput.status][:, StepStatus.ok] != 0
        self._last_ok = ok
        commands = Z[:, :4]  # u_0: the first four entries of the column-major blocks
        if ok.all():
            inputs[StepInput.Z_previous][:] = Z
            cold[:] = 0.0
        else:
            commands = commands.copy()
            inputs[StepInput.Z_previous][ok] = Z[ok]
            cold[ok] = 0.0
            for row in np.flatnonzero(~ok).tolist():
                commands[row] = self._fail(row, batch[row, _OBS_R].reshape(3, 3), self._failure_reason(row))
        self.solve_times.extend([(t_end - t_solve) / n] * n)
        self.solve_cpu_times.extend([(cpu_end - cpu_solve) / n] * n)
        self.step_times.extend([(time.perf_counter() - t_start) / n] * n)
        self.cpu_step_times.extend([(time.thread_time() - cpu_start) / n] * n)
        self.iteration_counts.extend(info[:, LMInfo.iterations].astype(int).tolist())
        return commands

    def _predicted_states(self, batch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where each row's solve starts from, ``x_0 .. x_N``: positions ``(n, N + 1, 3)`` and attitudes
        ``(n, N + 1, 3, 3)`` of the measured state and the warm start (the previous solution shifted, as
        the compiled step shifts it), or at a cold start the reference with the measured attitude."""
        n, N = len(batch), self.problem.horizon
        inputs = self.step.inputs
        Z = inputs[StepInput.Z_previous].reshape(n, N, -1)  # [row, block, entry]: column-major blocks
        k = min(self.shift, N - 1)
        warm = np.concatenate([Z[:, k:], np.repeat(Z[:, N - 1:], k, axis=1)], axis=1)
        R_now = batch[:, _OBS_R].reshape(n, 3, 3)
        p = np.concatenate([batch[:, None, _OBS_P], warm[:, :, PointIndex.p_world]], axis=1)
        R = np.concatenate([R_now[:, None], warm[:, :, PointIndex.R_body_to_world].reshape(n, N, 3, 3)
                            .transpose(0, 1, 3, 2)], axis=1)
        cold = inputs[StepInput.cold][:, 0] > 0.5
        if cold.any():
            samples = inputs[StepInput.samples][cold].reshape(-1, N + 1, 9)  # p, v, a at t + k dt
            anchor = batch[cold][:, _OBS_P] - batch[cold][:, _OBS_ERROR]  # the reference position now
            p[cold] = anchor[:, None, :] + samples[:, :, 0:3] - samples[:, :1, 0:3]
            R[cold] = R_now[cold][:, None]
        return p, R

    def _predicted_surfaces(self, batch: np.ndarray) -> None:
        """The rotors' local surfaces at each row's predicted states (the ``surfaces`` input of the step)."""
        n, N = len(batch), self.problem.horizon
        block = self.step.inputs[StepInput.surfaces].reshape(n, N + 1, -1)  # column-major: a column per state
        if self.surfaces is None:
            block[:] = self.problem.scene.to_vector()[self.problem.plane_size:]
            return
        p, R = self._predicted_states(batch)
        block[:] = self.surfaces.rotor_surfaces_at(p.reshape(-1, 3), R.reshape(-1, 3, 3)).reshape(n, N + 1, -1)

    def _failure_reason(self, i: int) -> str:
        info = self.step.outputs[StepOutput.info][i]
        if not self.step.outputs[StepOutput.status][i, StepStatus.finite_observation]:
            return "non-finite observation"
        if info[LMInfo.failed]:
            return f"SolverFailure: non-finite MPC cost {info[LMInfo.initial_cost]} at the initial guess"
        return f"non-finite MPC solution (cost {info[LMInfo.cost]})"

    def _solve_batch(self) -> None:
        """Run the compiled control step on every row of the batch arrays (one native call)."""
        self.step()

    @property
    def last_solves(self) -> list[SolveRecord | None]:
        """Per batch index, the latest solve (``None`` where it failed or none ran yet)."""
        if self.step.n == 0:
            return []
        N = self.problem.horizon
        inputs, outputs = self.step.inputs, self.step.outputs
        records: list[SolveRecord | None] = []
        for i in range(self.step.n):
            if not self._last_ok[i]:
                records.append(None)
                continue
            observation = inputs[StepInput.observation][i]
            start = np.concatenate([np.zeros(4), observation[_OBS_P],
                                    observation[_OBS_R].reshape(3, 3).ravel(order="F"), observation[_OBS_V]])
            records.append(SolveRecord(
                outputs[StepOutput.Z0][i].reshape(POINT_SIZE, N, order="F").copy(), start,
                outputs[StepOutput.stage_params][i].reshape(-1, N, order="F").copy(),
                inputs[StepInput.global_params][i].copy(), bool(outputs[StepOutput.status][i, StepStatus.cold]),
                LMResult.from_outputs(outputs[StepOutput.Z][i], outputs[StepOutput.info][i])))
        return records


class SCMPC(MPC):
    """Suction-compensated MPC: :class:`MPC` whose model adds the wall suction (paper Eq. 9-10).

    ``compensation``: ``"dynamics+attitude"`` (default) or ``"dynamics"`` (the paper's form);
    see the module docstring. ``adapt``: learn the wall in flight (``True``, or
    :class:`~controllers.adaptation.AdaptationSettings` or a dict of them): the model's
    ``k_s``, ``d_thr`` and a residual force (a ``constant_force`` added to the model) are
    re-estimated at every control step from the flight (:mod:`controllers.adaptation`) and the
    next solve predicts with the estimate; :attr:`estimate_history` keeps each step's
    estimates ``(n, 5)`` and :attr:`estimates` the latest. Other arguments as :class:`MPC`.
    """

    name = "SC-MPC"

    def __init__(self, description: EnvDescription, model: AeroModel | None = None, *,
                 compensation: str = "dynamics+attitude", adapt: Any = False, **kwargs: Any):
        if compensation not in COMPENSATION_MODES:
            raise ValueError(f"compensation must be one of {list(COMPENSATION_MODES)}, got {compensation!r}")
        if "attitude_model" in kwargs:
            raise ValueError("SCMPC sets attitude_model from compensation; do not pass both")
        self.compensation = compensation
        model = model if model is not None else description.nominal_model
        settings = None if adapt is False or adapt is None else AdaptationSettings.from_spec(adapt)
        if settings is not None and model.get(RESIDUAL_EFFECT) is None:
            model = model.with_effect(make_effect(RESIDUAL_EFFECT))  # the residual force, from zero
        attitude_model = model.without("wall_suction") if compensation == "dynamics" else None
        self._adapt_settings = settings
        super().__init__(description, model, attitude_model=attitude_model, **kwargs)
        if compensation == "dynamics":
            self.name = "SC-MPC (dynamics only)"
        self.adaptation: OnlineSuctionEstimator | None = None
        self.estimate_history: list[np.ndarray] = []
        if settings is not None:
            self.adaptation = OnlineSuctionEstimator(self.model, self.model_vehicle, description.scene,
                                                     self.control_dt, settings, surfaces=self.surfaces)
            self.name += " adaptive"
            self._last_thrust = np.zeros(0)
            labels = self.attitude_model.param_labels()
            self._attitude_columns = [labels.index(label) for label in self.model.param_labels() if label in labels]
            model_labels = self.model.param_labels()
            self._attitude_sources = [model_labels.index(label) for label in self.model.param_labels() if label in labels]

    def _surface_reach(self) -> float:
        reach = super()._surface_reach()
        if self._adapt_settings is not None:  # the estimate may move d_thr up to the grid's end
            reach = max(reach, float(self._adapt_settings.thresholds()[-1]) + REACH_MARGIN)
        return reach

    @property
    def estimates(self) -> dict[str, np.ndarray]:
        """The latest estimate of each batch row, by name (:data:`~controllers.adaptation.ESTIMATED`)."""
        if self.adaptation is None:
            raise AttributeError("estimates exist with adapt=True")
        return {name: self.adaptation.theta[:, i].copy() for i, name in enumerate(ESTIMATED)}

    def clear_statistics(self) -> None:
        super().clear_statistics()
        self.estimate_history.clear()

    def _commands(self, batch: np.ndarray) -> np.ndarray:
        estimator = self.adaptation
        if estimator is None:
            return super()._commands(batch)
        n = len(batch)
        if estimator.n != n:
            estimator.resize(n)
            self._last_thrust = np.full(n, np.nan)
        fresh = np.array([memory["fresh"] for memory in self._memory], dtype=bool)
        if fresh.any():
            estimator.start(fresh)
            self._last_thrust[fresh] = np.nan
        scenes = np.stack([memory["scene"].to_vector() for memory in self._memory])
        estimator.update(batch, self._last_thrust, self.model_vehicle.mass, scenes)
        theta = estimator.model_theta(self.model.theta())
        inputs = self.step.inputs
        inputs[StepInput.global_params][:, self.problem.theta_slice] = theta
        attitude_theta = inputs[StepInput.attitude_global][:, self.attitude_problem.theta_slice]
        attitude_theta[:, self._attitude_columns] = theta[:, self._attitude_sources]
        inputs[StepInput.attitude_global][:, self.attitude_problem.theta_slice] = attitude_theta
        commands = super()._commands(batch)
        # what the env flies: the command through the action mapping's limits
        self._last_thrust = self.action_mapping.to_physical(self.action_mapping.to_normalised(commands))[:, 0]
        self.estimate_history.append(estimator.theta.copy())
        return commands

    @classmethod
    def from_env(cls, env: Any, *, k_s: float | None = None, d_thr: float | None = None,
                 model: str | Path | FlightModel | None = None, preset: str | Path | None = "tuned",
                 **kwargs: Any) -> SCMPC:
        """SC-MPC for ``env``.

        The suction comes from ``k_s`` (N/m) and ``d_thr`` (m) -- missing ones take the
        paper's identified values 4.1 N/m and 0.132 m -- or from a model file
        ``model`` (path or :class:`FlightModel`), whose vehicle and every effect
        (``aero_model()``: nominal drag, wall suction, anything else it holds) become
        the prediction model. Giving both raises ``ValueError``. ``preset`` as in
        :meth:`MPC.from_env` (weights, horizon and compensation); keywords override it.
        """
        description = cls._description(env)
        kwargs = _settings_objects({**_preset_kwargs(preset, "scmpc", description), **kwargs})
        if model is not None:
            if k_s is not None or d_thr is not None:
                raise ValueError("give the suction either as k_s/d_thr or as a model file, not both")
            flight_model = model if isinstance(model, FlightModel) else FlightModel.load(model)
            policy = cls(description, flight_model.aero_model(), vehicle=flight_model.vehicle, **kwargs)
        else:
            suction = make_effect("wall_suction",
                                  k_s=PAPER_SUCTION["k_s"] if k_s is None else k_s,
                                  d_thr=PAPER_SUCTION["d_thr"] if d_thr is None else d_thr)
            policy = cls(description, description.nominal_model.with_effect(suction), **kwargs)
        policy.follow(env)
        return policy


def _settings_objects(kwargs: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` with a ``solver`` mapping (from a configuration file) built into its :class:`LMSettings`."""
    if kwargs.get("solver") is not None:
        kwargs = {**kwargs, "solver": LMSettings.coerce(kwargs["solver"])}
    return kwargs


def _preset_kwargs(preset: str | Path | None, method: str, description: EnvDescription) -> dict[str, Any]:
    """Constructor keywords of ``method`` from ``preset`` for the env's task (``{}`` for ``None``)."""
    if preset is None:
        return {}
    from controllers.presets import load_preset

    return load_preset(preset, method=method, task=description.task).controller_kwargs(method)
