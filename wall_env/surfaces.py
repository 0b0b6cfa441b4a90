"""Each rotor's local surfaces, and the vehicle's contacts, from PyBullet's closest-point queries on a scene's bodies.

A scene's bodies (:mod:`wall_env.bodies`) are loaded into a headless PyBullet client:
every box and cylinder as one compound body, each mesh and each URDF model as a body of
its own (:func:`add_bodies`; the pictures of :mod:`wall_env.bullet_world` load the same
bodies). :class:`SurfaceQuery` asks PyBullet, for many vehicles at once, where the
surfaces near each rotor are:

**What a rotor feels** (the documented choice for finite and curved surfaces). A rotor is
its centre. For each body part within :attr:`SurfaceQuery.reach` of the rotor centre
(a box or cylinder of the compound, a triangle of a mesh, a URDF link), PyBullet's
closest-point query gives the part's distance ``d`` from the rotor centre and the outward
normal ``n`` there (from the part toward the rotor); the local surface is the tangent plane
with normal ``n`` through the nearest point ``c = p_rotor - d n``. The wall suction (:mod:`wall_env.effects.suction`)
reads two of them per rotor (:data:`~wall_env.scene.SURFACE_SLOTS`):

* slot 0, the nearest point of all, weight 1;
* slot 1, the nearest point of another surface: its normal turns more than 30 degrees from
  slot 0's and it lies off slot 0's tangent plane; its weight rises linearly from 0 at 30
  degrees to 1 at 60 degrees and beyond, times a factor rising from 0 on slot 0's plane
  to 1 at :data:`SAME_PLANE` from it (the neighbouring triangles of a flat mesh, whose
  nearest points lie on the same plane, add nothing).

So over a face a rotor feels the face's plane (exactly: a plane built as a mesh pulls as
the plane does); **at an edge**, a rotor partly or wholly past it feels the edge itself:
its distance grows as ``sqrt(h^2 + s^2)`` (stand-off ``h``, ``s`` past the edge) and the
pull turns from the face's normal toward the edge, so the suction fades continuously over
about ``d_thr`` past the edge rather than stopping; on a curved surface (a cylinder) a
rotor feels the tangent plane at its foot point. In an inside corner (a ledge meeting a
facade) both faces pull, as two wall planes do; two coplanar parts side by side (the seam
of two boxes) pull once. The weight ramp keeps the force continuous when the nearest point
moves from one face to the other.

Within one control step the compiled integration holds each rotor's tangent planes
fixed (taken at the step's start); on a plane this is exact, on a curved surface the
error is of second order in the distance moved in a step (a test bounds it against
querying at every physics step).

**Contacts** come from PyBullet too: the vehicle's collision shapes
(:func:`wall_env.contact.collision_shapes`) against the bodies, asked only for vehicles
that some probe (a rotor centre or the centre of mass) has within
:attr:`SurfaceQuery.contact_reach` of a surface; each contact is a penetration depth and
the normal along which the vehicle leaves the body.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from wall_env.bodies import Body, Box, Cylinder, Mesh, Urdf, rpy_to_rotation
from wall_env.contact import collision_shapes
from wall_env.pybullet_client import connect, pybullet, quiet_native_output
from wall_env.rotations import quat_to_rotation_rows
from wall_env.scene import ROTOR_COUNT, SURFACE_SLOTS, Scene
from wall_env.vehicle import VehicleParams

__all__ = ["SurfaceQuery", "RotorSurfaces", "add_bodies", "surface_weight", "PROBE_RADIUS", "SECOND_SLOT_ANGLES",
           "SAME_PLANE", "REACH_MARGIN", "NO_SURFACE"]

PROBE_RADIUS = 1e-3  # m, the sphere PyBullet measures from (its radius is added back)
SECOND_SLOT_ANGLES = (math.radians(30.0), math.radians(60.0))  # slot 1's weight ramps from 0 to 1 across these
SAME_PLANE = 0.02  # m, a point nearer than this to slot 0's tangent plane is partly (on it: wholly) the same surface
REACH_MARGIN = 0.05  # m, queried beyond the suction's threshold: what a vehicle moves in a step at 5 m/s
NO_SURFACE = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0])  # a slot with nothing in it (weight 0)
_BODY_COLOUR = (0.72, 0.7, 0.66, 1.0)


def surface_weight(cos_angle: np.ndarray, off_plane: np.ndarray) -> np.ndarray:
    """Slot 1's weight (0 to 1) for the cosine of the angle between its normal and slot 0's and its point's
    distance (m) from slot 0's tangent plane."""
    low, high = SECOND_SLOT_ANGLES
    angle = np.arccos(np.clip(cos_angle, -1.0, 1.0))
    on_plane = np.clip((np.abs(off_plane) - 1e-9) / SAME_PLANE, 0.0, 1.0)  # a nanometre is rounding: on it
    return np.clip((angle - low) / (high - low), 0.0, 1.0) * on_plane


