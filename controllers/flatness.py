"""Differential flatness of the quadrotor: desired attitude and body rates from a thrust vector and yaw.

A quadrotor's position and yaw are flat outputs: the thrust it needs follows from
the acceleration, and the attitude from the thrust direction plus the heading.
With world z up and thrust along +z_body,

    f_world  = m (a + g e3) - F_ext            thrust vector (N)
    z_body   = f_world / |f_world|             (tilted at most ``max_tilt`` from e3)
    y_body   = z_body x x_c / |z_body x x_c|,  x_c = (cos yaw, sin yaw, 0)
    x_body   = y_body x z_body
    R_des    = [x_body y_body z_body]          R_body_to_world

``F_ext`` is the force a model predicts besides thrust and gravity (drag, wall
suction); the cascaded PID uses none, the MPCs use their own model's prediction so
that their attitude reference is consistent with the dynamics they optimise over
(see :mod:`controllers.mpc.reference`).

The body rates that follow the thrust direction come from its time derivative:
with ``h = (j - (z_body . j) z_body) / |f / m|`` for the jerk ``j`` of the thrust
acceleration, ``omega_x = -h . y_body``, ``omega_y = h . x_body``, and
``omega_z = yaw_rate * (e3 . z_body)`` (Mellinger & Kumar, ICRA 2011).

All functions are vectorised over a leading axis and use NumPy only, except
:func:`attitude_from_thrust_symbolic`, the CasADi form of :func:`attitude_from_thrust`
that the MPCs compile into their control step (a test holds the two equal, edge
cases included).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["thrust_vector", "attitude_from_thrust", "attitude_from_thrust_symbolic", "feedforward_body_rates",
           "attitude_error", "level_attitude"]

_E3 = np.array([0.0, 0.0, 1.0])


def thrust_vector(acceleration_world: np.ndarray, mass: float, gravity: float,
                  external_force_world: np.ndarray | None = None) -> np.ndarray:
    """Thrust vector ``m (a + g e3) - F_ext`` (N), shape ``(..., 3)``."""
    f = mass * (np.asarray(acceleration_world, dtype=float) + gravity * _E3)
    if external_force_world is not None:
        f = f - external_force_world
    return f


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of ``(n, 3)`` arrays (``np.cross`` costs far more for small n)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _limit_tilt(z: np.ndarray, max_tilt: float) -> np.ndarray:
    """Unit vectors ``z (n, 3)`` rotated toward e3 so that their angle to it is at most ``max_tilt``."""
    cos_max = math.cos(max_tilt)
    too_tilted = z[:, 2] < cos_max
    if np.any(too_tilted):
        horizontal = z[too_tilted, :2]
        norm = np.linalg.norm(horizontal, axis=1, keepdims=True)
        direction = np.where(norm > 1e-12, horizontal / np.maximum(norm, 1e-12), np.array([1.0, 0.0]))
        z = z.copy()
        z[too_tilted, :2] = direction * math.sin(max_tilt)
        z[too_tilted, 2] = cos_max
    return z


def attitude_from_thrust(thrust_world: np.ndarray, yaw: np.ndarray | float, max_tilt: float = math.pi / 2
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Desired ``R_body_to_world`` ``(n, 3, 3)`` and body z axis ``(n, 3)`` for thrust vectors ``(n, 3)``.

    A thrust vector that points down or vanishes is replaced by e3 (the attitude
    stays level: a quadrotor cannot push downward). ``max_tilt`` (rad) limits the
    angle between body z and world z.
    """
    f = np.atleast_2d(np.asarray(thrust_world, dtype=float))
    n = f.shape[0]
    norm = np.sqrt(np.sum(f * f, axis=1, keepdims=True))
    usable = (norm[:, 0] > 1e-9) & (f[:, 2] > 0.0)
    z = np.where(usable[:, None], f / np.maximum(norm, 1e-9), _E3)
    z = _limit_tilt(z, max_tilt)
    psi = np.asarray(yaw, dtype=float)
    x_c = np.zeros((n, 3))
    x_c[:, 0] = np.cos(psi)
    x_c[:, 1] = np.sin(psi)
    y = _cross(z, x_c)
    # heading direction parallel to body z only at 90 deg tilt, which max_tilt < pi/2 excludes
    y /= np.maximum(np.sqrt(np.sum(y * y, axis=1, keepdims=True)), 1e-9)
    R = np.empty((n, 3, 3))
    R[:, :, 0] = _cross(y, z)
    R[:, :, 1] = y
    R[:, :, 2] = z
    return R, z


