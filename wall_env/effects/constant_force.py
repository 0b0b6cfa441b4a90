"""Constant force in the world frame: steady wind, a tether, or a bias of the thrust model."""

from __future__ import annotations

import casadi as ca

from wall_env.effects.base import Effect, FlightContext, Parameter, Wrench


class ConstantForce(Effect):
    name = "constant_force"
    description = "steady force in the world frame, acting at the centre of mass"
    reference = "steady wind or bias"
    parameters = (Parameter("F", "N", (0.0, 0.0, 0.0), -50.0, 50.0, "force along world x, y, z", "world"),)

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        return Wrench(theta["F"], ca.SX.zeros(3))
