"""Contact between the vehicle and the scene's planes, in closed form.

The scene is planes (walls, the ground, an optional ceiling) and the vehicle's collision
geometry is four ducts (cylinders of ``duct_radius`` and ``duct_height`` around the
rotor centres, axis along body z) plus a central box (:func:`collision_shapes`). The
PyBullet scene of :mod:`wall_env.bullet_world` is built from the same shapes.

For a plane through ``point`` with outward unit normal ``n``, the signed distance of
the deepest point of each shape is

* duct centred at ``c`` with axis ``a`` (body z in the world):
  ``n . (c - point) - (h / 2) |n . a| - r sqrt(1 - (n . a)^2)``;
* box centred at the centre of mass ``p`` with half extents ``e`` along body axes
  ``b_i``: ``n . (p - point) - sum_i e_i |n . b_i|``.

The penetration of a plane is ``max(0, -min over shapes)``. The response to each
plane in contact, in the order walls, ground, ceiling: the vehicle is pushed out
along ``n`` by the penetration and its velocity into the plane is reflected with the
restitution ``e``: ``v <- v - (1 + e) min(n . v, 0) n``. Both envs use this response
(it is part of the compiled control step, :func:`wall_env.dynamics.build_env_step_function`),
so a vehicle of a batch and a single env bounce identically.

Against a scene's bodies (boxes, cylinders, meshes) the penetration and its normal come
from PyBullet's collision query (:meth:`wall_env.surfaces.SurfaceQuery.contacts`) after
the compiled step, and :func:`respond` applies this same response (:func:`plane_response`,
the one definition) to the deepest contact, until the vehicle is clear.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from wall_env.scene import SceneSymbols
from wall_env.vehicle import VehicleParams

__all__ = ["CollisionShapes", "collision_shapes", "scene_planes", "plane_clearances", "contact_response",
           "plane_response", "respond", "SURFACES"]


@dataclass(frozen=True)
class CollisionShapes:
    """The vehicle's collision geometry in the body frame (m)."""

    duct_centres: np.ndarray  # (4, 3)
    duct_radius: float
    duct_height: float
    box_half_extents: np.ndarray  # (3,)


def collision_shapes(vehicle: VehicleParams) -> CollisionShapes:
    """Ducts around the rotor centres and a central box reaching the ducts' inner edges."""
    rotors = vehicle.rotor_positions_array
    arm_half = float(np.max(np.linalg.norm(rotors[:, :2], axis=1))) - vehicle.duct_radius
    half = max(arm_half, 0.02) / 2
    return CollisionShapes(rotors.copy(), float(vehicle.duct_radius), float(vehicle.duct_height),
                           np.array([half, half, 0.015]))


def scene_planes(symbols: SceneSymbols) -> tuple[list[tuple[ca.SX, ca.SX]], list[str]]:
    """The scene's planes as ``(point, outward normal)`` pairs and the surface name of each."""
    planes = list(zip(symbols.wall_points, symbols.wall_normals))
    names = ["wall"] * len(planes)
    if symbols.ground_z is not None:
        planes.append((ca.vertcat(0, 0, symbols.ground_z), ca.DM([0.0, 0.0, 1.0])))
        names.append("ground")
    if symbols.ceiling_z is not None:
        planes.append((ca.vertcat(0, 0, symbols.ceiling_z), ca.DM([0.0, 0.0, -1.0])))
        names.append("ceiling")
    return planes, names


SURFACES = ("wall", "ground", "ceiling", "structure")  # structure: a body of the scene (wall_env.bodies)


def _shape_distances(p: ca.SX, R: ca.SX, shapes: CollisionShapes, point, normal) -> list[ca.SX]:
    axis = R[:, 2]
    along = ca.dot(normal, axis)
    across = ca.sqrt(ca.fmax(1.0 - along * along, 0.0))
    distances = []
    for centre in shapes.duct_centres:
        c = p + R @ ca.DM(centre)
        distances.append(ca.dot(normal, c - point) - shapes.duct_height / 2 * ca.fabs(along)
                         - shapes.duct_radius * across)
    box = ca.dot(normal, p - point)
    for i in range(3):
        box -= float(shapes.box_half_extents[i]) * ca.fabs(ca.dot(normal, R[:, i]))
    distances.append(box)
    return distances


def plane_clearances(p: ca.SX, R: ca.SX, symbols: SceneSymbols, shapes: CollisionShapes) -> list[ca.SX]:
    """Signed distance (m) of the vehicle's deepest point from each of the scene's planes (walls, ground,
    ceiling, in :func:`scene_planes`' order): positive when clear, minus the penetration when inside."""
    planes, _ = scene_planes(symbols)
    return [ca.mmin(ca.vertcat(*_shape_distances(p, R, shapes, point, normal))) for point, normal in planes]


def contact_response(p: ca.SX, R: ca.SX, v: ca.SX, symbols: SceneSymbols, shapes: CollisionShapes,
                     restitution: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """``(p_after, v_after, penetrations)``: the response described in the module docstring;
    ``penetrations`` has one entry per plane (walls, ground, ceiling), zero when clear."""
    planes, _ = scene_planes(symbols)
    depths = [ca.fmax(-clearance, 0.0) for clearance in plane_clearances(p, R, symbols, shapes)]
    for (_, normal), depth in zip(planes, depths):
        p, v = plane_response(p, v, normal, depth, restitution)
    penetrations = ca.vertcat(*depths) if depths else ca.SX.zeros(0, 1)
    return p, v, penetrations


def plane_response(p: ca.SX, v: ca.SX, normal: ca.SX, depth: ca.SX, restitution: ca.SX) -> tuple[ca.SX, ca.SX]:
    """The response to one contact of ``depth`` (m, 0 when clear) along the outward unit ``normal``: pushed out
    by the depth, the velocity into the surface reflected with the restitution."""
    touching = depth > 0
    p = p + depth * normal
    v_n = ca.dot(v, normal)
    v = v - ca.if_else(touching, (1.0 + restitution) * ca.fmin(v_n, 0.0), 0.0) * normal
    return p, v


_RESPONSE: list[ca.Function] = []


def respond(p_world: np.ndarray, v_world: np.ndarray, normal: np.ndarray, depth: float, restitution: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`plane_response` on numbers (a contact found by PyBullet): ``(p_world, v_world)`` after it."""
    if not _RESPONSE:
        p, v, n = ca.SX.sym("p", 3), ca.SX.sym("v", 3), ca.SX.sym("n", 3)
        depth_sym, e = ca.SX.sym("depth"), ca.SX.sym("e")
        _RESPONSE.append(ca.Function("plane_response", [p, v, n, depth_sym, e],
                                     list(plane_response(p, v, n, depth_sym, e))))
    p_after, v_after = _RESPONSE[0](p_world, v_world, normal, depth, restitution)
    return np.asarray(p_after).reshape(3), np.asarray(v_after).reshape(3)
