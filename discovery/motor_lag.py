"""Looking for a motor lag: the rotors produce the logged thrust late.

Discovery's nominal model takes the logged thrust (a command, as PX4 and most flight
stacks log it) as what acted. Real rotors follow their command with a time constant of
tens of milliseconds, and that lag is not aerodynamic: the force it leaves in the
residual, ``(f(tau_m) - f_cmd) z_body`` with ``f(tau_m)`` the thrust of
:func:`wall_env.motor_lag.held_command_response`, opposes every change of thrust. On a
climb and descent at angular frequency ``w`` it is ``tau_m m w^2`` times the vertical
velocity: it looks like a *negative* vertical drag, and a vertical drag fitted without
it comes out low (by 40-55 % with a 30 ms lag on the second simulator's 3 s climb and
descent).

So, once the effects are chosen, :func:`discovery.selection.forward_selection` (with
``look_for_lag``) fits a lag jointly with them: the :class:`MotorLag` term, with its
``time_constant`` in seconds and, as nuisance parameters, each segment's ``start_error``,
how far the rotors were from the logged thrust at the segment's first sample. A log begun in
mid-air, or a stretch after a gap, need not start settled; taking it so biased a 30 ms lag
10-25 % low on the second simulator's logs, which start with the rotors at hover under a
command far from it. A cross-validation fold whose held-out rows a start error reaches takes
that start settled (:meth:`LagTerm.fold_fixed`), so the errors never fit held-out rows, and
the rows a start error reaches are left out when the lag is scored (:meth:`LagTerm.clear_of_starts`).
The lag is kept when it lowers the held-out score and its 95 % interval is away from zero and
from :data:`MAX_FITTED_S`, however small its force: a determined lag biases what is fitted
next to it (see :func:`discovery.selection._motor_lag`). A lag so found is not an
aerodynamic effect: it becomes the vehicle's ``motor_time_constant``, the logs are prepared
again with the lagged thrust and the effects are chosen again on them
(:class:`discovery.workflow.Discovery`). A vehicle block that gives ``motor_time_constant``
is taken at its word and no lag is looked for.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from discovery.residuals import FlightData
from discovery.terms import Term
from wall_env.effects import Effect, FlightContext, Parameter, Wrench
from wall_env.motor_lag import held_command_response

__all__ = ["MotorLag", "LagTerm", "MAX_FITTED_S", "MAX_START_ERROR_N", "LAG_KEY", "UNDETERMINED_LAG",
           "lag_force_steps"]

LAG_KEY = "motor_lag"
UNDETERMINED_LAG = "the flight does not determine it"
MAX_FITTED_S = 0.25  # s, the longest lag discovery fits (hobby motors: 10-100 ms)
SEEN_SHARE = 1e-3  # share of a start error's effect (rms) that rows must carry to count as seeing it
MAX_START_ERROR_N = 1e4  # N, bound of a segment's start error (a range, not a prior: far above any rotor's thrust)


class MotorLag(Effect):
    """The lag as a selection candidate (parameters, ranges, fitting); it has no wrench of its own.

    It is never put into an :class:`~wall_env.aero.AeroModel`: a lag found becomes the
    vehicle's ``motor_time_constant``, which the simulator integrates as rotor state.
    """

    name = LAG_KEY
    description = "the rotors produce the logged thrust late (first-order lag)"
    reference = "first-order motor model (wall_env.motor_lag)"
    parameters = (Parameter("time_constant", "s", 0.02, 0.0, MAX_FITTED_S, "first-order motor time constant"),)
    # segments: how many segments' start errors are fitted (0: every segment starts settled);
    # thrust_scale: the scale of the chosen effects' thrust_scale, which the lagging thrust also has
    options = {"segments": 0, "thrust_scale": 1.0}

    def base_parameters(self) -> tuple[Parameter, ...]:
        segments = self.option_values["segments"]
        if segments < 0:
            raise ValueError(f"{self.name}.segments must be >= 0, got {segments}")
        if not 0.0 < self.option_values["thrust_scale"] < float("inf"):
            raise ValueError(f"{self.name}.thrust_scale must be a positive number, got {self.option_values['thrust_scale']}")
        if not segments:
            return type(self).parameters
        return type(self).parameters + (Parameter(
            "start_error", "N", (0.0,) * segments, -MAX_START_ERROR_N, MAX_START_ERROR_N,
            "collective thrust produced minus logged at each segment's first sample"),)

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        raise TypeError("a motor lag is the vehicle's motor_time_constant (rotor state), not an aerodynamic wrench")

    def fitting_term(self, data: FlightData) -> LagTerm:
        """The lag's force on ``data`` as the fit sums it (:func:`discovery.fitting.make_term`)."""
        return LagTerm(data, self)


