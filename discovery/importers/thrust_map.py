"""The nominal thrust map of a log that has normalised commands but no thrust in newtons.

In hover the thrust along the vertical balances the weight plus the small vertical
acceleration, so over the hover samples

    m (g + a_z) = k x,    x = R_33 sum_j g(u_j)   (motor commands)   or   x = R_33 u   (collective)

with ``g(u) = u`` (``motor_command``: thrust proportional to the command, PX4's
normalised thrust setpoints) or ``g(u) = u^2`` (``motor_command_squared``: the command
proportional to rotor speed). ``k`` is the least-squares slope through the origin.
Hover samples are those where the vehicle is airborne and steady: speed below
0.3 m/s, acceleration below 0.7 m/s^2, tilt below 15 degrees, the command above
5 % (the rotors turn) and the vehicle off the ground: at least 0.1 m above the
ground (the median height while the log's own land detector says landed; without
one, while the rotors are stopped; else the lowest point of the log) and, where the
log has a land detector, not landed. At
least one second of them is needed, and the weight balance must hold on them to
10 % of the weight (rms); else no map is fitted and the note says why. Hover alone cannot
tell ``u`` from ``u^2`` (one operating point): the kind is the user's choice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from discovery.differentiation import moving_average
from discovery.flight_log import ThrustMap

__all__ = ["HoverFit", "hover_mask", "fit_thrust_map", "apply_thrust_map"]

HOVER_SPEED = 0.3  # m/s
HOVER_ACCELERATION = 0.7  # m/s^2
HOVER_TILT_DEG = 15.0
MIN_COMMAND = 0.05
MIN_HOVER_S = 1.0
MAX_BALANCE_RMS = 0.1  # of the weight: a worse weight balance is not a hover the map can be read from
MIN_HEIGHT = 0.1  # m above the ground height (see the module text)


@dataclass
class HoverFit:
    """What the thrust-map fit saw: the map (or None) and why."""

    thrust_map: ThrustMap | None
    hover_s: float
    relative_rms: float | None  # rms of the weight-balance residual / weight
    note: str


def _acceleration(t: np.ndarray, v_world: np.ndarray, window_s: float = 0.5) -> np.ndarray:
    dt = float(np.median(np.diff(t)))
    size = max(1, int(round(window_s / dt)))
    smooth = moving_average(v_world, size)
    return np.gradient(smooth, t, axis=0)


def hover_mask(t: np.ndarray, p_world: np.ndarray, v_world: np.ndarray, R_body_to_world: np.ndarray,
               command: np.ndarray, airborne: np.ndarray | None = None) -> np.ndarray:
    """Samples where the vehicle is airborne and steady (see the module text)."""
    a = _acceleration(t, v_world)
    turning = np.min(np.atleast_2d(command.T).T, axis=1) > MIN_COMMAND
    if airborne is not None and not airborne.all():
        ground = np.median(p_world[~airborne, 2])
    elif (~turning).sum() >= 2:  # rotors stopped: on the ground (a spin-up there is no hover)
        ground = np.median(p_world[~turning, 2])
    else:
        ground = np.min(p_world[:, 2])
    lifted = p_world[:, 2] > ground + MIN_HEIGHT
    airborne = lifted if airborne is None else airborne & lifted
    tilt = np.degrees(np.arccos(np.clip(R_body_to_world[:, 2, 2], -1.0, 1.0)))
    return (airborne & (np.linalg.norm(v_world, axis=1) < HOVER_SPEED) & (np.linalg.norm(a, axis=1) < HOVER_ACCELERATION)
            & (tilt < HOVER_TILT_DEG) & turning)


def _basis(command: np.ndarray, kind: str) -> np.ndarray:
    u = np.clip(np.asarray(command, dtype=float), 0.0, None)
    return u**2 if kind == "motor_command_squared" else u


def apply_thrust_map(thrust_map: ThrustMap, command: np.ndarray) -> np.ndarray:
    """Thrust in N: ``(n,)`` collective for a ``collective`` map, ``(n, k)`` per rotor otherwise."""
    return thrust_map.coefficient * _basis(command, thrust_map.kind)


def fit_thrust_map(t: np.ndarray, p_world: np.ndarray, v_world: np.ndarray, R_body_to_world: np.ndarray, command: np.ndarray,
                   kind: str, mass: float, gravity: float, airborne: np.ndarray | None = None) -> HoverFit:
    """Fit ``k`` of the ``kind`` map on the hover samples; ``thrust_map`` is None with a note if there are too few."""
    command = np.asarray(command, dtype=float)
    mask = hover_mask(t, p_world, v_world, R_body_to_world, command, airborne)
    dt = float(np.median(np.diff(t)))
    hover_s = float(mask.sum() * dt)
    if hover_s < MIN_HOVER_S:
        return HoverFit(None, hover_s, None, f"{hover_s:.1f} s of hover (speed < {HOVER_SPEED} m/s, "
                        f"acceleration < {HOVER_ACCELERATION} m/s^2, tilt < {HOVER_TILT_DEG:g} deg, rotors "
                        f"turning, off the ground); the thrust map needs at least {MIN_HOVER_S:g} s")
    a = _acceleration(t, v_world)
    basis = _basis(command, kind)
    x = R_body_to_world[:, 2, 2] * (basis if basis.ndim == 1 else basis.sum(axis=1))
    y = mass * (gravity + a[:, 2])
    x, y = x[mask], y[mask]
    k = float(np.dot(x, y) / np.dot(x, x))
    relative = float(np.sqrt(np.mean((y - k * x) ** 2)) / (mass * gravity))
    if not np.isfinite(k) or k <= 0 or relative > MAX_BALANCE_RMS:
        return HoverFit(None, hover_s, relative, f"{hover_s:.1f} s of hover whose weight balance does not fit one "
                        f"thrust map (k = {k:.4g} N, rms {100 * relative:.1f} % of the weight; at most "
                        f"{100 * MAX_BALANCE_RMS:g} %): the command does not carry the weight there")
    return HoverFit(ThrustMap(kind, k, f"fitted on {hover_s:.1f} s of hover"), hover_s, relative,
                    f"fitted on {hover_s:.1f} s of hover: weight balance rms {100 * relative:.1f} % of the weight")
