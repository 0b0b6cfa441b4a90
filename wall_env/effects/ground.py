"""Ground effect: each rotor's thrust grows near the ground plane.

Per rotor j at height ``h_j`` of its centre above the ground, the thrust gain is the
Cheeseman-Bennett image-rotor result (Cheeseman & Bennett, "The effect of the ground
on a helicopter rotor in forward flight", ARC R&M 3021, 1955):

    T_IGE / T_OGE = 1 / (1 - (r / (4 h_j))^2)

with ``r`` an effective rotor radius, the one parameter (for multirotors the gain is
larger than for one isolated rotor, see Sanchez-Cuevas et al., "Characterization of
the aerodynamic ground effect and its influence in multirotor control", IJAE 2017;
an effective radius absorbs that). The height is clamped at ``r / 2`` so the gain
stays finite (at most 4/3). With the option ``distance_offset`` (a second parameter, the
distance offset ``k2`` of Sanchez-Cuevas et al.) the gain follows ``h_j + offset``:
``1 / (1 - (r / (4 (h_j + offset)))^2)``, their ``1 / (1 - (1/k1) (R / (d + k2))^2)``
with ``k1 = 16 (R / r)^2``. The extra thrust ``(gain - 1) f_j`` acts along +z_body at
the rotor, so unequal heights also give a moment.
"""

from __future__ import annotations

import casadi as ca

from wall_env.effects.base import Effect, FlightContext, Parameter, Wrench


def image_rotor_gain(radius: ca.SX, distance: ca.SX, offset: ca.SX | float = 0.0) -> ca.SX:
    """Thrust ratio ``1 / (1 - (r / (4 (h + offset)))^2)`` with ``h + offset`` clamped at ``r / 2``.

    With the offset this is Sanchez-Cuevas et al.'s form ``1 / (1 - (1/k1) (R / (d + k2))^2)``
    for a rotor of radius ``R``: ``k2 = offset`` and ``k1 = 16 (R / r)^2``, ``r`` the effective radius.
    """
    h = ca.fmax(distance + offset, radius / 2.0)
    return 1.0 / (1.0 - (radius / (4.0 * h)) ** 2)


#: effective radii (distance plus offset) from the surface out to which the form is trusted: nearer, how the gain
#: levels off is the clamp's guess (here half the radius), not something a measured rotor need share
FORM_TRUSTED_FROM_RADII = 1.0

OFFSET = Parameter("offset", "m", 0.0, -0.05, 0.5,
                   "distance offset k2 of Sanchez-Cuevas et al. (the gain follows the distance plus this)")


class GroundEffect(Effect):
    name = "ground_effect"
    description = "per-rotor thrust gain near the ground plane"
    reference = "Cheeseman & Bennett 1955 (ARC R&M 3021)"
    parameters = (Parameter("radius", "m", 0.06, 1e-3, 0.5, "effective rotor radius of the image-rotor model"),)
    options = {"distance_offset": False}
    optional_parameters = {"distance_offset": (OFFSET,)}

    def applies_to(self, scene_structure: tuple) -> bool:
        return scene_structure[1]

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        extra = []
        for j in range(4):
            height = ctx.rotor_position_world(j)[2] - ctx.scene.ground_z
            extra.append((image_rotor_gain(theta["radius"], height, theta.get("offset", 0.0)) - 1.0)
                         * ctx.rotor_thrusts[j])
        return Wrench.from_rotor_thrust_changes(ctx, extra)