def _quaternion(rpy: Sequence[float]) -> list[float]:
    return Rotation.from_matrix(rpy_to_rotation(rpy)).as_quat().tolist()  # x, y, z, w


def add_bodies(client: int, bodies: Sequence[Body], visual: bool = False,
               colour: tuple[float, float, float, float] = _BODY_COLOUR) -> list[int]:
    """Load ``bodies`` into PyBullet client ``client`` as static bodies; return their ids (the compound of
    boxes and cylinders first, then one per mesh and URDF). ``visual``: give them visual shapes (pictures).
    A file PyBullet cannot read raises ``ValueError`` naming it."""
    ids: list[int] = []
    primitives = [b for b in bodies if isinstance(b, (Box, Cylinder))]
    if primitives:
        kinds, radii, lengths, halves, positions, orientations = [], [], [], [], [], []
        for primitive in primitives:
            if isinstance(primitive, Box):
                kinds.append(pybullet.GEOM_BOX)
                radii.append(0.0)
                lengths.append(0.0)
                halves.append([s / 2 for s in primitive.size])
            else:
                kinds.append(pybullet.GEOM_CYLINDER)
                radii.append(primitive.radius)
                lengths.append(primitive.length)
                halves.append([0.0, 0.0, 0.0])
            positions.append(list(primitive.position))
            orientations.append(_quaternion(primitive.rpy))
        shape = pybullet.createCollisionShapeArray(
            shapeTypes=kinds, radii=radii, lengths=lengths, halfExtents=halves, collisionFramePositions=positions,
            collisionFrameOrientations=orientations, physicsClientId=client)
        look = -1
        if visual:
            look = pybullet.createVisualShapeArray(
                shapeTypes=kinds, radii=radii, lengths=lengths, halfExtents=halves, visualFramePositions=positions,
                visualFrameOrientations=orientations, rgbaColors=[list(colour)] * len(kinds), physicsClientId=client)
        ids.append(pybullet.createMultiBody(0, shape, look, physicsClientId=client))
    for body in bodies:
        if isinstance(body, Mesh):
            try:
                with quiet_native_output():
                    shape = pybullet.createCollisionShape(
                        pybullet.GEOM_MESH, fileName=body.file, meshScale=list(body.scale),
                        flags=pybullet.GEOM_FORCE_CONCAVE_TRIMESH, physicsClientId=client)
                    look = pybullet.createVisualShape(pybullet.GEOM_MESH, fileName=body.file, meshScale=list(body.scale),
                                                      rgbaColor=list(colour), physicsClientId=client) if visual else -1
            except pybullet.error:
                raise ValueError(f"mesh file {body.file}: PyBullet cannot read it as a Wavefront OBJ mesh") from None
            ids.append(pybullet.createMultiBody(0, shape, look, basePosition=list(body.position),
                                                baseOrientation=_quaternion(body.rpy), physicsClientId=client))
        elif isinstance(body, Urdf):
            try:
                with quiet_native_output():
                    ids.append(pybullet.loadURDF(body.file, basePosition=list(body.position),
                                                 baseOrientation=_quaternion(body.rpy), useFixedBase=True,
                                                 globalScaling=body.scale, physicsClientId=client))
            except pybullet.error:
                raise ValueError(f"URDF file {body.file}: PyBullet cannot load it") from None
    for body_id in ids:  # sharp edges: PyBullet rounds them by its collision margin otherwise (1 mm)
        for link in range(-1, pybullet.getNumJoints(body_id, physicsClientId=client)):
            pybullet.changeDynamics(body_id, link, collisionMargin=0.0, physicsClientId=client)
    return ids


