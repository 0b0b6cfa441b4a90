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

starting from the first command (the rotors settled before the log began) unless another
start is given. It also returns the derivatives of the step means with respect to ``tau_m``
and to that start, for fitting them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["MAX_TIME_CONSTANT", "MIN_LAG_STEPS", "thrust_rate", "LagResponse", "held_command_response"]

MAX_TIME_CONSTANT = 1.0  # s, the longest motor lag a vehicle may be given
# the simulator integrates the lag with RK4 at its physics step h, stable for h / tau_m below 2.78: a lag
# shorter than one physics step is refused (0, no lag, is always allowed)
MIN_LAG_STEPS = 1.0


def thrust_rate(commanded: Any, produced: Any, time_constant: float) -> Any:
    """``df/dt = (f_cmd - f) / tau_m`` (N/s); ``time_constant`` > 0."""
    return (commanded - produced) / time_constant


@dataclass(frozen=True)
class LagResponse:
    """What the rotors produce for a logged command, sample by sample and step by step."""

    at_samples: np.ndarray  # (n, ...) N, produced thrust at each sample time
    step_mean: np.ndarray  # (n - 1, ...) N, produced thrust averaged over each step
    d_step_mean_d_tau: np.ndarray  # (n - 1, ...) N/s, derivative of step_mean with respect to tau_m
    d_step_mean_d_start: np.ndarray  # (n - 1,), derivative of step_mean with respect to the start (each entry alike)


def held_command_response(commanded: np.ndarray, dt: float, time_constant: float,
                          start: np.ndarray | float | None = None) -> LagResponse:
    """Exact response of :func:`thrust_rate` to ``commanded`` ``(n, ...)`` held over steps of ``dt`` seconds.

    The rotors produce ``start`` (shaped like ``commanded[0]``) at the first sample; by
    default the first command. A log with slightly uneven steps is taken at its mean step
    ``dt``; a ``time_constant`` of zero gives back the command.
    """
    commanded = np.asarray(commanded, dtype=float)
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    if not np.isfinite(time_constant) or time_constant < 0:
        raise ValueError(f"time_constant must be >= 0 s, got {time_constant!r}")
    first = commanded[0] if start is None else np.broadcast_to(np.asarray(start, dtype=float), commanded[0].shape)
    if not np.all(np.isfinite(first)):
        raise ValueError(f"start must be a finite thrust (N), got {start!r}")
    held = commanded[:-1]
    if time_constant == 0.0:
        # as tau -> 0, b -> tau / h and f_k -> f_cmd,k-1 (f_0 into the first step): the step mean's slope
        # is minus the change into the step / h, and the start is forgotten at once
        change = np.zeros_like(held)
        change[1:] = commanded[1:-1] - commanded[:-2]
        if len(held):
            change[0] = held[0] - first
        return LagResponse(commanded.copy(), held.copy(), -change / dt, np.zeros(len(held)))
    a = float(np.exp(-dt / time_constant))
    b = time_constant / dt * (1.0 - a)
    # a time constant under dt / 745 makes a zero, and with it da and a / tau (tau^2 may underflow too)
    da = a * dt / time_constant**2 if a > 0 else 0.0
    db = (1.0 - a) / dt - (a / time_constant if a > 0 else 0.0)
    # f_{k+1} = a f_k + (1 - a) f_cmd,k, from the start
    produced = _first_order(a, first, (1.0 - a) * held)
    error = produced[:-1] - held  # f_k - f_cmd,k
    # d f_{k+1} / d tau = a d f_k / d tau + da (f_k - f_cmd,k), from 0
    d_produced = _first_order(a, np.zeros_like(commanded[0]), da * error)
    step_mean = held + b * error
    d_step_mean = b * d_produced[:-1] + db * error
    # the start's share of f_k is a^k, of the step mean b a^k
    return LagResponse(produced, step_mean, d_step_mean, b * a ** np.arange(len(held), dtype=float))


def _first_order(a: float, start: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """``y`` ``(n + 1, ...)`` with ``y_0 = start`` and ``y_{k+1} = a y_k + inputs_k``, ``0 <= a < 1``.

    In closed form ``y_k = a^k y_0 + sum_{j<k} a^(k-1-j) inputs_j``: a convolution with ``a^m``,
    done by FFT along the first axis (a Python loop would take a second on a long log, and
    :mod:`scipy.signal` a third of a second to import).
    """
    n = len(inputs)
    powers = a ** np.arange(n + 1, dtype=float)
    shape = (-1,) + (1,) * (inputs.ndim - 1)
    out = np.empty((n + 1,) + inputs.shape[1:])
    out[:] = powers.reshape(shape) * start
    if n:
        size = 1 << int(np.ceil(np.log2(2 * n)))
        kernel = np.fft.rfft(powers[:n], size)
        spectrum = np.fft.rfft(inputs, size, axis=0) * kernel.reshape(shape)
        out[1:] += np.fft.irfft(spectrum, size, axis=0)[:n]
    return out
