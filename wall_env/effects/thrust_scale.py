"""Thrust scale: the rotors produce ``scale`` times the thrust the model expects.

Stands for a thrust-coefficient error or a sagging battery. The extra thrust
``(scale - 1) f_j`` acts along +z_body at each rotor (so roll and pitch moments
scale too; the rotors' drag torque is left as commanded).
"""

from __future__ import annotations

import casadi as ca

from wall_env.effects.base import Effect, FlightContext, Parameter, Wrench


class ThrustScale(Effect):
    name = "thrust_scale"
    description = "actual rotor thrust = scale x commanded rotor thrust"
    reference = "thrust-coefficient or battery-voltage mismatch"
    parameters = (Parameter("scale", "-", 1.0, 0.3, 2.0, "ratio of actual to commanded thrust"),)

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        return Wrench.from_rotor_thrust_changes(ctx, [(theta["scale"] - 1.0) * ctx.rotor_thrusts[j] for j in range(4)])
