"""Configurations, domain randomisation reaching the env, and the multi-env worker vector env."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import wall_env
from agents.config import apply_overrides, default_config, task_env_id, task_name, task_slug
from agents.envs import env_kwargs, make_env, make_vec_env
from agents.vec_env import MultiEnvSubprocVecEnv, split_evenly


@pytest.mark.parametrize("spelling", ["WallSweep", "WallSweep-v0", "WallInspector/WallSweep-v0", "wall_sweep"])
def test_task_spellings(spelling):
    assert task_name(spelling) == "WallSweep"
    assert task_env_id(spelling) == "WallInspector/WallSweep-v0"
    assert task_slug(spelling) == "wall_sweep"


def test_every_task_has_a_valid_config():
    for task in wall_env.TASKS:
        config = default_config(task)
        assert config["env_id"] == f"WallInspector/{task}-v0"
        ranges = set(config["randomize_ranges"])
        if task in ("Facade", "WallSweep"):  # the path's start time alone: the start-state curriculum of training
            assert ranges == {"start_time"} and config["randomize"]  # (a randomised sweep: wall_sweep_randomized.yaml)
        elif task == "Pier":  # its circle grows with the stand-off, which the batched env cannot shift per row
            assert ranges == {"k_s", "d_thr", "mass", "start_time"}
        else:
            assert ranges == {"k_s", "d_thr", "mass", "standoff"}
        # the ranges are ones the environment accepts
        env = make_env({**config, "randomize": True})
        env.close()


def test_overrides_and_their_errors():
    config = apply_overrides(default_config("WallHover"), ["ppo.n_steps=128", "policy.net_arch=[32, 32]", "randomize=true"])
    assert config["ppo"]["n_steps"] == 128 and config["policy"]["net_arch"] == [32, 32] and config["randomize"]
    with pytest.raises(ValueError, match="unknown key 'nsteps'"):
        apply_overrides(config, ["nsteps=3"])
    with pytest.raises(ValueError, match="ppo.batch_size must be a positive integer"):
        apply_overrides(config, ["ppo.batch_size=0"])
    with pytest.raises(ValueError, match="key=value"):
        apply_overrides(config, ["ppo.n_steps"])


def test_randomisation_reaches_the_env():
    config = default_config("WallHover")
    assert "randomize" not in env_kwargs(config)
    config["randomize"] = True
    ranges = config["randomize_ranges"]
    assert env_kwargs(config)["randomize"] == {k: tuple(v) for k, v in ranges.items()}

    env = make_env(config)
    draws = []
    for seed in range(6):
        env.reset(seed=seed)
        draws.append(dict(env.unwrapped.episode_parameters))
        assert env.unwrapped.scene.walls[0].point[0] == 0.0
        # the drawn stand-off is the one the reference uses
        assert env.unwrapped.reference.position(np.array([0.0]))[0][0] == pytest.approx(draws[-1]["standoff"])
    env.close()
    for key, (low, high) in ranges.items():
        values = [d[key] for d in draws]
        assert all(low <= v <= high for v in values) and len(set(values)) == len(values), key

    # through the worker processes too, and differently in each environment
    venv = make_vec_env(config, n_envs=4, n_workers=2)
    venv.seed(0)
    venv.reset()
    drawn = venv.get_attr("episode_parameters")
    venv.close()
    assert len({d["k_s"] for d in drawn}) == 4 and all(ranges["k_s"][0] <= d["k_s"] <= ranges["k_s"][1] for d in drawn)


def test_randomize_flag_reaches_the_saved_config(tmp_path):
    from wall_inspector.cli import main

    out = tmp_path / "rand"
    assert main(["train", "--env", "WallHover-v0", "--randomize", "--timesteps", "256", "--n-envs", "2", "--workers", "1",
                 "--out", str(out), "--set", "ppo.n_steps=128", "--set", "ppo.batch_size=128", "--set", "ppo.n_epochs=1",
                 "--set", "card_eval.episodes=1", "--checkpoint-freq", "0", "--no-progress", "--quiet"]) == 0
    assert yaml.safe_load((out / "config.yaml").read_text())["randomize"] is True
    assert "--randomize" in (out / "model_card.md").read_text()


def test_split_evenly():
    assert [list(r) for r in split_evenly(5, 2)] == [[0, 1, 2], [3, 4]]
    with pytest.raises(ValueError):
        split_evenly(1, 2)


def test_multi_env_workers_match_one_process_step_for_step():
    """Same seeds and actions: identical observations, rewards, dones, terminal observations."""
    config = default_config("WallHover")
    config["env_kwargs"] = {"duration": 0.2}  # 20-step episodes, so time-limit ends happen
    reference = make_vec_env(config, n_envs=3, n_workers=0)
    workers = make_vec_env(config, n_envs=3, n_workers=2)
    assert isinstance(workers, MultiEnvSubprocVecEnv) and workers.n_workers == 2
    rng = np.random.default_rng(0)
    try:
        for venv in (reference, workers):
            venv.seed(11)
        obs_a, obs_b = reference.reset(), workers.reset()
        np.testing.assert_array_equal(obs_a, obs_b)
        ends = 0
        for _ in range(45):
            actions = rng.uniform(-0.6, 0.6, (3, 4)).astype(np.float32)
            obs_a, rew_a, done_a, info_a = reference.step(actions)
            obs_b, rew_b, done_b, info_b = workers.step(actions)
            np.testing.assert_array_equal(obs_a, obs_b)
            np.testing.assert_array_equal(rew_a, rew_b)
            np.testing.assert_array_equal(done_a, done_b)
            for a, b, done in zip(info_a, info_b, done_a):
                assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
                if done:
                    ends += 1
                    np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
                    assert a["episode"]["l"] == b["episode"]["l"] and a["episode"]["r"] == b["episode"]["r"]
        assert ends >= 6
        assert workers.env_method("reset", seed=1, indices=[2])[0][0].shape == (48,)
    finally:
        reference.close()
        workers.close()


def _broken_env():
    raise ValueError("this environment cannot be built")


def _env_that_fails_on_step():
    import gymnasium as gym

    class Failing(gym.Wrapper):
        def step(self, action):
            raise FloatingPointError("the simulator blew up")

    return Failing(gym.make("WallInspector/WallHover-v0"))


def test_worker_failures_reach_the_parent_with_their_cause():
    with pytest.raises(RuntimeError, match="this environment cannot be built"):
        MultiEnvSubprocVecEnv([_broken_env, _broken_env], n_workers=2)
    venv = MultiEnvSubprocVecEnv([_env_that_fails_on_step] * 2, n_workers=1)
    try:
        venv.reset()
        with pytest.raises(RuntimeError, match="the simulator blew up"):
            venv.step(np.zeros((2, 4), dtype=np.float32))
        assert venv.get_attr("task")[0].name == "WallHover"  # the worker is still answering
    finally:
        venv.close()
