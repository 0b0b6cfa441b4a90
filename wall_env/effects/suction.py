"""Wall suction: the paper's per-rotor model (Sec. 3.2, Eq. 6, 9, 10).

For every wall plane k (point ``c_k``, outward unit normal ``n_k``) and rotor j at
``p_j = p_world + R_body_to_world r_j``, the rotor's distance to the wall is
``d_j = n_k . (p_j - c_k)``. Within the threshold the rotor is pulled toward the
wall, against the outward normal:

    F_j = -n_k * k_s * max(0, d_thr - max(d_j, 0))            (Eq. 6, 10)

so the force grows linearly from zero at ``d_thr`` to ``k_s d_thr`` at the surface.
With the option ``thrust_scaling`` (off by default, as in the paper's flight model)
each rotor's force is multiplied by its thrust relative to hover, ``f_j / (m g / 4)``,
following the paper's bench finding that suction grows with rotor speed (Fig. 8).

The force acts at each rotor centre, so unequal rotor forces (one rotor nearer the
wall than another) also produce a moment about the centre of mass. The paper's
model (Eq. 10) lumps the rotor forces into one force at the centre of mass and has
no moment; the translational part here is identical to the paper's.

On finite and curved surfaces (a scene with bodies, :mod:`wall_env.bodies`) the model
is read locally: each rotor also feels its *local surfaces* (:class:`~wall_env.scene.RotorSurface`),
tangent planes through the nearest points of the scene's bodies that PyBullet finds for that
rotor (:mod:`wall_env.surfaces`, where the choice at edges is documented), each with a
weight ``w``:

    F_j += -n_s * k_s * max(0, d_thr - max(d_s, 0)) * w_s,   d_s = n_s . (p_j - c_s)

the same expression as for a wall plane. A plane built as a mesh therefore pulls
exactly as the plane does.
"""

from __future__ import annotations

import casadi as ca

from wall_env.effects.base import Effect, FlightContext, Parameter, Wrench


class WallSuction(Effect):
    name = "wall_suction"
    description = "per-rotor pull toward a wall plane within a threshold distance"
    reference = "Yang et al., Wall Inspector, Eq. 6, 9, 10"
    parameters = (
        Parameter("k_s", "N/m", 4.1, 0.0, 200.0, "suction force scale factor"),
        Parameter("d_thr", "m", 0.132, 1e-3, 1.0, "threshold distance beyond which there is no suction"),
    )
    options = {"thrust_scaling": False}

    def applies_to(self, scene_structure: tuple) -> bool:
        return scene_structure[0] > 0 or (len(scene_structure) > 3 and scene_structure[3] > 0)

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        return Wrench.from_rotor_forces(ctx, self.rotor_forces(ctx, theta))

    def rotor_forces(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> list[ca.SX]:
        """Each rotor's suction force (world frame, N), as the module docstring writes it."""
        k_s, d_thr = theta["k_s"], theta["d_thr"]

        def magnitude(p_rotor: ca.SX, point: ca.SX, normal: ca.SX) -> ca.SX:
            d_j = ca.dot(normal, p_rotor - point)
            return k_s * ca.fmax(0.0, d_thr - ca.fmax(d_j, 0.0))

        forces = []
        for j in range(4):
            p_rotor = ctx.rotor_position_world(j)
            scale = ctx.rotor_thrusts[j] / ctx.hover_rotor_thrust if self.option_values["thrust_scaling"] else 1.0
            f_j = ca.SX.zeros(3)
            for point, normal in zip(ctx.scene.wall_points, ctx.scene.wall_normals):
                f_j -= normal * magnitude(p_rotor, point, normal) * scale
            for surface in ctx.scene.rotor_surfaces[j] if ctx.scene.rotor_surfaces else ():
                f_j -= surface.normal * magnitude(p_rotor, surface.point, surface.normal) * scale * surface.weight
            forces.append(f_j)
        return forces
