"""The Gymnasium environments: API contract, physics through the env, collisions, seeding, leaks."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pybullet
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.passive_env_checker import env_render_passive_checker

import wall_env
from wall_env.observation import OBSERVATION_FIELDS, parse_observation

A = 0.1 / np.sqrt(2)
QUIET = {"noise": False}


@pytest.mark.parametrize("env_id", wall_env.ENV_IDS)
def test_check_env_passes(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    # check_env's render check makes the env in every declared mode, "human" included, which
    # needs a display; rgb_array is checked here and in the rendering test below
    check_env(env.unwrapped, skip_render_check=True)
    env_render_passive_checker(env.unwrapped)
    env.close()


def test_all_six_tasks_are_registered_under_the_namespace():
    assert set(wall_env.ENV_IDS) == {
        "WallInspector/WallHover-v0", "WallInspector/WallCircle-v0",
        "WallInspector/WallSweep-v0", "WallInspector/Corridor-v0",
        "WallInspector/Facade-v0", "WallInspector/Pier-v0",
    }
    for env_id in wall_env.ENV_IDS:
        assert env_id in gym.registry


@pytest.mark.parametrize("env_id", wall_env.ENV_IDS)
def test_same_seed_same_actions_same_observations(env_id):
    def rollout(seed):
        env = gym.make(env_id)
        obs, _ = env.reset(seed=seed)
        actions = np.random.default_rng(123).uniform(-0.3, 0.3, (200, 4))
        trace = [obs]
        for a in actions:
            obs, _, terminated, truncated, _ = env.step(a)
            trace.append(obs)
            if terminated or truncated:
                env.reset()
        env.close()
        return np.array(trace)

    first, second, other = rollout(7), rollout(7), rollout(8)
    assert np.array_equal(first, second)
    assert not np.allclose(first, other)


def test_command_noise_has_the_papers_spread_and_can_be_switched_off():
    env = gym.make("WallInspector/WallHover-v0", standoff=2.0, k_s=0.0)
    env.reset(seed=3)
    commands = []
    for _ in range(3000):
        _, _, term, trunc, info = env.step(np.zeros(4))
        commands.append(info["command"])
        if term or trunc:
            env.reset()
    commands = np.array(commands)
    hover = env.unwrapped.vehicle.hover_thrust
    assert commands[:, 0].mean() == pytest.approx(hover, abs=0.02)
    assert commands[:, 0].std() == pytest.approx(0.2, rel=0.06)
    assert commands[:, 1:].std(axis=0) == pytest.approx([0.2] * 3, rel=0.06)
    env.close()

    quiet = gym.make("WallInspector/WallHover-v0", noise=False)
    quiet.reset(seed=3)
    _, _, _, _, info = quiet.step(np.zeros(4))
    assert info["command"] == pytest.approx([hover, 0, 0, 0])
    quiet.close()


def test_hover_in_free_space_without_noise_stays_put():
    env = gym.make("WallInspector/WallHover-v0", standoff=2.0, **QUIET)
    obs, info = env.reset(seed=0, options={"perturb_start": False})
    start = info["p_world"]
    for _ in range(200):
        obs, reward, term, trunc, info = env.step(np.zeros(4))
    assert info["p_world"] == pytest.approx(start, abs=1e-6)
    assert reward == pytest.approx(1.0, abs=1e-6)  # alive bonus, nothing to subtract
    env.close()


@pytest.mark.parametrize("env_id", ["WallInspector/WallHover-v0", "WallInspector/Corridor-v0"])
def test_the_wall_normal_weight_prices_the_error_along_the_nearest_walls_normal(env_id):
    """Two envs alike but for reward_weights["wall_normal"] fly the same flight; their rewards differ by the weight
    times the position error along the outward normal of the wall nearest to a rotor, at every step."""
    weight = 16.0
    plain = gym.make(env_id)
    priced = gym.make(env_id, reward_weights={"wall_normal": weight})
    plain.reset(seed=4)
    priced.reset(seed=4)
    actions = np.random.default_rng(4).uniform(-0.3, 0.3, (60, 4))
    differences, expected = [], []
    for action in actions:
        obs, reward, _, _, info = plain.step(action)
        _, reward_priced, _, _, info_priced = priced.step(action)
        assert info_priced["p_world"] == pytest.approx(info["p_world"], abs=0.0)  # the reward does not fly
        normal = parse_observation(obs)["wall_normal"]  # exact state: the true nearest wall's normal
        assert np.linalg.norm(normal) == pytest.approx(1.0)
        differences.append(reward - reward_priced)
        expected.append(weight * abs(np.dot(info["p_world"] - info["p_ref"], normal)))
    assert np.asarray(differences) == pytest.approx(np.asarray(expected), rel=1e-9, abs=1e-12)
    assert min(expected) > 0.0  # the flight is off the reference along the normal: the term is priced
    plain.close()
    priced.close()


def test_suction_pulls_the_open_loop_vehicle_into_the_wall():
    env = gym.make("WallInspector/WallHover-v0", **QUIET)
    env.reset(seed=0, options={"perturb_start": False})
    u = env.unwrapped
    standoff = u.standoff
    first = None
    for _ in range(200):
        obs, reward, term, trunc, info = env.step(np.zeros(4))
        if first is None:
            first = info
            # near rotors at standoff - A: 2 k_s (d_thr - d) toward the wall
            expected = 2 * 4.1 * (0.132 - (standoff - A))
            assert info["suction_force_world"] == pytest.approx([-expected, 0, 0], rel=0.01)
        if term:
            break
    assert info["collision"] and info["collision_surface"] == "wall"
    assert term and not trunc and info["collisions"] == 1
    assert reward < -5  # collision penalty 10 on top of the tracking terms
    # x(t) = x0 - F t^2 / (2m) for small displacements: about half a second to close 4.9 cm
    assert 0.35 < info["time"] < 0.65
    env.close()


def test_without_termination_collisions_are_counted_and_the_vehicle_stays_outside():
    env = gym.make("WallInspector/WallHover-v0", terminate_on_collision=False, **QUIET)
    env.reset(seed=0, options={"perturb_start": False})
    clearances = []
    for _ in range(150):
        _, _, term, trunc, info = env.step(np.zeros(4))
        clearances.append(info["wall_clearance"])
        assert not term
    assert info["collisions"] >= 2  # it keeps being pulled back against the wall
    assert min(clearances) > -2e-3  # pushed back out of the wall every step
    env.close()


def test_observation_matches_the_documented_layout():
    env = gym.make("WallInspector/WallSweep-v0")
    obs, info = env.reset(seed=4)
    for _ in range(120):
        obs, _, _, _, info = env.step(np.array([0.0, 0.05, -0.05, 0.0]))
    o = parse_observation(obs)
    u = env.unwrapped
    assert o["p_world"] == pytest.approx(info["p_world"], abs=1e-5)
    assert o["p_error"] == pytest.approx(info["p_world"] - info["p_ref"], abs=1e-5)
    assert o["v_error"] == pytest.approx(info["v_world"] - info["v_ref"], abs=1e-5)
    assert o["time"] == pytest.approx(1.2, abs=1e-6)
    preview = u.reference.position(1.2 + 0.05 * np.arange(1, 5)) - u.reference.position(1.2)
    assert o["reference_preview"] == pytest.approx(preview, abs=1e-5)
    assert o["rotor_clearance"].min() - u.vehicle.duct_radius == pytest.approx(info["wall_clearance"], abs=1e-5)
    assert o["wall_normal"] == pytest.approx([1, 0, 0])
    assert o["previous_action"] == pytest.approx([0.0, 0.05, -0.05, 0.0], abs=1e-7)
    R = o["R_body_to_world"]
    assert R @ R.T == pytest.approx(np.eye(3), abs=1e-5)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    assert sum(s.stop - s.start for s in OBSERVATION_FIELDS.values()) == obs.size == 48
    env.close()


def test_corridor_clearance_sees_the_nearest_of_two_walls():
    env = gym.make("WallInspector/Corridor-v0", **QUIET)
    obs, info = env.reset(seed=0, options={"perturb_start": False})
    o = parse_observation(obs)
    # level, yaw 0, centred in a 0.4 m corridor: every rotor is 0.2 - A from its nearer wall
    assert o["rotor_clearance"] == pytest.approx([0.2 - A] * 4, abs=1e-6)
    assert abs(o["wall_normal"][1]) == pytest.approx(1.0)
    env.close()


def test_action_mapping_is_documented_and_public():
    env = gym.make("WallInspector/WallHover-v0")
    mapping = env.unwrapped.action_mapping
    hover = env.unwrapped.vehicle.hover_thrust
    assert mapping.to_physical(np.zeros(4)) == pytest.approx([hover, 0, 0, 0])
    assert mapping.to_physical(np.ones(4)) == pytest.approx([27.0, 3.0, 3.0, 3.0])
    assert mapping.to_physical(-np.ones(4)) == pytest.approx([0.0, -3.0, -3.0, -3.0])
    command = np.array([12.0, 0.5, -1.0, 2.0])
    assert mapping.to_physical(mapping.to_normalised(command)) == pytest.approx(command)
    env.close()


def test_domain_randomisation_changes_the_suction_every_episode():
    env = gym.make("WallInspector/WallHover-v0", randomize={"k_s": (1.0, 8.0), "standoff": (0.14, 0.2), "mass": (0.9, 1.1)},
                   **QUIET)
    seen = []
    for episode in range(5):
        _, info = env.reset(seed=episode, options={"perturb_start": False})
        params = env.unwrapped.episode_parameters
        assert 1.0 <= params["k_s"] <= 8.0 and 0.9 <= params["mass"] <= 1.1
        assert info["p_ref"][0] == pytest.approx(params["standoff"])
        _, _, _, _, info = env.step(np.zeros(4))
        d = params["standoff"] - A
        expected = 2 * params["k_s"] * max(0.0, 0.132 - d)
        assert -info["suction_force_world"][0] == pytest.approx(expected, rel=0.02)
        seen.append(params["k_s"])
    assert np.ptp(seen) > 1.0
    env.close()


def test_a_drawn_start_time_starts_the_episode_that_far_along_the_reference():
    """randomize={"start_time": ...}: the episode starts at the reference's position and velocity of that time,
    the time observation starts there, and the episode ends at the task's duration as from the start."""
    env = gym.make("WallInspector/WallSweep-v0", randomize={"start_time": (6.0, 9.0)}, **QUIET)
    dt = env.unwrapped.config.control_dt
    starts = set()
    for seed in range(3):
        obs, info = env.reset(seed=seed, options={"perturb_start": False})
        t0 = float(obs[OBSERVATION_FIELDS["time"]][0])
        assert 6.0 <= t0 <= 9.0 and t0 == pytest.approx(env.unwrapped.episode_parameters["start_time"], abs=dt / 2)
        step = round(t0 / dt)  # the observation's time is float32
        p_ref, v_ref = (np.ravel(a) for a in env.unwrapped.reference.sample(step * dt)[:2])
        assert info["p_ref"] == pytest.approx(p_ref, abs=1e-9)
        assert obs[OBSERVATION_FIELDS["p_world"]] == pytest.approx(p_ref, abs=1e-6)
        assert obs[OBSERVATION_FIELDS["v_world"]] == pytest.approx(v_ref, abs=1e-6)
        assert obs[OBSERVATION_FIELDS["p_error"]] == pytest.approx(np.zeros(3), abs=1e-6)
        starts.add(t0)
    assert len(starts) == 3
    # without perturbation and noise the vehicle starts on the reference: a short flight to the end
    env = gym.make("WallInspector/WallSweep-v0", randomize={"start_time": (16.9, 16.9)}, **QUIET)
    env.reset(seed=0)
    steps, truncated = 0, False
    while not truncated:
        _, _, terminated, truncated, _ = env.step(np.zeros(4))
        steps += 1
        assert not terminated
    assert steps == round((17.0 - 16.9) / dt)
    env.close()


