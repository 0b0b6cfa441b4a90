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

The rotation maps ``Exp`` and ``Log`` come from :mod:`wall_env.rotations`, written to be
smooth to every order the solvers need, also at the identity.
"""

from __future__ import annotations

import casadi as ca

from wall_env.rotations import skew, so3_exp

__all__ = [
    "POINT_SIZE",
    "TANGENT_SIZE",
    "STATE_SIZE",
    "PointIndex",
    "TangentIndex",
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
    R_new = R @ so3_exp(delta[TangentIndex.theta_body])
    if orthonormalise:
        R_new = 1.5 * R_new - 0.5 * (R_new @ R_new.T @ R_new)
    return _pack(u + delta[TangentIndex.u], p + delta[TangentIndex.p_world], R_new, v + delta[TangentIndex.v_world])


def boxplus_first_order(point, delta):
    """``point [+] delta`` with ``Exp(dtheta) ~ I + [dtheta]x``: same value and first derivative at
    ``delta = 0`` as :func:`boxplus`, and a much smaller expression for Jacobians."""
    u, p, R, v = unpack_point(point)
    R_new = R + R @ skew(delta[TangentIndex.theta_body])
    return _pack(u + delta[TangentIndex.u], p + delta[TangentIndex.p_world], R_new, v + delta[TangentIndex.v_world])
