"""The MPC's variables on their manifold: layout, boxplus and boxminus (paper Sec. 3.1), in CasADi.

One *block* of the horizon holds the input of step k and the state it leads to,
``(u_k, x_{k+1})``, stored as a point of 19 numbers and perturbed in a tangent
space of 13 (paper Eq. 1-2):

=========  =====  ==========  =====================================================
quantity   point  tangent     boxplus
=========  =====  ==========  =====================================================
u          0-3    0-3         ``u + du``            (T in N, body rates in rad/s)
p_world    4-6    4-6         ``p + dp``            (m)
R          7-15   7-9         ``R Exp(dtheta)``     (R_body_to_world, column-major;
                                                     dtheta in the body frame)
v_world    16-18  10-12       ``v + dv``            (m/s)
=========  =====  ==========  =====================================================

Rotation helpers here are written to be smooth to every order the solvers need,
also at the identity, where ``wall_env.rotations.so3_log``'s ``acos`` has an
infinite derivative: :func:`so3_log_smooth` writes ``Log R = f(c) vee(R - R^T) / 2``
with ``c = (tr R - 1) / 2`` and ``f(c) = theta / sin(theta)`` evaluated by its
series in ``1 - c`` near the identity. It is valid for rotations below about 170 deg,
far beyond what one control step or a tracking error produces.
"""

from __future__ import annotations

import casadi as ca

__all__ = [
    "POINT_SIZE",
    "TANGENT_SIZE",
    "STATE_SIZE",
    "PointIndex",
    "TangentIndex",
    "skew",
    "so3_log_smooth",
    "so3_exp_smooth",
    "boxplus",
    "boxplus_first_order",
    "unpack_point",
]

POINT_SIZE = 19
TANGENT_SIZE = 13
STATE_SIZE = 15  # p (3), R (9), v (3): a state without its input


class PointIndex:
    u = slice(0, 4)
    p_world = slice(4, 7)
    R_body_to_world = slice(7, 16)
    v_world = slice(16, 19)
    state = slice(4, 19)


class TangentIndex:
    u = slice(0, 4)
    p_world = slice(4, 7)
    theta_body = slice(7, 10)
    v_world = slice(10, 13)


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


def so3_log_smooth(R):
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


def so3_exp_smooth(phi):
    """``Exp(phi)`` by Rodrigues' formula with series coefficients near zero (smooth everywhere)."""
    t2 = ca.dot(phi, phi)
    small = t2 < 1e-6
    t2_far = ca.fmax(t2, 0.5e-6)  # clamp kink away from the switch (see so3_log_smooth)
    t = ca.sqrt(t2_far)
    a = ca.if_else(small, 1 - t2 / 6 + t2**2 / 120, ca.sin(t) / t)
    b = ca.if_else(small, 0.5 - t2 / 24 + t2**2 / 720, (1 - ca.cos(t)) / t2_far)
    K = skew(phi)
    return ca.DM.eye(3) + a * K + b * (K @ K)


def unpack_point(point):
    """``(u, p_world, R_body_to_world (3x3), v_world)`` of a 19-vector."""
    return (
        point[PointIndex.u],
        point[PointIndex.p_world],
        ca.reshape(point[PointIndex.R_body_to_world], 3, 3),
        point[PointIndex.v_world],
    )


def _pack(u, p, R, v):
    return ca.vertcat(u, p, ca.reshape(R, 9, 1), v)


def boxplus(point, delta, orthonormalise: bool = True):
    """``point [+] delta`` with the exact exponential (optionally one polar-decomposition
    Newton step, ``R <- (3 R - R R^T R) / 2``, to remove rounding drift)."""
    u, p, R, v = unpack_point(point)
    R_new = R @ so3_exp_smooth(delta[TangentIndex.theta_body])
    if orthonormalise:
        R_new = 1.5 * R_new - 0.5 * (R_new @ R_new.T @ R_new)
    return _pack(u + delta[TangentIndex.u], p + delta[TangentIndex.p_world], R_new, v + delta[TangentIndex.v_world])


def boxplus_first_order(point, delta):
    """``point [+] delta`` with ``Exp(dtheta) ~ I + [dtheta]x``: same value and first derivative at
    ``delta = 0`` as :func:`boxplus`, and a much smaller expression for Jacobians."""
    u, p, R, v = unpack_point(point)
    R_new = R + R @ skew(delta[TangentIndex.theta_body])
    return _pack(u + delta[TangentIndex.u], p + delta[TangentIndex.p_world], R_new, v + delta[TangentIndex.v_world])
