"""Flights among bodies: the suction from PyBullet's geometry against the closed form and the analytic distance,
the per-step surfaces against a query at every physics step, contacts, and the scene keyword."""

import gymnasium as gym
import numpy as np
import pybullet
import pytest

import wall_env
from controllers import PID
from wall_env import Scene
from wall_env.aero import rotor_suction_function
from wall_env.bodies import Mesh
from wall_env.dynamics import StateIndex
from wall_env.rotations import quat_to_rotation_rows

PLANE_MESH = Scene((), 0.0, None, (Mesh("tests/data/scenes/plane_x0.obj"),))
STIFF = {"preset": "paper", "kp": (20.0, 20.0, 20.0), "kv": (8.0, 8.0, 8.0)}  # clear of the pier, no tuning needed


def test_a_plane_built_as_a_mesh_pulls_each_rotor_as_the_closed_form_plane_over_a_whole_flight():
    closed = gym.make("WallInspector/WallSweep-v0", terminate_on_collision=False)
    mesh = gym.make("WallInspector/WallSweep-v0", terminate_on_collision=False, scene=PLANE_MESH)
    policy = PID.from_env(mesh)
    _, _ = closed.reset(seed=3)
    observation, _ = mesh.reset(seed=3)
    worst, strongest, steps, done = 0.0, 0.0, 0, False
    while not done:
        action, _ = policy.predict(observation)
        # the closed-form env steps from the mesh env's state: the same start, the same command noise
        closed.unwrapped._batch.simulator.x[:] = mesh.unwrapped._batch.simulator.x
        _, _, _, _, info_closed = closed.step(action)
        observation, _, terminated, truncated, info = mesh.step(action)
        worst = max(worst, float(np.abs(info["rotor_suction_world"] - info_closed["rotor_suction_world"]).max()))
        strongest = max(strongest, float(np.abs(info["rotor_suction_world"]).max()))
        steps, done = steps + 1, terminated or truncated
    assert steps == 1700 and strongest > 0.2  # the whole sweep, with the near rotors well inside d_thr
    assert worst < 1e-9


def _analytic_pier_suction(p, q, k_s=4.1, d_thr=0.132, radius=0.5):
    rotors = p + (quat_to_rotation_rows(q[None])[0] @ wall_env.VehicleParams().rotor_positions_array.T).T
    across = np.linalg.norm(rotors[:, :2], axis=1)
    normal = np.column_stack([rotors[:, :2] / across[:, None], np.zeros(4)])
    return -normal * (k_s * np.maximum(0.0, d_thr - (across - radius)))[:, None]


def test_around_a_cylinder_each_rotors_suction_is_the_analytic_one():
    env = gym.make("WallInspector/Pier-v0", noise=False, duration=8.0)
    base = env.unwrapped
    model, sim = base.config.truth, base._batch.simulator
    suction = rotor_suction_function(model, base.vehicle.rotor_positions_array, base.scene.structure)
    policy = PID.from_env(env, **STIFF)
    observation, _ = env.reset(seed=0)
    worst_force, strongest, done = 0.0, 0.0, False
    while not done:
        action, _ = policy.predict(observation)
        observation, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        x = sim.x[0]
        R = quat_to_rotation_rows(x[None, StateIndex.q_body_to_world])[0]
        # the effect at this state, reading the local surfaces PyBullet gave for it
        geometry = np.asarray(suction(x[StateIndex.p_world], R, x[StateIndex.v_world], x[StateIndex.omega_body],
                                      x[StateIndex.rotor_thrusts], sim.mass[0, 0], sim.theta[0], sim.scene[0])).T
        analytic = _analytic_pier_suction(x[StateIndex.p_world], x[StateIndex.q_body_to_world])
        worst_force = max(worst_force, float(np.abs(geometry - analytic).max()))
        strongest = max(strongest, float(np.abs(analytic).max()))
    assert info["collisions"] == 0 and strongest > 0.15
    # a micrometre of distance (4e-6 N) and a few milliradians of direction on the strongest pull (PyBullet's GJK)
    assert worst_force < 3e-3 * strongest + 1e-5


