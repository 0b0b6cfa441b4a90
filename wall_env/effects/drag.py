"""Aerodynamic drag of the airframe, acting at the centre of mass.

``linear_drag`` is the paper's Eq. 4: in the body frame ``F_drag_body = -D v_body``
with ``D = diag(D)`` and ``v_body = R_body_to_world^T v_world``, opposing the
body-frame velocity. ``quadratic_drag`` is the high-speed counterpart,
``F_drag_body = -C |v_body| v_body`` element by element.

With the option ``wind`` both act on the air-relative velocity instead of the ground
velocity, ``v_body = R_body_to_world^T (v_world - w_world)``, with a steady wind
``w_world`` (m/s, world frame) as three more parameters: drag in wind, as the
literature writes it (for linear drag a steady wind is nearly a steady force; for
quadratic drag it is not).
"""

from __future__ import annotations

import casadi as ca

from wall_env.effects.base import Effect, FlightContext, Parameter, Wrench

WIND = Parameter("w", "m/s", (0.0, 0.0, 0.0), -30.0, 30.0, "steady wind velocity along world x, y, z", "world")


def _body_velocity(ctx: FlightContext, theta: dict[str, ca.SX]) -> ca.SX:
    """Air-relative velocity in the body frame (ground velocity without the wind option)."""
    v_air = ctx.v_world - theta["w"] if "w" in theta else ctx.v_world
    return ctx.R_body_to_world.T @ v_air


class LinearDrag(Effect):
    name = "linear_drag"
    description = "body-frame drag proportional to velocity"
    reference = "Yang et al., Wall Inspector, Eq. 4"
    parameters = (Parameter("D", "N s/m", (0.3, 0.3, 0.2), 0.0, 20.0, "drag coefficients along body x, y, z", "body"),)
    options = {"wind": False}
    optional_parameters = {"wind": (WIND,)}

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        f_body = -theta["D"] * _body_velocity(ctx, theta)
        return Wrench(ctx.R_body_to_world @ f_body, ca.SX.zeros(3))


class QuadraticDrag(Effect):
    name = "quadratic_drag"
    description = "body-frame drag proportional to velocity squared"
    reference = "standard bluff-body drag, F = -C |v| v per body axis"
    parameters = (
        Parameter("C", "N s^2/m^2", (0.05, 0.05, 0.05), 0.0, 20.0, "quadratic drag coefficients along body x, y, z", "body"),
    )
    options = {"wind": False}
    optional_parameters = {"wind": (WIND,)}

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        v_body = _body_velocity(ctx, theta)
        f_body = -theta["C"] * ca.fabs(v_body) * v_body
        return Wrench(ctx.R_body_to_world @ f_body, ca.SX.zeros(3))
