"""The PyBullet side of the simulator: scene bodies, pictures and a contact query.

PyBullet holds the walls, the ground, an optional ceiling, the scene's bodies (boxes,
cylinders, meshes, URDF models: :func:`wall_env.surfaces.add_bodies`, as the envs' distance
queries load them) and the vehicle's collision geometry (four ducts as cylinders around
the rotor centres plus the central body, the shapes of
:func:`wall_env.contact.collision_shapes`). The envs place the vehicle at the integrated
state for pictures (PyBullet's CPU renderer, no display needed) and the human viewer.
Contact with planes during flight is computed in closed form by :mod:`wall_env.contact`
(the same code for one vehicle and for a batch), contact with bodies by the envs' own
PyBullet query (:mod:`wall_env.surfaces`); :meth:`BulletWorld.contacts` remains as an
independent check of that geometry.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from wall_env.contact import collision_shapes
from wall_env.pybullet_client import connect, pybullet
from wall_env.scene import Scene
from wall_env.vehicle import VehicleParams

__all__ = ["BulletWorld", "Contact"]

_WALL_HALF_WIDTH = 4.0  # m, visual extent of a wall along its surface
_WALL_HALF_HEIGHT = 2.0  # m
_WALL_THICKNESS = 0.02  # m
_WALL_COLOUR = (0.75, 0.8, 0.9, 0.55)
_GROUND_COLOUR = (0.45, 0.5, 0.45, 1.0)
_DUCT_COLOUR = (0.15, 0.15, 0.18, 1.0)
_BODY_COLOUR = (0.9, 0.45, 0.1, 1.0)
_REFERENCE_COLOUR = (0.1, 0.6, 0.1, 1.0)


@dataclass(frozen=True)
class Contact:
    """A contact between the vehicle and a scene body."""

    surface: str  # "wall", "ground" or "ceiling"
    normal_world: np.ndarray  # unit, from the surface toward the vehicle
    penetration: float  # m, >= 0


def _plane_orientation(normal: np.ndarray) -> np.ndarray:
    """Quaternion [x, y, z, w] of a frame whose z is ``normal`` and whose y is as close to
    world up as possible (world y for horizontal planes), so a wall's box stands upright."""
    z = normal / np.linalg.norm(normal)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    y = up - np.dot(up, z) * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return Rotation.from_matrix(np.column_stack([x, y, z])).as_quat()