def test_surfaces_held_over_a_control_step_fly_as_surfaces_queried_at_every_physics_step():
    settings = {"noise": False, "duration": 6.0, "terminate_on_collision": False, "standoff": 0.2}
    coarse = gym.make("WallInspector/Pier-v0", **settings)
    fine = gym.make("WallInspector/Pier-v0", control_dt=0.001, physics_substeps=1, **settings)  # a query a step
    pilots = PID.from_env(coarse, **STIFF), PID.from_env(fine, **STIFF)
    start = {"perturb_start": False}
    (obs_coarse, _), (obs_fine, _) = coarse.reset(seed=1, options=start), fine.reset(seed=1, options=start)
    worst, strongest = 0.0, 0.0
    for _ in range(600):
        action_coarse, _ = pilots[0].predict(obs_coarse)
        action_fine, _ = pilots[1].predict(obs_fine)
        obs_coarse, _, _, _, info = coarse.step(action_coarse)
        for _ in range(10):  # the same 10 ms command, the surfaces queried every millisecond
            obs_fine, _, _, _, info_fine = fine.step(action_fine)
        worst = max(worst, float(np.abs(info["p_world"] - info_fine["p_world"]).max()))
        strongest = max(strongest, float(np.abs(info["rotor_suction_world"]).max()))
    assert info["collisions"] == 0 and strongest > 0.1
    assert worst < 5e-5  # m over 6 s around the pier (measured 1.3e-5)


def test_flying_into_the_facade_counts_contacts_and_keeps_the_vehicle_outside():
    env = gym.make("WallInspector/Facade-v0", terminate_on_collision=False, noise=False, restitution=0.0,
                   max_tracking_error=5.0)
    env.reset(seed=0, options={"perturb_start": False})
    contacts, closest, surfaces = 0, np.inf, set()
    for k in range(150):  # tip toward the facade (yaw = pi: body x faces it), then level rates: it drifts in
        action = np.array([0.0, 0.0, -0.1 if k < 10 else 0.0, 0.0], dtype=np.float32)
        _, _, terminated, truncated, info = env.step(action)
        assert not (terminated or truncated)
        contacts += info["collision"]
        surfaces.add(info["collision_surface"])
        R = quat_to_rotation_rows(info["q_body_to_world"][None])[0]
        rotors = info["p_world"] + (R @ env.unwrapped.vehicle.rotor_positions_array.T).T
        closest = min(closest, float(rotors[:, 0].min() - env.unwrapped.vehicle.duct_radius))  # duct edge to x = 0
    assert contacts >= 50 and info["collisions"] == contacts and surfaces == {None, "structure"}
    assert -0.002 < closest < 0.002  # pushed out to the facade's face at every contact (the ducts tilt a little)
    assert abs(info["v_world"][0]) < 1e-9  # no restitution: it rests against the face


def test_the_scene_keyword_takes_a_file_and_names_a_clash(tmp_path):
    (tmp_path / "plane.obj").write_text(open("tests/data/scenes/plane_x0.obj").read())
    (tmp_path / "scene.yaml").write_text("bodies:\n  - {type: mesh, file: plane.obj}\n")
    env = gym.make("WallInspector/WallHover-v0", scene=str(tmp_path / "scene.yaml"))
    assert env.unwrapped.scene.walls == () and len(env.unwrapped.scene.bodies) == 1
    with pytest.raises(ValueError, match="scene has ground_z=0.0, ceiling_z=None but the env's ground_z=0.0, "
                                         "ceiling_z=3.0"):
        gym.make("WallInspector/WallHover-v0", scene=str(tmp_path / "scene.yaml"), ceiling_z=3.0)
    with pytest.raises(ValueError, match="randomize\\['standoff'\\]: task 'Pier' cannot randomise it"):
        gym.make("WallInspector/Pier-v0", randomize={"standoff": (0.18, 0.25)})
    client = env.unwrapped._batch.surfaces.client
    env.close()  # the surface queries' PyBullet client goes with the env
    assert not pybullet.getConnectionInfo(physicsClientId=client)["isConnected"]
