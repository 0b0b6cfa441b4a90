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
``look_for_lag``) fits a lag jointly with them (the :class:`MotorLag` term, one parameter
``time_constant`` in seconds). It is kept when it lowers the held-out score, the force it
accounts for is at least the weight share an effect must explain, and its 95 % interval is
away from zero and from :data:`MAX_FITTED_S`. A lag so
found is not an aerodynamic effect: it becomes the vehicle's ``motor_time_constant``,
the logs are prepared again with the lagged thrust and the effects are chosen again on
them (:class:`discovery.workflow.Discovery`). A vehicle block that gives
``motor_time_constant`` is taken at its word and no lag is looked for.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from discovery.residuals import FlightData, step_average_samples
from wall_env.effects import Effect, FlightContext, Parameter, Wrench
from wall_env.motor_lag import held_command_response

__all__ = ["MotorLag", "LagTerm", "MAX_FITTED_S", "LAG_KEY", "UNDETERMINED_LAG", "lag_force_steps"]

LAG_KEY = "motor_lag"
UNDETERMINED_LAG = "the flight does not determine it"
MAX_FITTED_S = 0.25  # s, the longest lag discovery fits (hobby motors: 10-100 ms)


class MotorLag(Effect):
    """The lag as a selection candidate (parameters, ranges, fitting); it has no wrench of its own.

    It is never put into an :class:`~wall_env.aero.AeroModel`: a lag found becomes the
    vehicle's ``motor_time_constant``, which the simulator integrates as rotor state.
    """

    name = LAG_KEY
    description = "the rotors produce the logged thrust late (first-order lag)"
    reference = "first-order motor model (wall_env.motor_lag)"
    parameters = (Parameter("time_constant", "s", 0.02, 0.0, MAX_FITTED_S, "first-order motor time constant"),)

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        raise TypeError("a motor lag is the vehicle's motor_time_constant (rotor state), not an aerodynamic wrench")


class LagTerm:
    """The lag's force ``K[(f(tau) - f_cmd) z_body]`` and its derivative at every segment's fit rows.

    Same interface as :class:`discovery.fitting.EffectFit`'s effect terms. The logged
    thrust is each segment's :attr:`~discovery.residuals.Segment.thrust_logged`, which
    must be what the nominal model took as produced (a vehicle without a lag).
    """

    affine = False

    def __init__(self, data: FlightData, effect: MotorLag):
        if data.vehicle.motor_time_constant > 0:
            raise ValueError("the vehicle already has a motor_time_constant; a lag on top of it is not fitted")
        self.data = data
        self.size = effect.param_size
        self.low, self.high = effect.param_bounds()
        self._rows = [seg.fit_rows for seg in data.segments]
        self._z_steps = [step_average_samples(seg.states.R_body_to_world[:, :, 2]) for seg in data.segments]
        self._cache: tuple[float, tuple[list[np.ndarray], list[np.ndarray]]] | None = None

    def evaluate(self, theta: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """``K[F]`` ``(m, 3)`` and its Jacobian ``(m, 3, 1)`` per segment at the fit rows."""
        tau = float(np.asarray(theta, dtype=float).reshape(-1)[0])
        if self._cache is not None and self._cache[0] == tau:
            return self._cache[1]
        forces, jacobians = [], []
        for seg, z_steps, rows in zip(self.data.segments, self._z_steps, self._rows):
            force, jacobian = lag_force_steps(seg.thrust_logged, seg.t, z_steps, tau)
            forces.append(seg.kernel.step_average(force, rows))
            jacobians.append(seg.kernel.step_average(jacobian, rows))
        self._cache = (tau, (forces, jacobians))
        return forces, jacobians


def lag_force_steps(thrust_logged: Any, t: np.ndarray, z_steps: np.ndarray,
                    tau: float) -> tuple[np.ndarray, np.ndarray]:
    """Per step: ``(f(tau) - f_cmd) z_body`` ``(n - 1, 3)`` N and its derivative in ``tau`` ``(n - 1, 3, 1)``."""
    thrust_logged = np.asarray(thrust_logged, dtype=float)
    response = held_command_response(thrust_logged, float(np.mean(np.diff(t))), tau)
    deficit = response.step_mean - thrust_logged[:-1]
    return deficit[:, None] * z_steps, (response.d_step_mean_d_tau[:, None] * z_steps)[:, :, None]