class BulletWorld:
    """One PyBullet client holding one scene and one vehicle."""

    def __init__(self, vehicle: VehicleParams, scene: Scene, gui: bool = False):
        self._client: Any = None
        if gui and not os.environ.get("DISPLAY"):
            raise ValueError("render_mode='human' needs a display (DISPLAY is not set); use render_mode='rgb_array'")
        self._client = connect(gui)
        self.client_id = self._client._client
        self.vehicle = vehicle
        self.scene = scene
        self._surface_of_body: dict[int, str] = {}
        self._bodies: list[int] = []
        self._build_scene(scene)
        self.vehicle_id = self._build_vehicle(vehicle)
        self._markers: list[int] = []

    # ------------------------------------------------------------------ building
    def _plane(self, point: np.ndarray, normal: np.ndarray, half_extents, colour, surface: str) -> int:
        bc = self._client
        orientation = _plane_orientation(normal)
        collision = bc.createCollisionShape(pybullet.GEOM_PLANE, planeNormal=[0, 0, 1])
        visual = bc.createVisualShape(
            pybullet.GEOM_BOX,
            halfExtents=[half_extents[0], half_extents[1], _WALL_THICKNESS / 2],
            visualFramePosition=[0, half_extents[1] if surface == "wall" else 0.0, -_WALL_THICKNESS / 2],
            rgbaColor=colour,
        )
        body = bc.createMultiBody(0, collision, visual, basePosition=list(point), baseOrientation=list(orientation))
        self._surface_of_body[body] = surface
        return body

    def _build_scene(self, scene: Scene) -> None:
        for wall in scene.walls:
            base = np.asarray(wall.point).copy()
            if scene.ground_z is not None and abs(wall.normal[2]) < 1e-9:  # stand a vertical wall on the ground
                base[2] = scene.ground_z
            self._plane(base, np.asarray(wall.normal), (_WALL_HALF_WIDTH, _WALL_HALF_HEIGHT),
                        _WALL_COLOUR, "wall")
        if scene.ground_z is not None:
            self._plane(np.array([0.0, 0.0, scene.ground_z]), np.array([0.0, 0.0, 1.0]), (6.0, 6.0),
                        _GROUND_COLOUR, "ground")
        if scene.ceiling_z is not None:
            self._plane(np.array([0.0, 0.0, scene.ceiling_z]), np.array([0.0, 0.0, -1.0]), (6.0, 6.0),
                        _WALL_COLOUR, "ceiling")
        from wall_env.surfaces import add_bodies

        self._bodies = add_bodies(self.client_id, scene.bodies, visual=True)
        for body in self._bodies:
            self._surface_of_body[body] = "structure"

    def _build_vehicle(self, vehicle: VehicleParams) -> int:
        bc = self._client
        geometry = collision_shapes(vehicle)  # the shapes the closed-form contact uses
        rotors = geometry.duct_centres
        n = len(rotors)
        shapes = [pybullet.GEOM_CYLINDER] * n + [pybullet.GEOM_BOX]
        radii = [geometry.duct_radius] * n + [0.0]
        lengths = [geometry.duct_height] * n + [0.0]
        half_box = [float(h) for h in geometry.box_half_extents]
        positions = [list(r) for r in rotors] + [[0.0, 0.0, 0.0]]
        collision = bc.createCollisionShapeArray(
            shapeTypes=shapes, radii=radii, lengths=lengths, halfExtents=[[0, 0, 0]] * n + [half_box],
            collisionFramePositions=positions,
        )
        visual = bc.createVisualShapeArray(
            shapeTypes=shapes, radii=radii, lengths=lengths, halfExtents=[[0, 0, 0]] * n + [half_box],
            visualFramePositions=positions, rgbaColors=[_DUCT_COLOUR] * n + [_BODY_COLOUR],
        )
        # A non-zero mass keeps Bullet from skipping vehicle-scene pairs; the body is never simulated.
        return bc.createMultiBody(vehicle.mass, collision, visual, basePosition=[0, 0, 1])

    # ------------------------------------------------------------------ queries
    def place_vehicle(self, p_world: np.ndarray, q_wxyz: np.ndarray) -> None:
        # direct module calls: the client wrapper's attribute lookup costs more than the call
        pybullet.resetBasePositionAndOrientation(
            self.vehicle_id, p_world.tolist(), [q_wxyz[1], q_wxyz[2], q_wxyz[3], q_wxyz[0]],
            physicsClientId=self.client_id,
        )

    def contacts(self, p_world: np.ndarray, q_wxyz: np.ndarray) -> list[Contact]:
        """Place the vehicle and return its contacts with the scene (empty when clear)."""
        self.place_vehicle(p_world, q_wxyz)
        pybullet.performCollisionDetection(physicsClientId=self.client_id)
        found = []
        for c in pybullet.getContactPoints(bodyA=self.vehicle_id, physicsClientId=self.client_id):
            if c[8] <= 0.0:  # contactDistance: negative means penetration
                found.append(Contact(self._surface_of_body.get(c[2], "wall"), np.asarray(c[7]), -float(c[8])))
        return found

    # ------------------------------------------------------------------ pictures
    def show_reference(self, points_world: np.ndarray) -> None:
        """Mark reference points with small green spheres (created once, moved afterwards)."""
        bc = self._client
        if not self._markers:
            shape = bc.createVisualShape(pybullet.GEOM_SPHERE, radius=0.012, rgbaColor=_REFERENCE_COLOUR)
            self._markers = [bc.createMultiBody(0, -1, shape, basePosition=[0, 0, -10]) for _ in points_world]
        for marker, point in zip(self._markers, points_world):
            bc.resetBasePositionAndOrientation(marker, list(point), [0, 0, 0, 1])

    def camera_eye(self, target: np.ndarray, distance: float = 1.0) -> np.ndarray:
        """A viewpoint in free space: beside and in front of a single wall, or behind the
        vehicle looking along a corridor (walls whose normals cancel); ``distance`` scales how far."""
        up = np.array([0.0, 0.0, 1.0])
        normals = [np.asarray(w.normal) for w in self.scene.walls]
        if not normals and self._bodies:  # in front of the nearest body surface, beside the vehicle, farther back
            normal = self._nearest_body_normal(target)
            if normal is not None and abs(normal[2]) < 0.9:
                n = (normal - normal[2] * up) / np.linalg.norm(normal - normal[2] * up)
                along = np.cross(up, n)
                return target + distance * (1.4 * n + 1.5 * along + 0.6 * up)
        if not normals:
            return target + distance * np.array([-1.2, -1.2, 0.5])
        total = np.sum(normals, axis=0)
        if np.linalg.norm(total) > 0.5:
            n = total / np.linalg.norm(total)
            along = np.cross(up, n)
            return target + distance * (0.6 * n + 1.1 * along + 0.25 * up)
        along = np.cross(normals[0], up)
        return target + distance * (-1.3 * along / np.linalg.norm(along) + 0.3 * up)

    def _nearest_body_normal(self, point: np.ndarray, reach: float = 5.0) -> np.ndarray | None:
        """The outward normal of the body surface nearest to ``point`` (within ``reach`` m), or None."""
        bc = self._client
        probe = bc.createCollisionShape(pybullet.GEOM_SPHERE, radius=1e-3)
        best: tuple[float, np.ndarray] | None = None
        for body in self._bodies:
            for pt in bc.getClosestPoints(-1, body, reach, collisionShapeA=probe,
                                          collisionShapePositionA=[float(v) for v in point]):
                if best is None or pt[8] < best[0]:
                    best = (pt[8], np.asarray(pt[7], dtype=float))
        return None if best is None else best[1]

    def render(self, target: np.ndarray, width: int = 480, height: int = 360, distance: float = 1.0) -> np.ndarray:
        """An RGB picture ``(height, width, 3)`` looking at ``target`` from :meth:`camera_eye`."""
        bc = self._client
        view = bc.computeViewMatrix(list(self.camera_eye(target, distance)), list(target), [0, 0, 1])
        projection = bc.computeProjectionMatrixFOV(fov=60, aspect=width / height, nearVal=0.05, farVal=30.0)
        _, _, rgba, _, _ = bc.getCameraImage(
            width, height, view, projection, renderer=pybullet.ER_TINY_RENDERER, shadow=0
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()

    # ------------------------------------------------------------------ lifetime
    @property
    def connected(self) -> bool:
        return self._client is not None

    def close(self) -> None:
        if self._client is not None:
            try:
                self._client.disconnect()
            except pybullet.error:
                pass
            self._client = None

    def __del__(self) -> None:
        self.close()