def attitude_from_thrust_symbolic(thrust_world, yaw, max_tilt):
    """:func:`attitude_from_thrust` for one thrust vector in CasADi (SX or MX ``3x1``, ``yaw`` and
    ``max_tilt`` scalars, rad): ``R_body_to_world`` as a ``3x3`` expression, the same numbers as the
    NumPy function (down-pointing or vanishing thrust gives level, the tilt is limited)."""
    f = thrust_world
    norm = ca.sqrt(ca.dot(f, f))
    usable = ca.logic_and(norm > 1e-9, f[2] > 0.0)
    z = ca.if_else(usable, f / ca.fmax(norm, 1e-9), ca.DM(_E3))
    cos_max, sin_max = ca.cos(max_tilt), ca.sin(max_tilt)
    horizontal = z[:2]
    h_norm = ca.sqrt(ca.dot(horizontal, horizontal))
    direction = ca.if_else(h_norm > 1e-12, horizontal / ca.fmax(h_norm, 1e-12), ca.DM([1.0, 0.0]))
    z = ca.if_else(z[2] < cos_max, ca.vertcat(direction * sin_max, cos_max), z)
    x_c = ca.vertcat(ca.cos(yaw), ca.sin(yaw), 0.0)
    y = ca.cross(z, x_c)
    y = y / ca.fmax(ca.sqrt(ca.dot(y, y)), 1e-9)
    return ca.horzcat(ca.cross(y, z), y, z)


def feedforward_body_rates(R_des: np.ndarray, thrust_acceleration: np.ndarray, jerk_world: np.ndarray,
                           yaw_rate: np.ndarray | float = 0.0) -> np.ndarray:
    """Body rates ``(n, 3)`` that make the thrust direction follow a jerk ``(n, 3)``.

    ``thrust_acceleration`` is ``|f| / m`` (m/s^2, ``(n,)``); ``R_des`` ``(n, 3, 3)``.
    """
    R_des = np.asarray(R_des, dtype=float).reshape(-1, 3, 3)
    x_b, y_b, z_b = R_des[:, :, 0], R_des[:, :, 1], R_des[:, :, 2]
    j = np.asarray(jerk_world, dtype=float).reshape(-1, 3)
    c = np.maximum(np.asarray(thrust_acceleration, dtype=float).reshape(-1), 1e-6)
    h = (j - np.sum(z_b * j, axis=1, keepdims=True) * z_b) / c[:, None]
    omega = np.empty_like(j)
    omega[:, 0] = -np.sum(h * y_b, axis=1)
    omega[:, 1] = np.sum(h * x_b, axis=1)
    omega[:, 2] = np.broadcast_to(np.asarray(yaw_rate, dtype=float), (len(j),)) * z_b[:, 2]
    return omega


def attitude_error(R_body_to_world: np.ndarray, R_des: np.ndarray) -> np.ndarray:
    """Rotation vector ``Log(R^T R_des)`` (rad, body frame), shape ``(n, 3)``.

    ``Log E = theta / sin(theta) * vee(E - E^T) / 2`` with ``cos(theta) = (tr E - 1) / 2``,
    which tolerates the rounding of a float32 rotation from an observation. Errors within
    1e-3 rad of a half turn, where that form loses its axis, go through SciPy instead
    (which costs about 100 times more, so it is not used for every call).
    """
    R = np.asarray(R_body_to_world, dtype=float).reshape(-1, 3, 3)
    Rd = np.asarray(R_des, dtype=float).reshape(-1, 3, 3)
    E = np.swapaxes(R, 1, 2) @ Rd
    cos_theta = np.clip((E[:, 0, 0] + E[:, 1, 1] + E[:, 2, 2] - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arccos(cos_theta)
    vee = np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], axis=1) / 2.0
    small = theta < 1e-4
    factor = np.where(small, 1.0 + theta**2 / 6.0, theta / np.where(small, 1.0, np.sin(theta)))
    out = factor[:, None] * vee
    half_turn = theta > math.pi - 1e-3
    if np.any(half_turn):
        out[half_turn] = Rotation.from_matrix(E[half_turn]).as_rotvec()
    return out


def level_attitude(R_body_to_world: np.ndarray) -> np.ndarray:
    """The level attitude with the heading of ``R_body_to_world`` ``(n, 3, 3)``."""
    R = np.asarray(R_body_to_world, dtype=float).reshape(-1, 3, 3)
    heading = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    return attitude_from_thrust(np.tile(_E3, (len(R), 1)), heading)[0]