@dataclass
class RotorSurfaces:
    """What :meth:`SurfaceQuery.rotor_surfaces` found for ``n`` vehicles.

    ``distance (n, 4)``: each rotor centre's distance to its nearest surface (``inf`` if none within the reach);
    ``normal (n, 4, 3)``: that surface's outward normal (zeros if none); ``centre_distance (n,)``: the centre of
    mass's distance to its nearest surface (``inf`` if none within the reach)."""

    distance: np.ndarray
    normal: np.ndarray
    centre_distance: np.ndarray


class SurfaceQuery:
    """PyBullet's closest-point queries on a scene's bodies, for vehicles of ``vehicle``'s layout.

    ``reach`` (m): surfaces farther than this from a rotor are not reported (the envs use the largest
    ``d_thr`` their episodes can draw plus :data:`REACH_MARGIN`).
    """

    def __init__(self, scene: Scene, vehicle: VehicleParams, reach: float):
        if not scene.bodies:
            raise ValueError("SurfaceQuery needs a scene with bodies (boxes, cylinders, meshes or URDF models)")
        self.scene = scene
        self.reach = float(reach)
        self._bullet = connect()
        self.client = self._bullet._client
        self.bodies = add_bodies(self.client, scene.bodies)
        self.rotors_body = vehicle.rotor_positions_array
        probes = np.vstack([self.rotors_body, np.zeros((1, 3))])  # the rotors, then the centre of mass
        self._probe = pybullet.createCollisionShapeArray(
            shapeTypes=[pybullet.GEOM_SPHERE] * len(probes), radii=[PROBE_RADIUS] * len(probes),
            collisionFramePositions=probes.tolist(), physicsClientId=self.client)
        self._point = pybullet.createCollisionShape(pybullet.GEOM_SPHERE, radius=PROBE_RADIUS,
                                                    physicsClientId=self.client)
        shapes = collision_shapes(vehicle)
        n_ducts = len(shapes.duct_centres)
        self._vehicle = pybullet.createCollisionShapeArray(
            shapeTypes=[pybullet.GEOM_CYLINDER] * n_ducts + [pybullet.GEOM_BOX],
            radii=[shapes.duct_radius] * n_ducts + [0.0], lengths=[shapes.duct_height] * n_ducts + [0.0],
            halfExtents=[[0.0, 0.0, 0.0]] * n_ducts + [list(shapes.box_half_extents)],
            collisionFramePositions=[list(c) for c in shapes.duct_centres] + [[0.0, 0.0, 0.0]],
            physicsClientId=self.client)
        # every point of the collision shapes lies within this distance of a probe: nearer than this to a
        # surface, and a vehicle may touch it
        duct_reach = math.hypot(shapes.duct_radius, shapes.duct_height / 2)
        self.contact_reach = max(duct_reach, float(np.linalg.norm(shapes.box_half_extents))) + 1e-3
        # each body's bounding box, grown by the reach and the probes' spread: a vehicle whose centre is
        # outside it has nothing of that body within the reach, and PyBullet is not asked
        spread = float(np.max(np.linalg.norm(self.rotors_body, axis=1))) + PROBE_RADIUS
        self._boxes = []
        for body in self.bodies:
            links = range(-1, pybullet.getNumJoints(body, physicsClientId=self.client))
            corners = np.array([pybullet.getAABB(body, link, physicsClientId=self.client) for link in links])
            self._boxes.append((corners[:, 0].min(axis=0) - self.reach - spread,
                                corners[:, 1].max(axis=0) + self.reach + spread))

    # ------------------------------------------------------------------ rotors
    def rotor_surfaces(self, p_world: np.ndarray, q_body_to_world: np.ndarray, out: np.ndarray) -> RotorSurfaces:
        """Each rotor's local surfaces (module docstring) for vehicles at ``p_world (n, 3)`` with attitudes
        ``q_body_to_world (n, 4)`` ([w, x, y, z]), written into ``out (n, 4 * SURFACE_SLOTS * SURFACE_SIZE)``
        (rotor 0's slots, then rotor 1's, ...; :data:`~wall_env.scene.SURFACE_SIZE` numbers a slot)."""
        n = p_world.shape[0]
        R = quat_to_rotation_rows(q_body_to_world)  # (n, 3, 3)
        probes = p_world[:, None, :] + np.einsum("nij,kj->nki", R, np.vstack([self.rotors_body, np.zeros((1, 3))]))
        xyzw = q_body_to_world[:, [1, 2, 3, 0]].tolist()
        positions = p_world.tolist()
        found: list = []
        rows: list[int] = []
        distance = self.reach - PROBE_RADIUS
        query = pybullet.getClosestPoints
        client, probe = self.client, self._probe
        for body, (low, high) in zip(self.bodies, self._boxes):
            for i in np.flatnonzero(np.all((p_world >= low) & (p_world <= high), axis=1)).tolist():
                points = query(-1, body, distance, collisionShapeA=probe, collisionShapePositionA=positions[i],
                               collisionShapeOrientationA=xyzw[i], physicsClientId=client)
                if points:
                    found.extend(points)
                    rows.extend([i] * len(points))
        slots = np.tile(NO_SURFACE, (n * ROTOR_COUNT, SURFACE_SLOTS, 1))  # [row and rotor, slot, entry]
        result = RotorSurfaces(np.full((n, ROTOR_COUNT), np.inf), np.zeros((n, ROTOR_COUNT, 3)), np.full(n, np.inf))
        if not found:
            out[:] = slots.reshape(n, -1)
            return result
        data = np.array([pt[5] + pt[6] + pt[7] + (pt[8],) for pt in found])  # on A, on B, normal on B, distance
        row = np.asarray(rows)
        normal_b = data[:, 6:9]
        centre = data[:, 0:3] + PROBE_RADIUS * normal_b  # the probe sphere's centre
        which = np.argmin(np.linalg.norm(probes[row] - centre[:, None, :], axis=2), axis=1)  # rotor 0-3, or 4: centre
        probe_at = probes[row, which]
        # PyBullet's distance and normal (its witness points are less exact: a millimetre off along a cylinder
        # when asked with a compound), and the nearest point on the tangent plane they give
        d = data[:, 9] + PROBE_RADIUS
        normal = normal_b / np.linalg.norm(normal_b, axis=1)[:, None]
        surface = probe_at - d[:, None] * normal
        centre_rows = which == ROTOR_COUNT
        np.minimum.at(result.centre_distance, row[centre_rows], d[centre_rows])
        keep = ~centre_rows
        row, which, surface, normal, d = row[keep], which[keep], surface[keep], normal[keep], d[keep]
        key = row * ROTOR_COUNT + which
        order = np.lexsort((d, key))
        key, surface, normal, d = key[order], surface[order], normal[order], d[order]
        first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])  # slot 0 of each (row, rotor): nearest
        slot0 = np.repeat(first, np.diff(np.r_[first, len(key)]))
        view = slots
        view[key[first], 0, 0:3] = surface[first]
        view[key[first], 0, 3:6] = normal[first]
        view[key[first], 0, 6] = 1.0
        weight = surface_weight(np.einsum("ij,ij->i", normal, normal[slot0]),
                                np.einsum("ij,ij->i", surface - surface[slot0], normal[slot0]))
        candidates = np.flatnonzero(weight > 0.0)  # in (key, distance) order: the first of a key is its nearest
        if len(candidates):
            ck = key[candidates]
            second = candidates[np.r_[True, ck[1:] != ck[:-1]]]
            view[key[second], 1, 0:3] = surface[second]
            view[key[second], 1, 3:6] = normal[second]
            view[key[second], 1, 6] = weight[second]
        result.distance.reshape(-1)[key[first]] = d[first]
        result.normal.reshape(-1, 3)[key[first]] = normal[first]
        out[:] = slots.reshape(n, -1)
        return result

    def rotor_surfaces_at(self, p_world: np.ndarray, R_body_to_world: np.ndarray) -> np.ndarray:
        """:meth:`rotor_surfaces` for poses given by rotation matrices ``(n, 3, 3)``: the local surfaces
        ``(n, 4 * SURFACE_SLOTS * SURFACE_SIZE)``."""
        p_world = np.asarray(p_world, dtype=float)
        out = np.tile(NO_SURFACE, (len(p_world), ROTOR_COUNT * SURFACE_SLOTS))
        finite = np.all(np.isfinite(p_world), axis=1) & np.all(np.isfinite(R_body_to_world), axis=(1, 2))
        if finite.any():  # a pose that is not finite feels nothing
            q = Rotation.from_matrix(R_body_to_world[finite]).as_quat()[:, [3, 0, 1, 2]]  # w, x, y, z
            found = np.empty((int(finite.sum()), out.shape[1]))
            self.rotor_surfaces(p_world[finite], q, found)
            out[finite] = found
        return out

    # ------------------------------------------------------------------ points
    def nearest(self, points_world: np.ndarray, reach: float | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The nearest surface point ``(k, 3)``, outward normal ``(k, 3)`` and distance ``(k,)`` of each of
        ``points_world (k, 3)`` within ``reach`` (default :attr:`reach`); distance ``inf`` and normal zeros
        where there is none."""
        points = np.atleast_2d(np.asarray(points_world, dtype=float))
        k = points.shape[0]
        limit = (self.reach if reach is None else float(reach)) - PROBE_RADIUS
        surface, normal, d = np.zeros((k, 3)), np.zeros((k, 3)), np.full(k, np.inf)
        for i, position in enumerate(points.tolist()):
            for body in self.bodies:
                for pt in pybullet.getClosestPoints(-1, body, limit, collisionShapeA=self._point,
                                                    collisionShapePositionA=position, physicsClientId=self.client):
                    distance = pt[8] + PROBE_RADIUS
                    if distance < d[i]:
                        direction = np.asarray(pt[7]) / np.linalg.norm(pt[7])
                        surface[i], normal[i], d[i] = points[i] - distance * direction, direction, distance
        return surface, normal, d

    # ------------------------------------------------------------------ contacts
    def contacts(self, p_world: np.ndarray, q_body_to_world: np.ndarray) -> list[tuple[float, np.ndarray]]:
        """The vehicle's contacts with the bodies at one pose: ``(depth (m, > 0), normal out of the body)``
        for every penetrating pair, deepest first (empty when clear)."""
        xyzw = [float(q_body_to_world[1]), float(q_body_to_world[2]), float(q_body_to_world[3]),
                float(q_body_to_world[0])]
        found = []
        for body in self.bodies:
            for pt in pybullet.getClosestPoints(-1, body, 0.0, collisionShapeA=self._vehicle,
                                                collisionShapePositionA=[float(v) for v in p_world],
                                                collisionShapeOrientationA=xyzw, physicsClientId=self.client):
                if pt[8] < 0.0:
                    found.append((-float(pt[8]), np.asarray(pt[7], dtype=float)))
        return sorted(found, key=lambda c: -c[0])

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        if self._bullet is not None:
            try:
                self._bullet.disconnect()
            except (AttributeError, getattr(pybullet, "error", RuntimeError)):  # at exit the module may be gone
                pass
            self._bullet = None

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - at interpreter exit even the builtins close() names may be gone
            pass

    def __getstate__(self):
        raise TypeError("a SurfaceQuery holds a PyBullet client and is not picklable; make one from the scene")
