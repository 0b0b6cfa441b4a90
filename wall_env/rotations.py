"""Rotation helpers for symbolic (CasADi) expressions.

Quaternions are ``[w, x, y, z]`` (scalar first, Hamilton convention) and rotate body
vectors into the world frame. Numeric code uses :mod:`scipy.spatial.transform`.
"""

from __future__ import annotations

import casadi as ca

__all__ = ["quat_to_rotation", "quat_multiply", "skew", "so3_exp", "so3_log"]


def skew(w: ca.SX) -> ca.SX:
    """Matrix ``[w]x`` with ``[w]x v = w x v``."""
    return ca.vertcat(
        ca.horzcat(0, -w[2], w[1]),
        ca.horzcat(w[2], 0, -w[0]),
        ca.horzcat(-w[1], w[0], 0),
    )


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


def so3_exp(phi: ca.SX) -> ca.SX:
    """Rotation matrix of a rotation vector (Rodrigues), smooth through zero."""
    theta2 = ca.dot(phi, phi)
    small = theta2 < 1e-8
    theta = ca.sqrt(theta2 + 1e-300)
    a = ca.if_else(small, 1 - theta2 / 6, ca.sin(theta) / theta)
    b = ca.if_else(small, 0.5 - theta2 / 24, (1 - ca.cos(theta)) / (theta2 + 1e-300))
    K = skew(phi)
    return ca.SX.eye(3) + a * K + b * (K @ K)


def so3_log(R: ca.SX) -> ca.SX:
    """Rotation vector of a rotation matrix (valid for angles below pi)."""
    cos_theta = ca.fmin(ca.fmax((ca.trace(R) - 1) / 2, -1 + 1e-12), 1.0)
    theta = ca.acos(cos_theta)
    sin_theta = ca.sin(theta)
    small = theta < 1e-4
    factor = ca.if_else(small, 0.5 + theta**2 / 12, theta / (2 * sin_theta + 1e-300))
    return factor * ca.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
