"""The batched env: Gymnasium's vector API, equality with the single env, contact geometry, memory."""

from __future__ import annotations

import tracemalloc

import casadi as ca
import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from scipy.spatial.transform import Rotation

import wall_env
from wall_env.bullet_world import BulletWorld
from wall_env.contact import collision_shapes, contact_response
from wall_env.scene import Scene, Wall
from wall_env.vector_env import WallInspectorVectorEnv
from wall_env.vehicle import VehicleParams

A = 0.1 / np.sqrt(2)


def make_vec(env_id="WallInspector/WallHover-v0", n=4, **kwargs):
    return gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)


@pytest.mark.parametrize("env_id", wall_env.ENV_IDS)
def test_make_vec_gives_the_native_batched_env_for_every_task(env_id):
    envs = make_vec(env_id, n=3)
    assert isinstance(envs.unwrapped, WallInspectorVectorEnv)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP  # Gymnasium 1.x's default
    assert envs.observation_space.shape == (3, 48) and envs.action_space.shape == (3, 4)
    assert envs.unwrapped.max_episode_steps == gym.spec(env_id).max_episode_steps
    obs, info = envs.reset(seed=0)
    assert obs.shape == (3, 48) and obs.dtype == np.float32 and envs.observation_space.contains(obs)
    assert info["p_world"].shape == (3, 3) and info["_p_world"].all()
    obs, reward, terminated, truncated, info = envs.step(np.zeros((3, 4), dtype=np.float32))
    assert reward.shape == (3,) and np.all(np.isfinite(reward))
    assert terminated.dtype == bool and truncated.dtype == bool
    assert info["effect_forces_world"]["wall_suction"].shape == (3, 3)
    envs.close()


def _fly_both(env_id, seeds, steps, action_fn, **kwargs):
    """The batched env and one single env per seed, same actions; returns both records."""
    n = len(seeds)
    envs = make_vec(env_id, n=n, **kwargs)
    singles = [gym.make(env_id, **kwargs) for _ in seeds]
    obs_b, info_b = envs.reset(seed=seeds[0])
    single_obs = [env.reset(seed=s)[0] for env, s in zip(singles, seeds)]
    np.testing.assert_array_equal(obs_b, single_obs)  # the same starts
    rng = np.random.default_rng(99)
    record = {"batched": [], "single": []}
    ended = np.zeros(n, dtype=bool)
    for t in range(steps):
        actions = action_fn(rng, t, n)
        obs_b, r_b, term_b, trunc_b, info_b = envs.step(actions)
        rows = []
        for k, env in enumerate(singles):
            if ended[k]:  # next-step autoreset: this step of the batch restarts env k
                o, info = env.reset()
                rows.append((o, 0.0, False, False, info))
            else:
                rows.append(env.step(actions[k]))
        ended = term_b | trunc_b
        assert np.array_equal(ended, [r[2] or r[3] for r in rows])
        record["batched"].append((info_b["p_world"].copy(), info_b["v_world"].copy(), info_b["q_body_to_world"].copy(),
                                  obs_b.copy(), r_b.copy(), info_b["collision"].copy(), info_b["collisions"].copy()))
        record["single"].append((np.array([r[4]["p_world"] for r in rows]), np.array([r[4]["v_world"] for r in rows]),
                                 np.array([r[4]["q_body_to_world"] for r in rows]), np.array([r[0] for r in rows]),
                                 np.array([r[1] for r in rows]), np.array([r[4]["collision"] for r in rows]),
                                 np.array([r[4]["collisions"] for r in rows])))
    envs.close()
    for env in singles:
        env.close()
    return record


