"""Rotation helpers for symbolic (CasADi) expressions, and two for batches of NumPy rows.

Quaternions are ``[w, x, y, z]`` (scalar first, Hamilton convention) and rotate body
vectors into the world frame. Numeric code uses :mod:`scipy.spatial.transform`, except
the envs' resets, which use :func:`euler_xyz_to_quat_rows` and :func:`quat_to_rotation_rows`
(closed forms on ``(n, ...)`` arrays, about 50x faster than SciPy's ``Rotation`` on
a thousand rows, checked against it in the tests).

``so3_exp`` and ``so3_log`` are smooth to every order the solvers need, also at the
identity, where the textbook ``acos`` form of Log has an infinite derivative:
``Log R = f(c) vee(R - R^T) / 2`` with ``c = (tr R - 1) / 2`` and
``f(c) = theta / sin(theta)`` evaluated by its series in ``1 - c`` near the identity.
Log is valid for rotations below about 170 deg.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["quat_to_rotation", "quat_multiply", "skew", "so3_exp", "so3_log", "euler_xyz_to_quat_rows",
           "quat_to_rotation_rows"]


def euler_xyz_to_quat_rows(angles: np.ndarray) -> np.ndarray:
    """Quaternions ``(n, 4)`` [w, x, y, z] of extrinsic x-y-z rotations ``(n, 3)`` (roll, pitch, yaw;
    SciPy's ``Rotation.from_euler("xyz", angles)``)."""
    half = 0.5 * np.ascontiguousarray(np.asarray(angles, dtype=float).T)  # (3, n): contiguous rows
    c, s = np.cos(half), np.sin(half)
    cx, cy, cz = c
    sx, sy, sz = s
    czcy, szsy, czsy, szcy = cz * cy, sz * sy, cz * sy, sz * cy
    return np.stack([czcy * cx + szsy * sx,
                     czcy * sx - szsy * cx,
                     czsy * cx + szcy * sx,
                     szcy * cx - czsy * sx], axis=1)


def quat_to_rotation_rows(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` of unit quaternions ``(n, 4)`` [w, x, y, z]."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], axis=1).reshape(-1, 3, 3)


def quat_to_rotation(q: ca.SX) -> ca.SX:
    """``R_body_to_world`` of a unit quaternion ``[w, x, y, z]``."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


def quat_multiply(a: ca.SX, b: ca.SX) -> ca.SX:
    """Hamilton product ``a * b``."""
    return ca.vertcat(
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    )


def skew(w):
    """``[w]x`` with ``[w]x v = w x v``."""
    return ca.vertcat(
        ca.horzcat(0, -w[2], w[1]),
        ca.horzcat(w[2], 0, -w[0]),
        ca.horzcat(-w[1], w[0], 0),
    )


def _vee_antisymmetric(M):
    return ca.vertcat(M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]) / 2


# Near the identity, theta / sin(theta) as a series in e = 1 - cos(theta):
# 1 + e/3 + 2 e^2/15 + 2 e^3/35 + 8 e^4/315 (next term below 1e-15 for e < 1e-3).
_SERIES_LIMIT = 1e-3


def so3_log(R):
    """Rotation vector of ``R`` (also of a nearly orthonormal matrix), smooth through the identity."""
    c = (R[0, 0] + R[1, 1] + R[2, 2] - 1) / 2
    e = 1 - c
    series = 1 + e * (1 / 3 + e * (2 / 15 + e * (2 / 35 + e * 8 / 315)))
    # the closed form is only selected for c <= 1 - _SERIES_LIMIT; its argument is clamped
    # well inside that (so acos and sqrt stay smooth where it is not selected, and the
    # clamp's kink never coincides with the switch, where it would halve the derivative)
    c_far = ca.fmax(ca.fmin(c, 1 - _SERIES_LIMIT / 2), -1 + 1e-9)
    closed = ca.acos(c_far) / ca.sqrt(1 - c_far**2)
    factor = ca.if_else(e < _SERIES_LIMIT, series, closed)
    return factor * _vee_antisymmetric(R)


def so3_exp(phi):
    """``Exp(phi)`` by Rodrigues' formula with series coefficients near zero (smooth everywhere)."""
    t2 = ca.dot(phi, phi)
    small = t2 < 1e-6
    t2_far = ca.fmax(t2, 0.5e-6)  # clamp kink away from the switch (see so3_log)
    t = ca.sqrt(t2_far)
    a = ca.if_else(small, 1 - t2 / 6 + t2**2 / 120, ca.sin(t) / t)
    b = ca.if_else(small, 0.5 - t2 / 24 + t2**2 / 720, (1 - ca.cos(t)) / t2_far)
    K = skew(phi)
    return ca.DM.eye(3) + a * K + b * (K @ K)