def test_extra_effects_and_model_files_reach_the_simulator(tmp_path):
    env = gym.make("WallInspector/WallHover-v0", standoff=2.0, effects={"constant_force": {"F": [0.5, 0, 0]}}, **QUIET)
    env.reset(seed=0, options={"perturb_start": False})
    _, _, _, _, info = env.step(np.zeros(4))
    assert info["effect_forces_world"]["constant_force"] == pytest.approx([0.5, 0, 0])
    # m dv/dt = F - D v  ->  v(t) = F / D (1 - exp(-D t / m)) with the vehicle's 0.3 N s/m body drag
    assert info["v_world"][0] == pytest.approx(0.5 / 0.3 * (1 - np.exp(-0.3 * 0.01)), rel=1e-6)
    env.close()

    model = wall_env.FlightModel(wall_env.VehicleParams(mass=1.2),
                                 [wall_env.make_effect("wall_suction", k_s=7.0, d_thr=0.1)])
    path = tmp_path / "model.json"
    model.save(path)
    env = gym.make("WallInspector/WallHover-v0", model=str(path), standoff=0.15, **QUIET)
    env.reset(seed=0, options={"perturb_start": False})
    _, _, _, _, info = env.step(np.zeros(4))
    assert env.unwrapped.vehicle.mass == 1.2
    assert -info["suction_force_world"][0] == pytest.approx(2 * 7.0 * (0.1 - (0.15 - A)), rel=0.02)
    env.close()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"k_s": -1.0}, r"wall_suction\.k_s must be in \[0, 200\] N/m"),
        ({"d_thr": 0.0}, r"wall_suction\.d_thr must be in"),
        ({"standoff": 0.05}, r"standoff must be in \[0\.1157"),
        ({"thrust_noise_std": -0.1}, r"thrust_noise_std must be in \[0, 10\]"),
        ({"randomize": {"wind": (0, 1)}}, r"randomize keys must be among"),
        ({"randomize": {"k_s": (5, 1)}}, r"randomize\['k_s'\] must have low <= high"),
        ({"randomize": {"standoff": (0.01, 0.3)}}, r"randomize\['standoff'\] must be in \[0\.1157"),
        ({"randomize": {"start_time": (0.0, 10.0)}, "duration": 2.0}, r"randomize\['start_time'\] must be in \[0, 1\.99\]"),
        ({"render_mode": "video"}, r"render_mode must be None or one of"),
        ({"physics_substeps": 0}, r"physics_substeps must be an integer in \[1, 100\]"),
        ({"control_dt": 0.5}, r"control_dt must be in \[0\.001, 0\.05\]"),
        ({"effects": {"linear_drag": {}}}, r"linear_drag is the vehicle's drag"),
        ({"effects": {"wall_suction": {"k_s": 2.0}}, "k_s": 3.0}, r"given both as keyword and in effects"),
        ({"vehicle": {"mass": 5.0}}, r"thrust_max must exceed the weight"),
        ({"vehicle": {"wingspan": 1.0}}, r"unknown vehicle parameter"),
        ({"ceiling_z": 0.5}, r"ceiling_z must be in"),
    ],
)
def test_invalid_arguments_name_the_argument_and_its_range(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("WallInspector/WallHover-v0", **kwargs)


def test_bad_actions_are_rejected_not_propagated_as_nan():
    env = gym.make("WallInspector/WallHover-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must be finite"):
        env.step(np.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match=r"action must have shape \(4,\)"):
        env.step(np.zeros(3))
    env.close()


def test_rgb_array_rendering_works_headless_and_shows_the_scene():
    env = gym.make("WallInspector/WallCircle-v0", render_mode="rgb_array", render_size=(160, 120))
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # not a blank image: wall, ground and vehicle differ in colour
    env.close()


def test_many_create_close_cycles_leak_no_pybullet_clients():
    ids = []
    # more than PyBullet's limit of simultaneously connected clients (1024)
    for _ in range(1100):
        env = gym.make("WallInspector/WallHover-v0", render_mode="rgb_array", render_size=(16, 16))
        env.reset(seed=0)
        env.render()  # PyBullet's world is made at the first picture
        ids.append(env.unwrapped._world.client_id)
        env.close()
    assert not any(pybullet.getConnectionInfo(physicsClientId=i)["isConnected"] for i in set(ids))


def test_vehicle_parameters_load_from_json_and_yaml(tmp_path):
    vehicle = wall_env.VehicleParams(mass=0.979, drag=(0.25, 0.25, 0.15))
    for suffix in (".json", ".yaml"):
        path = tmp_path / f"vehicle{suffix}"
        vehicle.save(path)
        assert wall_env.VehicleParams.from_file(path) == vehicle
    defaults = wall_env.VehicleParams()
    assert defaults.rotor_positions_array == pytest.approx(
        np.array([[A, A, 0], [-A, A, 0], [-A, -A, 0], [A, -A, 0]]))
    assert defaults.inertia == (2.64e-3, 2.64e-3, 4.96e-3)
    bad = tmp_path / "bad.yaml"
    bad.write_text("mass: -1\n")
    with pytest.raises(ValueError, match=r"bad\.yaml: mass must be in \(0, 100\]"):
        wall_env.VehicleParams.from_file(bad)
    broken = tmp_path / "broken.json"
    broken.write_text('{"mass": 1.0,')
    with pytest.raises(ValueError, match=r"vehicle file .*broken\.json is not valid JSON"):
        wall_env.VehicleParams.from_file(broken)