@pytest.mark.parametrize("env_id, kwargs", [
    ("WallInspector/WallHover-v0", {"terminate_on_collision": False, "max_tracking_error": 5.0,
                                    "randomize": {"k_s": (2.0, 8.0), "mass": (0.9, 1.1), "standoff": (0.13, 0.2)}}),
    ("WallInspector/Corridor-v0", {"terminate_on_collision": True, "randomize": {"standoff": (0.17, 0.25)}}),
    ("WallInspector/Facade-v0", {"terminate_on_collision": False, "max_tracking_error": 5.0,
                                 "randomize": {"k_s": (2.0, 8.0), "d_thr": (0.1, 0.2), "standoff": (0.14, 0.2)}}),
    ("WallInspector/Pier-v0", {"terminate_on_collision": True, "randomize": {"mass": (0.9, 1.1)}}),
])
def test_batched_and_single_envs_fly_the_same_trajectories_and_contacts(env_id, kwargs):
    def toward_wall(rng, t, n):  # roll/pitch about at random with a bias that drives the vehicles into walls
        a = rng.uniform(-0.6, 0.6, (n, 4))
        a[:, 2] += 0.25
        a[:, 1] += 0.25
        return a.astype(np.float32)

    record = _fly_both(env_id, seeds=[11, 12, 13, 14, 15], steps=250, action_fn=toward_wall, **kwargs)
    contact_steps = {"batched": 0, "single": 0}
    for b, s in zip(record["batched"], record["single"]):
        np.testing.assert_allclose(b[0], s[0], rtol=0, atol=1e-9)  # position
        np.testing.assert_allclose(b[1], s[1], rtol=0, atol=1e-9)  # velocity
        np.testing.assert_allclose(b[2], s[2], rtol=0, atol=1e-9)  # attitude
        np.testing.assert_allclose(b[3], s[3], rtol=0, atol=1e-6)  # observations (float32)
        np.testing.assert_allclose(b[4], s[4], rtol=0, atol=1e-9)  # rewards
        assert np.array_equal(b[5], s[5]) and np.array_equal(b[6], s[6])  # contact steps and counts
        contact_steps["batched"] += int(b[5].sum())
        contact_steps["single"] += int(s[5].sum())
    assert contact_steps["batched"] == contact_steps["single"] >= 3  # the flights did hit walls


def test_next_step_autoreset_starts_a_new_episode_with_zero_reward():
    envs = make_vec("WallInspector/WallHover-v0", n=2, duration=0.05, noise=False, standoff=0.4)  # 5 steps
    envs.reset(seed=0)
    for _ in range(4):
        _, _, terminated, truncated, _ = envs.step(np.zeros((2, 4)))
        assert not (terminated | truncated).any()
    obs, _, terminated, truncated, info = envs.step(np.zeros((2, 4)))
    assert truncated.all() and not terminated.any() and info["time"] == pytest.approx([0.05, 0.05])
    obs, reward, terminated, truncated, info = envs.step(np.ones((2, 4)))  # action ignored: a reset
    assert np.array_equal(reward, [0.0, 0.0]) and not (terminated | truncated).any()
    assert info["time"] == pytest.approx([0.0, 0.0]) and obs[:, 47] == pytest.approx([0.0, 0.0])
    assert np.all(obs[:, 43:47] == 0.0)  # previous action of a fresh episode
    envs.close()


def test_max_episode_steps_truncates_the_batch():
    envs = make_vec("WallInspector/WallHover-v0", n=2, max_episode_steps=3, noise=False, standoff=0.4)
    envs.reset(seed=0)
    dones = [envs.step(np.zeros((2, 4)))[3].all() for _ in range(3)]
    assert dones == [False, False, True]
    envs.close()


def test_each_env_has_its_own_seeded_stream_and_reseeding_repeats_it():
    envs = make_vec("WallInspector/WallHover-v0", n=3)
    first, _ = envs.reset(seed=5)
    assert not np.allclose(first[0], first[1])  # per-env seeds 5, 6, 7
    again, _ = envs.reset(seed=5)
    assert np.array_equal(first, again)
    listed, _ = envs.reset(seed=[7, 6, 5])
    assert np.array_equal(listed[0], first[2]) and np.array_equal(listed[2], first[0])
    with pytest.raises(ValueError, match="seed must be"):
        envs.reset(seed=[1, 2])
    envs.close()


