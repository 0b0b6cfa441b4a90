"""Ceiling effect: each rotor's thrust grows close under a ceiling, pulling the vehicle up.

Per rotor j whose centre is ``h_j`` below the ceiling plane, the thrust ratio follows
the form of Sanchez-Cuevas, Heredia & Ollero, "Multirotor UAS for bridge inspection by
contact using the ceiling effect" (ICUAS 2017), ``1 / (1 - (1/k1) (R / (d + k2))^2)``.
By default their offset ``k2`` is zero, which is the image-rotor expression used for
the ground:

    T_ICE / T_OCE = 1 / (1 - (r / (4 h_j))^2)

and with the option ``distance_offset`` the offset ``offset`` is a second parameter,
``1 / (1 - (r / (4 (h_j + offset)))^2)`` (``k1 = 16 (R / r)^2`` for rotor radius ``R``),

with its own effective radius ``r`` (the ceiling effect is typically stronger than the
ground effect at equal distance, hence the larger default). The extra thrust acts
along +z_body at the rotor.
"""

from __future__ import annotations

import casadi as ca

from wall_env.effects.base import Effect, FlightContext, Parameter, Wrench
from wall_env.effects.ground import OFFSET, image_rotor_gain


class CeilingEffect(Effect):
    name = "ceiling_effect"
    description = "per-rotor thrust gain close below a ceiling plane"
    reference = "Sanchez-Cuevas, Heredia & Ollero, ICUAS 2017"
    parameters = (Parameter("radius", "m", 0.08, 1e-3, 0.5, "effective rotor radius of the image-rotor model"),)
    options = {"distance_offset": False}
    optional_parameters = {"distance_offset": (OFFSET,)}

    def applies_to(self, scene_structure: tuple) -> bool:
        return scene_structure[2]

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        extra = []
        for j in range(4):
            depth = ctx.scene.ceiling_z - ctx.rotor_position_world(j)[2]
            extra.append((image_rotor_gain(theta["radius"], depth, theta.get("offset", 0.0)) - 1.0)
                         * ctx.rotor_thrusts[j])
        return Wrench.from_rotor_thrust_changes(ctx, extra)