class LagTerm(Term):
    """The lag's force ``K[(f(tau, e_s) - f_cmd) z_body]`` and its derivatives at every segment's fit rows.

    Same interface as :class:`discovery.fitting.EffectFit`'s effect terms. The logged
    thrust is each segment's :attr:`~discovery.residuals.Segment.thrust_logged`, which
    must be what the nominal model took as produced (a vehicle without a lag). With the
    effect's ``segments`` option equal to the number of segments, segment ``s`` starts at
    ``f_cmd + e_s`` (its ``start_error``); with 0, every segment starts settled.

    A thrust scale ``c`` among the effects acts on the logged thrust, while the rotors produce
    ``c f(tau)``: the lag's force is then ``c (f(tau) - f_cmd)``, or a fitted ``tau`` comes out
    ``c`` times the true one (26.3 ms for 30 ms under a 0.91 scale on the second simulator). The
    effect's ``thrust_scale`` option is that ``c``, taken from the effects chosen before the lag.
    """

    affine = False

    def __init__(self, data: FlightData, effect: MotorLag):
        if data.vehicle.motor_time_constant > 0:
            raise ValueError("the vehicle already has a motor_time_constant; a lag on top of it is not fitted")
        segments = effect.option_values["segments"]
        if segments not in (0, len(data.segments)):
            raise ValueError(f"{effect.name}.segments must be 0 or the number of segments, {len(data.segments)}; "
                             f"got {segments}")
        self.data = data
        self.scale = effect.option_values["thrust_scale"]
        self.size = effect.param_size
        self.low, self.high = effect.param_bounds()
        self._rows = [seg.fit_rows for seg in data.segments]
        self._cache: dict[int, tuple[bytes, tuple[np.ndarray, np.ndarray]]] = {}

    def fold_fixed(self, theta: np.ndarray, train: list[np.ndarray], held: list[np.ndarray]) -> np.ndarray:
        """The start errors a cross-validation fold holds settled (0): those whose effect (rms) reaches its
        held-out rows ``held`` by :data:`SEEN_SHARE` or more, or its training rows ``train`` by less."""
        out = np.zeros(self.size, dtype=bool)
        if self.size == 1:
            return out
        for s, (train_rows, held_rows) in enumerate(zip(train, held)):
            column = self.at_rows(s, theta)[1][:, :, 1 + s]
            share = SEEN_SHARE**2 * float(np.sum(column**2))
            out[1 + s] = float(np.sum(column[held_rows] ** 2)) >= share or float(np.sum(column[train_rows] ** 2)) <= share
        return out

    def clear_of_starts(self, theta: np.ndarray) -> list[np.ndarray]:
        """Per segment, a mask of the fit rows that no start error reaches: rows each carrying less than
        :data:`SEEN_SHARE` of its effect (rms), as :meth:`fold_fixed` counts them."""
        out = []
        for s, rows in enumerate(self._rows):
            clear = np.ones(len(rows), dtype=bool)
            if self.size > 1:
                column = self.at_rows(s, theta)[1][:, :, 1 + s]
                energy = np.sum(column**2, axis=1)
                clear = energy < SEEN_SHARE**2 * float(np.sum(energy))
            out.append(clear)
        return out

    def _steps(self, s: int, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        tau, starts = float(theta[0]), theta[1:]
        seg = self.data.segments[s]
        start = float(starts[s]) if starts.size else 0.0
        return lag_force_steps(seg.thrust_logged, seg.t, seg.z_body_steps, tau, start)

    def at_rows(self, segment: int, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``K[F]`` ``(m, 3)`` and its Jacobian ``(m, 3, p)`` at the segment's fit rows."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        key = theta.tobytes()
        cached = self._cache.get(segment)
        if cached is not None and cached[0] == key:
            return cached[1]
        seg, rows = self.data.segments[segment], self._rows[segment]
        force, jacobian = self._steps(segment, theta)
        smoothed = self.scale * seg.kernel.step_average(jacobian, rows)
        full = np.zeros(smoothed.shape[:2] + (self.size,))
        full[:, :, 0] = smoothed[:, :, 0]
        if theta.size > 1:
            full[:, :, 1 + segment] = smoothed[:, :, 1]
        result = (self.scale * seg.kernel.step_average(force, rows), full)
        self._cache[segment] = (key, result)
        return result

    def steps(self, segment: int, theta: np.ndarray) -> np.ndarray:
        """``F`` over each step ``(n - 1, 3)`` (one parameter vector for the whole segment)."""
        theta = np.asarray(theta, dtype=float)
        if theta.ndim == 2:
            if not np.all(theta == theta[:1]):
                raise ValueError("a motor lag is evaluated with one parameter vector per segment")
            theta = theta[0]
        return self.scale * self._steps(segment, theta)[0]


def lag_force_steps(thrust_logged: Any, t: np.ndarray, z_steps: np.ndarray, tau: float,
                    start_error: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Per step: ``(f(tau) - f_cmd) z_body`` ``(n - 1, 3)`` N, the rotors starting ``start_error`` N from the
    first logged thrust, and its derivatives in ``tau`` and in ``start_error`` ``(n - 1, 3, 2)``."""
    thrust_logged = np.asarray(thrust_logged, dtype=float)
    response = held_command_response(thrust_logged, float(np.mean(np.diff(t))), tau,
                                     start=thrust_logged[0] + start_error)
    deficit = response.step_mean - thrust_logged[:-1]
    slopes = np.stack([response.d_step_mean_d_tau, response.d_step_mean_d_start], axis=1)  # (n - 1, 2)
    return deficit[:, None] * z_steps, slopes[:, None, :] * z_steps[:, :, None]