def test_domain_randomisation_is_drawn_per_env_at_each_of_its_resets():
    ranges = {"k_s": (2.0, 8.0), "d_thr": (0.1, 0.16), "mass": (0.9, 1.1)}
    envs = make_vec("WallInspector/WallHover-v0", n=16, noise=False, randomize=ranges)
    _, info = envs.reset(seed=1, options={"perturb_start": False})
    params = envs.unwrapped.episode_parameters
    for key, (low, high) in ranges.items():
        assert np.all((params[key] >= low) & (params[key] <= high)) and np.ptp(params[key]) > 0
    _, _, _, _, info = envs.step(np.zeros((16, 4)))
    # hover at 0.16 m facing the wall: the two near rotors 0.16 - A from it pull with k_s (d_thr - d) each
    d = info["p_world"][:, 0] - A
    expected = 2 * params["k_s"] * np.maximum(params["d_thr"] - d, 0.0)
    np.testing.assert_allclose(-info["suction_force_world"][:, 0], expected, rtol=0.03, atol=1e-3)
    envs.reset(options={"reset_mask": np.arange(16) < 8})
    again = envs.unwrapped.episode_parameters
    assert np.all(again["k_s"][:8] != params["k_s"][:8]) and np.array_equal(again["k_s"][8:], params["k_s"][8:])
    envs.close()


def test_vector_env_lifecycle_and_actions_give_clear_errors():
    envs = WallInspectorVectorEnv(2, "WallHover")
    with pytest.raises(RuntimeError, match="before reset"):
        envs.step(np.zeros((2, 4)))
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 4\)"):
        envs.step(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="real numbers"):
        envs.step(np.zeros((2, 4), dtype=complex))
    with pytest.raises(ValueError, match="finite"):
        envs.step(np.full((2, 4), np.nan))
    envs.close()
    with pytest.raises(RuntimeError, match="closed"):
        envs.step(np.zeros((2, 4)))
    with pytest.raises(ValueError, match="num_envs must be"):
        WallInspectorVectorEnv(0, "WallHover")
    with pytest.raises(ValueError, match="does not render"):
        WallInspectorVectorEnv(2, "WallHover", render_mode="rgb_array")


def test_memory_stays_flat_over_many_resets():
    """No memory grows with the number of resets. CasADi's Python wrappers keep a pool of small objects whose
    size, once tracing starts, settles within the first few hundred calls and then wanders by tens of kB
    (60-77 kB after 300, 600 and 900 resets of 256 envs): the growth is measured from a snapshot taken after
    that, over 600 resets, where a leak of 107 bytes per reset would show as 64 kB."""
    envs = make_vec("WallInspector/WallSweep-v0", n=256)
    envs.reset(seed=0)
    for _ in range(20):
        envs.reset()
        envs.step(np.zeros((256, 4)))
    tracemalloc.start()
    for _ in range(300):
        envs.reset()
        envs.step(np.zeros((256, 4)))
    before = tracemalloc.take_snapshot()
    for _ in range(600):
        envs.reset()
        envs.step(np.zeros((256, 4)))
    after = tracemalloc.take_snapshot()
    tracemalloc.stop()
    growth = sum(stat.size_diff for stat in after.compare_to(before, "filename"))
    assert growth < 64_000, f"{growth} bytes more after 600 resets of 256 envs"
    envs.close()


# ---------------------------------------------------------------------- contact geometry against PyBullet
def _penetrations(vehicle, scene, p, R):
    symbols, vector = scene.symbols()
    ps, Rs = ca.SX.sym("p", 3), ca.SX.sym("R", 3, 3)
    _, _, depth = contact_response(ps, Rs, ca.SX.zeros(3), symbols, collision_shapes(vehicle), 0.3)
    f = ca.Function("depth", [ps, Rs, vector], [depth])
    return np.asarray(f(p, R, scene.to_vector())).ravel()


