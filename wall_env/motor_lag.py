"""First-order motor lag: the rotors produce their commanded thrust only after a time constant.

The model, written once here and used by the simulator's dynamics and by discovery::

    df/dt = (f_cmd - f) / tau_m

with ``f`` the thrust a rotor produces, ``f_cmd`` what the mixer asks of it and
``tau_m`` the vehicle's ``motor_time_constant`` (s). :func:`thrust_rate` is that
right-hand side (numbers or CasADi symbols alike); the simulator integrates it as part
of its state. :func:`held_command_response` is its exact solution for a command held
over each sample step, as a flight log records it: with ``a = exp(-h / tau_m)`` over a
step of length ``h``,

    f_{k+1} = f_cmd,k + (f_k - f_cmd,k) a
    mean of f over the step = f_cmd,k + (f_k - f_cmd,k) tau_m / h (1 - a)

starting from the first command (the rotors settled before the log began). It also
returns the derivative of the step means with respect to ``tau_m``, for fitting it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.signal import lfilter

__all__ = ["MAX_TIME_CONSTANT", "thrust_rate", "LagResponse", "held_command_response"]

MAX_TIME_CONSTANT = 1.0  # s, the longest motor lag a vehicle may be given


def thrust_rate(commanded: Any, produced: Any, time_constant: float) -> Any:
    """``df/dt = (f_cmd - f) / tau_m`` (N/s); ``time_constant`` > 0."""
    return (commanded - produced) / time_constant


@dataclass(frozen=True)
class LagResponse:
    """What the rotors produce for a logged command, sample by sample and step by step."""

    at_samples: np.ndarray  # (n, ...) N, produced thrust at each sample time
    step_mean: np.ndarray  # (n - 1, ...) N, produced thrust averaged over each step
    d_step_mean_d_tau: np.ndarray  # (n - 1, ...) N/s, derivative of step_mean with respect to tau_m


def held_command_response(commanded: np.ndarray, dt: float, time_constant: float) -> LagResponse:
    """Exact response of :func:`thrust_rate` to ``commanded`` ``(n, ...)`` held over steps of ``dt`` seconds.

    A log with slightly uneven steps is taken at its mean step ``dt``; a ``time_constant`` of
    zero gives back the command.
    """
    commanded = np.asarray(commanded, dtype=float)
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    if not np.isfinite(time_constant) or time_constant < 0:
        raise ValueError(f"time_constant must be >= 0 s, got {time_constant!r}")
    held = commanded[:-1]
    if time_constant == 0.0:
        # as tau -> 0, b -> tau / h and f_k -> f_cmd,k-1: the step mean's slope is minus the change into the step / h
        change = np.zeros_like(held)
        change[1:] = commanded[1:-1] - commanded[:-2]
        return LagResponse(commanded.copy(), held.copy(), -change / dt)
    a = float(np.exp(-dt / time_constant))
    b = time_constant / dt * (1.0 - a)
    da = a * dt / time_constant**2
    db = (1.0 - a) / dt - a / time_constant
    # f_{k+1} = a f_k + (1 - a) f_cmd,k, from f_0 = f_cmd,0
    produced = np.empty_like(commanded)
    produced[0] = commanded[0]
    if len(commanded) > 1:
        zi = a * commanded[0][None] if commanded.ndim > 1 else np.array([a * commanded[0]])
        produced[1:] = lfilter([1.0 - a], [1.0, -a], held, axis=0, zi=zi)[0]
    error = produced[:-1] - held  # f_k - f_cmd,k
    # d f_{k+1} / d tau = a d f_k / d tau + da (f_k - f_cmd,k), from 0
    d_produced = np.zeros_like(commanded)
    if len(commanded) > 1:
        d_produced[1:] = lfilter([da], [1.0, -a], error, axis=0)
    step_mean = held + b * error
    d_step_mean = b * d_produced[:-1] + db * error
    return LagResponse(produced, step_mean, d_step_mean)
