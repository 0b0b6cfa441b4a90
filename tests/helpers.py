"""Shared helpers for the tests: evaluate one effect numerically at a chosen flight state."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from wall_env.aero import AeroModel
from wall_env.effects import Effect
from wall_env.scene import Scene
from wall_env.vehicle import VehicleParams

FACE_WALL = Rotation.from_euler("z", np.pi).as_matrix()  # body x toward a wall whose normal is +x


def wrench(
    effect: Effect,
    scene: Scene,
    p_world,
    R_body_to_world=None,
    v_world=(0.0, 0.0, 0.0),
    rotor_thrusts=None,
    vehicle: VehicleParams | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Force (world) and moment (body) of one effect, through its CasADi function."""
    vehicle = vehicle or VehicleParams()
    model = AeroModel([effect])
    function = model.function(vehicle.rotor_positions_array, scene)
    thrusts = np.full(4, vehicle.hover_thrust / 4) if rotor_thrusts is None else np.asarray(rotor_thrusts, float)
    force, moment, _ = function(
        np.asarray(p_world, float), np.eye(3) if R_body_to_world is None else np.asarray(R_body_to_world, float),
        np.asarray(v_world, float), np.zeros(3),
        thrusts, vehicle.mass, model.theta(), scene.to_vector(),
    )
    return np.asarray(force).ravel(), np.asarray(moment).ravel()