def test_closed_form_contact_matches_pybullets_query_on_the_same_shapes():
    vehicle = VehicleParams()
    scene = Scene((Wall((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),), ground_z=0.0, ceiling_z=2.0)
    world = BulletWorld(vehicle, scene)
    rng = np.random.default_rng(4)
    compared = 0
    try:
        for _ in range(400):
            p = np.array([rng.uniform(0.05, 0.2), rng.uniform(-1, 1), rng.choice([rng.uniform(0.0, 0.1), 1.0,
                                                                                    rng.uniform(1.9, 2.0)])])
            attitude = Rotation.from_euler("xyz", rng.uniform(-0.5, 0.5, 3) + [0, 0, rng.uniform(-np.pi, np.pi)])
            depths = _penetrations(vehicle, scene, p, attitude.as_matrix())  # wall, ground, ceiling
            contacts = world.contacts(p, np.roll(attitude.as_quat(), 1))
            bullet = {"wall": 0.0, "ground": 0.0, "ceiling": 0.0}
            for c in contacts:
                bullet[c.surface] = max(bullet[c.surface], c.penetration)
            for depth, surface in zip(depths, ("wall", "ground", "ceiling")):
                if depth > 2e-3 or bullet[surface] > 2e-3:  # clear contacts: both see them, same depth
                    assert depth == pytest.approx(bullet[surface], abs=1.5e-3), (p, surface)
                    compared += 1
                if depth == 0.0:
                    assert bullet[surface] < 1.5e-3
    finally:
        world.close()
    assert compared > 50


def test_reset_rotations_in_closed_form_equal_scipys():
    from wall_env.rotations import euler_xyz_to_quat_rows, quat_to_rotation_rows

    angles = np.random.default_rng(0).uniform(-3, 3, (200, 3))
    q = euler_xyz_to_quat_rows(angles)
    reference = Rotation.from_euler("xyz", angles)
    np.testing.assert_allclose(quat_to_rotation_rows(q), reference.as_matrix(), atol=1e-14)
    np.testing.assert_allclose(np.abs(np.sum(q * np.roll(reference.as_quat(), 1, axis=1), axis=1)), 1.0, atol=1e-14)


def test_streams_draw_uniform_and_normal_numbers_independent_of_the_batch():
    from wall_env.streams import RandomStreams

    big, one = RandomStreams(1000), RandomStreams(1)
    big.seed(np.arange(1000), list(range(1000)))
    one.seed([0], [7])
    u = big.uniform(slice(None), 4)
    assert u.min() >= 0.0 and u.max() < 1.0 and abs(u.mean() - 0.5) < 0.01 and abs(u.var() - 1 / 12) < 0.003
    z = big.normal(slice(None), 4)
    assert abs(z.mean()) < 0.05 and abs(z.std() - 1.0) < 0.03
    np.testing.assert_array_equal(one.uniform([0], 4), u[7:8])  # row 7 of the batch = a stream of one seeded 7
    np.testing.assert_array_equal(one.normal([0], 4), z[7:8])


def test_bench_env_batched_writes_its_table_json_and_plot(tmp_path):
    import json

    from wall_inspector.cli import main

    files = {kind: tmp_path / f"bench.{kind}" for kind in ("md", "json", "png")}
    code = main(["bench-env", "--batched", "--steps", "200", "--sizes", "1", "8", "--batched-steps", "200",
                 "--two-core-n", "0", "--memory-resets", "3", "--geometry-n", "4", "--markdown", str(files["md"]),
                 "--json", str(files["json"]), "--plot", str(files["png"])])
    assert code == 0
    payload = json.loads(files["json"].read_text())
    assert [r["env_id"] for r in payload["geometry"]] == ["WallInspector/WallSweep-v0", "WallInspector/Facade-v0",
                                                          "WallInspector/Pier-v0"]
    assert all(r["n"] == 4 and r["steps_per_s"] > 0 for r in payload["geometry"])
    assert "| `WallInspector/Facade-v0` |" in files["md"].read_text()
    assert [r["n"] for r in payload["batched"]] == [1, 8]
    assert all(r["steps_per_s"] > 0 and r["env_steps"] >= 200 for r in payload["batched"])
    assert payload["batched"][1]["ratio_to_single"] == pytest.approx(
        payload["batched"][1]["steps_per_s"] / payload["single_steps_per_s"])
    assert payload["memory"]["resets"] == 3 and "load_average_start" in payload["machine"]
    assert "| 8 |" in files["md"].read_text() and files["png"].stat().st_size > 1000


def test_a_stream_of_one_draws_its_step_noise_from_a_block_that_equals_drawing_each_step():
    from wall_env.streams import RandomStreams

    one, reference = RandomStreams(1), RandomStreams(1)
    drawn, expected = [], []
    for seed in (3, 4):  # reseeding must drop the block drawn for the old key
        one.seed([0], [seed])
        reference.seed([0], [seed])
        for step in range(150):  # past the block's 64 steps, with resets drawing odd and even counts
            if step % 37 == 0:
                extra = 9 + step % 2
                one.uniform(slice(None), extra)
                reference.uniform(slice(None), extra)
            drawn.append(one.step_normals(4)[0].copy())
            expected.append(reference.normal(slice(None), 4)[0])
    assert np.array_equal(np.array(drawn), np.array(expected))
    assert one.counters[0] == reference.counters[0]
    batch = RandomStreams(3)
    batch.seed([0, 1, 2], [3, 4, 5])
    batch.step_normals(4, active=np.array([True, False, True]))
    assert batch.counters.tolist() == [4, 0, 4]


def test_a_non_finite_action_row_is_named_in_a_short_message():
    envs = gym.make_vec("WallInspector/WallSweep-v0", num_envs=1024, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    actions = np.zeros((1024, 4))
    actions[517, 2] = np.nan
    with pytest.raises(ValueError) as error:
        envs.step(actions)
    assert "1 of 1024 rows are not (row 517: [0.0, 0.0, nan, 0.0])" in str(error.value) and len(str(error.value)) < 200


def _wall_clearance(x, vehicle):
    """Clearance (m) of states ``x`` from the wall x = 0 (normal +x) by the contact module's equation: the
    deepest point of each duct, ``n . c - (h / 2) |n . a| - r sqrt(1 - (n . a)^2)``, and of the central box."""
    from wall_env.state import StateIndex

    shapes = collision_shapes(vehicle)
    R = Rotation.from_quat(np.roll(x[:, StateIndex.q_body_to_world], -1, axis=1)).as_matrix()  # (k, 3, 3)
    p = x[:, StateIndex.p_world]
    along = R[:, 0, 2]  # n . body z
    across = np.sqrt(np.clip(1.0 - along**2, 0.0, None))
    ducts = [p[:, 0] + (R @ centre)[:, 0] - shapes.duct_height / 2 * np.abs(along) - shapes.duct_radius * across
             for centre in shapes.duct_centres]
    box = p[:, 0] - sum(e * np.abs(R[:, 0, i]) for i, e in enumerate(shapes.box_half_extents))
    return np.min(np.stack([*ducts, box], axis=1), axis=1)


def test_no_perturbed_start_touches_the_wall_and_clear_starts_stay_as_drawn(monkeypatch):
    """WallHover's 5 cm position spread about a start 4.7 cm clear of the wall put 2.8 % of its starts inside the
    wall (their episodes ended in contact at the first step). A start closer than ``START_CLEARANCE`` is mirrored
    back out across it, along the wall's normal; every other start is exactly as drawn."""
    import wall_env.batch as batch
    from wall_env.state import StateIndex

    margin, n = batch.START_CLEARANCE, 4000
    assert 0.005 <= margin <= 0.02

    def starts(clearance):
        monkeypatch.setattr(batch, "START_CLEARANCE", clearance)
        envs = make_vec(n=n)
        envs.reset(seed=11)
        x = envs.unwrapped.batch.simulator.x.copy()
        envs.close()
        return x

    drawn, kept = starts(-np.inf), starts(margin)
    vehicle = VehicleParams()
    c_drawn, c_kept = _wall_clearance(drawn, vehicle), _wall_clearance(kept, vehicle)
    assert np.mean(c_drawn < 0.0) > 0.01  # as drawn, some starts are inside the wall
    assert c_kept.min() >= margin - 1e-8
    clear = c_drawn >= margin
    assert 0.8 < clear.mean() < 0.95
    np.testing.assert_array_equal(kept[clear], drawn[clear])
    near = ~clear
    np.testing.assert_allclose(c_kept[near], 2 * margin - c_drawn[near], atol=1e-8)  # mirrored across the margin
    moved = kept[:, StateIndex.p_world] - drawn[:, StateIndex.p_world]
    np.testing.assert_allclose(moved[near, 1:], 0.0, atol=1e-12)  # along the wall's normal only
    others = np.ones(kept.shape[1], dtype=bool)
    others[StateIndex.p_world] = False
    np.testing.assert_array_equal(kept[:, others], drawn[:, others])  # attitude, velocity, rotors as drawn
