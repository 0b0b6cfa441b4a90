"""The force residual of paper Eq. 28 at every sample, against any model built from the effects library.

Eq. 28 reads ``r = m a + m g e3 - R (e3 T + F_drag) - F_s``: what the accelerometer (or
the differentiated velocity) says the vehicle felt, minus what the model says acted on
it. Here the modelled part is the thrust plus an :class:`~wall_env.aero.AeroModel`'s
force (the nominal model's is the vehicle's linear drag, paper Eq. 4), evaluated
through the library's own CasADi functions (:class:`~discovery.aero_eval.ForceEvaluator`).

Consistent smoothing (see :mod:`discovery.differentiation`): ``m a`` is the
local-polynomial derivative of the logged velocity and every modelled force is
averaged over each sample step and smoothed with the matched kernel, so that::

    y_k     = m D v_k + m g e3 - K[T R e3]_k           measured aerodynamic force (N)
    r_k(M)  = y_k - K[F_M]_k                            residual against model M (N)

where ``K`` is the matched kernel over steps, ``T`` the collective thrust of the step
(the command, held over the step, or the sum of logged rotor thrusts; when the vehicle has a
``motor_time_constant``, what lagging rotors produce from it, averaged over the step,
:func:`lagged_thrust`) and ``F_M`` the
aerodynamic force of model ``M`` at the samples. With a measured acceleration the
first term is ``m K[a]`` instead. Effects are evaluated at the position and velocity
smoothed over a short window (:data:`STATE_WINDOW_S`) and the logged attitude and body
rates.

The window is long (1 s by default) because nothing is lost by it: both sides are
smoothed alike, so a long window only averages noise away (the derivative's noise
falls as window^-1.5, the thrust noise's as window^-0.5), while every model is still
compared with the data on exactly the same footing. The state an effect is evaluated at
is another matter: ``K[F(x)]`` is not ``K[F(K x)]`` for a force that is nonlinear in the
state, and a 1 s smoothed distance misses how close a survey came to a ceiling by
millimetres, which biases a fitted distance offset (k2 of the ceiling effect) by 7 % on
a noiseless log; so the state only gets a short window that averages the measurement
noise of position and velocity (a millimetre or two) without rounding off the manoeuvre.

:class:`FlightData` holds every segment of every log prepared this way, with the
cross-validation folds (:attr:`Segment.fold`) that all held-out figures use.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from discovery.aero_eval import ForceEvaluator, SampleStates
from discovery.differentiation import LocalPolynomial
from discovery.flight_log import FlightLog, NominalVehicle
from wall_env.aero import AeroModel
from wall_env.model_file import nominal_aero_model
from wall_env.motor_lag import held_command_response
from wall_env.scene import Scene

__all__ = ["Segment", "FlightData", "prepare", "step_average_samples", "DEFAULT_WINDOW_S", "DEFAULT_BLOCK_S",
           "DEFAULT_FOLDS", "STATE_WINDOW_S", "HAC_WINDOWS"]

DEFAULT_WINDOW_S = 1.0  # s, smoothing window of the differentiator (both sides of Eq. 28 alike)
DEFAULT_BLOCK_S = 4.0  # s, length of the time blocks dealt to cross-validation folds
DEFAULT_FOLDS = 5
START_WINDOW_S = 0.5  # s, smoothing of the state a prediction starts from
STATE_WINDOW_S = 0.1  # s, smoothing of the position and velocity at which effects are evaluated
HAC_WINDOWS = 2.0  # smoothing windows of lags over which standard errors sum the scores' correlation


def step_average_samples(x: np.ndarray) -> np.ndarray:
    """Trapezoidal average over each step of per-sample values ``(n, ...) -> (n - 1, ...)``."""
    return 0.5 * (x[1:] + x[:-1])


def accelerometer_steps(a: np.ndarray, v: np.ndarray, thrust: np.ndarray, z_body: np.ndarray, mass: float,
                        kernel: LocalPolynomial) -> tuple[np.ndarray, bool]:
    """The mean acceleration over each step ``(n - 1, 3)`` from a logged acceleration ``a`` ``(n, 3)``, and whether
    each step's is the mean of its two samples (their noise then reaches it averaged); ``thrust`` ``(n,)`` N is each
    row's thrust, held over the step the row starts, along the body z axis ``z_body`` ``(n, 3)``.

    Loggers stand a sample for different instants. A central difference of the velocity is centred on the row: a
    step's mean is that of its two samples. An IMU that integrates over the interval before each row gives the step's
    mean as its last sample. A simulator that logs its state derivative with the row gives the acceleration at the
    row's instant under the row's command: it jumps with the command there, so the step's end is its next sample less
    the next command's jump. Which one the log holds is read from the log itself: the one whose matched smoothing is
    nearest the smoothed derivative of the logged velocity (a step's mean by definition, up to the velocity's noise).
    Taken centred, a simulator's derivative was half a step late on every thrust change: on a climb and descent at
    50 Hz that added 0.056 N s/m (16 %) to the vertical drag."""
    centred = step_average_samples(a)
    jump = np.diff(thrust)[:, None] * z_body[1:] / mass  # the next row's command less this one's, at the next row
    candidates = (centred, centred - 0.5 * jump, a[1:])
    reference = kernel.derivative(v)
    best = int(np.argmin([float(np.mean((kernel.step_average(c) - reference) ** 2)) for c in candidates]))
    return candidates[best], best < 2


@dataclass
class Segment:
    """One gap-free stretch of one log, ready for residuals and fits (SI, frames in the names)."""

    log_index: int
    source: str
    t: np.ndarray  # (n,) s
    states: SampleStates  # smoothed position and velocity, logged attitude and rates, rotor thrusts
    thrust: np.ndarray  # (n,) N, collective thrust of the step starting at each sample
    omega_cmd_body: np.ndarray  # (n, 3) rad/s
    kernel: LocalPolynomial
    scene: Scene
    gravity: float
    measured_force: np.ndarray  # (n, 3) N, y_k: the aerodynamic force the data show
    fold: np.ndarray  # (n,) int, the cross-validation fold each sample is held out in
    train_mask: np.ndarray  # (K, n) bool, samples usable for fitting when fold k is held out
    # (n - 1, 3) the body z axis in the world frame averaged over each step: the direction of the thrust held over
    # the step (the measured force, the noise floor's step residual and a motor lag's force)
    z_body_steps: np.ndarray = field(repr=False)
    thrust_logged: np.ndarray | None = field(repr=False, default=None)  # (n,) N, the log's own thrust (a command)
    p_measured: np.ndarray | None = field(repr=False, default=None)  # (n, 3) logged (unsmoothed) position
    p_start: np.ndarray | None = field(repr=False, default=None)  # (n, 3) position for prediction starts (short smoothing)
    v_start: np.ndarray | None = field(repr=False, default=None)  # (n, 3) velocity for prediction starts (short smoothing)
    v_raw: np.ndarray | None = field(repr=False, default=None)  # (n, 3) logged velocity, unsmoothed
    # (n - 1, 3) mean acceleration over each step from the logged acceleration, when the log has one
    # (accelerometer_steps)
    a_steps: np.ndarray | None = field(repr=False, default=None)
    a_steps_averaged: bool = False  # each of a_steps is the mean of two logged samples (their noise averaged)
    evaluators: dict = field(default_factory=dict, repr=False)
    flight: int = 0  # index of its flight among the flights fitted together (their own conditions)

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def dt(self) -> float:
        """Median sample period (s)."""
        return float(np.median(np.diff(self.t)))

    def step_weights(self) -> np.ndarray:
        """The matched kernel's weights over the steps of a centred window (``K`` of :mod:`discovery.residuals`)."""
        return self.kernel.interior["step"] if self.kernel.uniform else self.kernel.edge["step"][self._centre_row]

    def impulse_weights(self) -> np.ndarray:
        """The same window's weights over each step's impulse taken over the median period
        (:func:`discovery.noise.step_residual`): the step weights times the median period over each step's own,
        so that a longer step (a dropped sample) does not make them jump."""
        w = self.step_weights()
        if self.kernel.uniform:
            return w
        steps = self.kernel.start[self._centre_row] + np.arange(len(w))
        return w * self.dt / self.kernel.dt[steps]

    @property
    def _centre_row(self) -> int:
        """The sample whose window stands for the segment's interior when the times are not uniform."""
        return self.n // 2

    def effective_samples(self) -> float:
        """Independent residual values per axis in this segment: ``n sum(w^2)``, ``w`` the kernel's step weights
        (the smoothing correlates residual values over ``1 / sum(w^2)`` samples)."""
        return self.n * float(np.sum(self.step_weights() ** 2))

    def hac_lags(self) -> int:
        """Lags (in fit rows) of a Newey-West sum over this segment: :data:`HAC_WINDOWS` smoothing windows.

        Rows less than a window apart share smoothed samples, so their residuals are correlated up to
        one window; the sum runs to two for margin (over ten noisy ground-offset logs the rms of
        error / standard error was 0.91 with one window and 0.78 with three).
        """
        rows_per_window = self.kernel.window / max(1, self.kernel.window // 10)
        return max(1, int(round(HAC_WINDOWS * rows_per_window)))

    def evaluator(self, model: AeroModel, rotor_positions_body: np.ndarray) -> ForceEvaluator:
        """A cached :class:`ForceEvaluator` of ``model``'s structure for this segment's scene."""
        key = model.structure_key
        if key not in self.evaluators:
            self.evaluators[key] = ForceEvaluator(model, rotor_positions_body, self.scene, self.gravity)
        return self.evaluators[key]

    def smooth_force(self, force_samples: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """``K[F]``: matched smoothing of per-sample forces ``(n, 3, ...)`` (only at ``rows`` if given)."""
        return self.kernel.step_average(step_average_samples(force_samples), rows)

    @property
    def fit_rows(self) -> np.ndarray:
        """Sample indices whose residuals the fits use: every ``window // 10``-th sample."""
        return np.arange(0, self.n, max(1, self.kernel.window // 10))


@dataclass
class FlightData:
    """All segments of all logs, the nominal vehicle and the nominal model."""

    segments: list[Segment]
    vehicle: NominalVehicle
    n_folds: int
    sources: list[str]

    @property
    def nominal_model(self) -> AeroModel:
        return nominal_aero_model(self.vehicle.to_vehicle_params())

    @property
    def rotor_positions_body(self) -> np.ndarray:
        return self.vehicle.rotor_positions_array

    @property
    def n_samples(self) -> int:
        return sum(s.n for s in self.segments)

    @property
    def n_flights(self) -> int:
        """Flights (logs with at least one segment) fitted together."""
        return max((s.flight for s in self.segments), default=-1) + 1

    def effective_samples(self) -> float:
        """Independent residual values per axis over every segment (at least 1)."""
        return max(sum(seg.effective_samples() for seg in self.segments), 1.0)

    @property
    def weight(self) -> float:
        """The vehicle's weight (N) under the logs' gravity (their mean, should logs give different values)."""
        return self.vehicle.mass * float(np.mean([s.gravity for s in self.segments]))

    def model_force(self, model: AeroModel) -> list[np.ndarray]:
        """``K[F_M]`` per segment for ``model`` at its current parameters."""
        out = []
        for seg in self.segments:
            force = seg.evaluator(model, self.rotor_positions_body).force(seg.states, model.theta())
            out.append(seg.smooth_force(force))
        return out

    def residuals(self, model: AeroModel) -> list[np.ndarray]:
        """Force residual ``r_k(M)`` per segment, ``(n, 3)`` N."""
        return [seg.measured_force - f for seg, f in zip(self.segments, self.model_force(model))]

    def concat(self, per_segment: list[np.ndarray]) -> np.ndarray:
        return np.concatenate(per_segment, axis=0)

    @property
    def folds(self) -> np.ndarray:
        return self.concat([s.fold for s in self.segments])

    @property
    def times(self) -> np.ndarray:
        return self.concat([s.t for s in self.segments])


def lagged_thrust(rotor_logged: np.ndarray, t: np.ndarray, time_constant: float) -> tuple[np.ndarray, np.ndarray]:
    """What lagging rotors produce for a logged rotor thrust ``(n, 4)`` held over each step
    (:func:`wall_env.motor_lag.held_command_response`): the rotor thrusts at the samples and the collective
    thrust of the step starting at each sample (its mean over the step; the last sample keeps its own)."""
    response = held_command_response(rotor_logged, float(np.mean(np.diff(t))), time_constant)
    collective = np.append(response.step_mean.sum(axis=1), response.at_samples[-1].sum())
    return response.at_samples, collective


def _fold_assignment(t: np.ndarray, t0: float, block_s: float, n_folds: int,
                     guard_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Fold of each sample (blocks of ``block_s`` dealt round robin) and the training masks.

    Training for fold k excludes fold k and the samples within ``guard_s`` of it, whose
    smoothing windows overlap the held-out block.
    """
    block = np.floor((t - t0) / block_s).astype(int)
    fold = block % n_folds
    train = np.empty((n_folds, len(t)), dtype=bool)
    for k in range(n_folds):
        held = fold == k
        near = held.copy()
        if held.any():
            # distance in time to the nearest held-out sample
            held_t = t[held]
            idx = np.searchsorted(held_t, t)
            before = np.abs(t - held_t[np.clip(idx - 1, 0, len(held_t) - 1)])
            after = np.abs(held_t[np.clip(idx, 0, len(held_t) - 1)] - t)
            near = np.minimum(before, after) <= guard_s
        train[k] = ~near
    return fold, train


def prepare(logs: list[FlightLog], *, window_s: float = DEFAULT_WINDOW_S, order: int = 2,
            block_s: float = DEFAULT_BLOCK_S, n_folds: int = DEFAULT_FOLDS) -> FlightData:
    """Smooth, differentiate and split the logs into segments with their measured aerodynamic force.

    All logs must share one vehicle block (they describe one vehicle); scenes may differ.
    A log shorter than ``2 n_folds block_s`` gets blocks of ``duration / (2 n_folds)``
    (at least two smoothing windows).
    """
    if not logs:
        raise ValueError("discovery needs at least one flight log")
    vehicle = logs[0].vehicle
    for log in logs[1:]:
        if log.vehicle != vehicle:
            raise ValueError(f"{log.source}: its vehicle block differs from that of {logs[0].source}; "
                             "discover one vehicle at a time")
    segments: list[Segment] = []
    e3 = np.array([0.0, 0.0, 1.0])
    # short logs get shorter blocks so every fold holds some of each log (never below two windows)
    blocks = [max(min(block_s, log.duration / (2 * n_folds)), 2 * window_s) for log in logs]
    for index, log in enumerate(logs):
        R_all = log.R_body_to_world
        for part in log.segments():
            t = log.t[part]
            if len(t) < 4 * order + 4:
                continue  # too short to differentiate reliably
            kernel = LocalPolynomial(t, window_s, order)
            m = vehicle.mass
            R = R_all[part]
            v_raw = log.v_world[part]
            if log.rotor_thrusts is not None:
                rotor = log.rotor_thrusts[part]
                thrust = rotor.sum(axis=1)
            else:
                thrust = log.thrust_cmd[part]
                rotor = np.repeat(thrust[:, None] / 4.0, 4, axis=1)
            logged = thrust
            if vehicle.motor_time_constant > 0:  # the rotors produce the logged thrust late
                rotor, thrust = lagged_thrust(rotor, t, vehicle.motor_time_constant)
            a_steps, averaged = (None, False) if log.a_world is None else \
                accelerometer_steps(log.a_world[part], v_raw, thrust, R[:, :, 2], m, kernel)
            if a_steps is not None:
                accel_term = m * kernel.step_average(a_steps)
            else:
                accel_term = m * kernel.derivative(v_raw)
            z_body_steps = step_average_samples(R[:, :, 2])
            thrust_steps = thrust[:-1, None] * z_body_steps  # command held over each step
            measured = accel_term + m * log.gravity * e3 - kernel.step_average(thrust_steps)
            state_kernel = LocalPolynomial(t, min(STATE_WINDOW_S, window_s), order)
            states = SampleStates(state_kernel.smooth(log.p_world[part]), R, state_kernel.smooth(v_raw),
                                  log.omega_body[part], rotor, m)
            fold, train = _fold_assignment(t, float(log.t[0]), blocks[index], n_folds,
                                           guard_s=0.5 * (kernel.window + 1) * float(np.median(np.diff(t))))
            # prediction starts need the state at one instant: a short window keeps the lag of a 1 s fit out
            short = LocalPolynomial(t, min(START_WINDOW_S, window_s), order)
            segments.append(Segment(index, log.source, t, states, thrust, log.omega_cmd_body[part], kernel,
                                    log.scene, log.gravity, measured, fold, train, z_body_steps, logged,
                                    log.p_world[part], short.smooth(log.p_world[part]), short.smooth(v_raw),
                                    None if log.a_world is not None else v_raw, a_steps, averaged))
    if not segments:
        raise ValueError("no log has a segment long enough to differentiate")
    flights = sorted({seg.log_index for seg in segments})
    for seg in segments:
        seg.flight = flights.index(seg.log_index)
    return FlightData(segments, vehicle, n_folds, [log.source for log in logs])
