"""Warm start by behaviour cloning: SC-MPC's demonstrations on the batched sweep, cloned into PPO's actor."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

from agents.batched_vec_env import BatchedVecEnv
from agents.behaviour_cloning import warm_start
from agents.config import apply_overrides, default_config
from agents.demonstrations import discounted_returns, record_demonstrations
from agents.residual import make_base_controller

SWEEP = "WallInspector/WallSweep-v0"
SCMPC = {"k_s": 4.1, "d_thr": 0.132, "preset": "tuned", "threads": 1, "solver": {"max_iterations": 1}}


def _demos(n_envs: int, steps: int, noise: float, seed: int):
    venv = BatchedVecEnv(SWEEP, n_envs, reward_weights={"position": 5.0})
    try:
        expert = make_base_controller("scmpc", venv, **SCMPC)
        return record_demonstrations(venv, expert, steps, noise=noise, seed=seed)
    finally:
        venv.close()


def test_discounted_returns_stop_at_terminations_and_go_on_with_the_tail_value_at_cuts():
    rewards = np.array([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0]])
    dones = np.array([[False, False], [True, True], [False, False], [False, False]])
    truncated = np.array([[False, False], [False, True], [False, False], [False, False]])
    returns = discounted_returns(rewards, dones, truncated, gamma=0.5, tail_value=4.0)
    # env 0 terminates at step 1: G1 = 1, G0 = 1 + 0.5 * 1; its next episode is cut by the recording's
    # end, where the sum goes on with the tail value: G3 = 1 + 0.5 * 4, G2 = 1 + 0.5 * 3
    np.testing.assert_allclose(returns[:, 0], [1.5, 1.0, 2.5, 3.0])
    # env 1 hits its time limit at step 1: that return goes on with the tail value as well
    np.testing.assert_allclose(returns[:, 1], [2.5, 3.0, 2.5, 3.0])
    with pytest.raises(ValueError, match="gamma"):
        discounted_returns(rewards, dones, truncated, gamma=1.0)


def test_demonstrations_record_the_clean_action_and_fly_the_noisy_one():
    demos = _demos(n_envs=4, steps=30, noise=0.1, seed=3)
    assert demos.observations.shape == (30, 4, 48) and demos.actions.shape == (30, 4, 4)
    np.testing.assert_allclose(demos.noise, [0.0, 0.1 / 3, 0.2 / 3, 0.1], rtol=1e-6)
    np.testing.assert_array_equal(demos.applied[:, 0], demos.actions[:, 0])  # env 0 flies the controller as it is
    deviation = np.std(demos.applied[:, 3] - demos.actions[:, 3])
    assert 0.07 < deviation < 0.13  # env 3: noise of std 0.1 (a little clipped at the range's ends)
    # the observation carries the previous action actually applied: the noisy one
    np.testing.assert_allclose(demos.observations[1:, :, 43:47], demos.applied[:-1], atol=1e-6)
    with pytest.raises(ValueError, match="noise"):
        record_demonstrations(None, None, 10, noise=-0.1)  # type: ignore[arg-type]


def test_cloned_policy_acts_like_the_controller_on_flights_it_never_saw():
    torch.manual_seed(0)
    demos = _demos(n_envs=16, steps=200, noise=0.1, seed=0)
    venv = BatchedVecEnv(SWEEP, 4, reward_weights={"position": 5.0})
    normalizer = VecNormalize(venv, gamma=0.99)
    model = PPO("MlpPolicy", normalizer, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu",
                policy_kwargs={"net_arch": {"pi": [64, 64], "vf": [64, 64]}, "log_std_init": -3.0})
    report = warm_start(model, normalizer, demos, epochs=60, batch_size=256, learning_rate=3e-3, holdout=0.0)

    # the normaliser holds the demonstrations' statistics
    flat = demos.observations.reshape(-1, 48).astype(np.float64)
    np.testing.assert_allclose(normalizer.obs_rms.mean, flat.mean(axis=0), rtol=1e-6, atol=1e-9)
    # (SB3's RunningMeanStd starts from variance 1 with weight 1e-4: a trace of it stays)
    np.testing.assert_allclose(normalizer.obs_rms.var, flat.var(axis=0), rtol=1e-6, atol=1e-6)
    assert normalizer.ret_rms.count == pytest.approx(demos.n_samples + 1e-4)  # every env at every recorded step
    assert float(model.policy.log_std.detach().mean()) == -3.0  # exploration starts where configured

    # held-out flights (another seed, a different noise draw): deterministic actions against the controller's
    test = _demos(n_envs=2, steps=200, noise=0.05, seed=7)
    obs, expected = test.flat()
    actions, _ = model.predict(normalizer.normalize_obs(obs), deterministic=True)
    error = float(np.sqrt(np.mean((actions - expected) ** 2)))
    assert error < 0.006, report  # normalised units: 0.1 N of thrust, 0.02 rad/s of body rate
    assert error < 0.2 * float(np.sqrt(np.mean(expected ** 2)))  # a fifth of the actions' own size

    # PPO goes on from those statistics: its rollouts add to them instead of starting afresh
    count = normalizer.obs_rms.count
    model.learn(total_timesteps=128)
    assert normalizer.obs_rms.count == pytest.approx(count + 128 + 4)  # rollout steps and the first reset
    np.testing.assert_allclose(normalizer.obs_rms.mean[:3], flat.mean(axis=0)[:3], atol=0.05)
    normalizer.close()


def test_warm_start_configuration_is_checked():
    config = default_config(SWEEP)
    assert config["warm_start"]["controller"] is None
    assert apply_overrides(config, ["warm_start.controller=scmpc"])["warm_start"]["controller"] == "scmpc"
    with pytest.raises(ValueError, match="warm_start.controller must be one of"):
        apply_overrides(config, ["warm_start.controller=ppo"])
    with pytest.raises(ValueError, match="residual agent"):
        apply_overrides(config, ["warm_start.controller=scmpc", "residual=scmpc"])
    with pytest.raises(ValueError, match=r"warm_start.noise must be in \[0.0, 1.0\]"):
        apply_overrides(config, ["warm_start.noise=2"])
    with pytest.raises(ValueError, match="warm_start.epochs must be a positive integer"):
        apply_overrides(config, ["warm_start.epochs=0"])


def test_training_with_a_warm_start_records_it_and_counts_its_time(tmp_path):
    from agents.train import train

    config = apply_overrides(default_config(SWEEP), [
        "warm_start.controller=scmpc", "warm_start.demo_envs=4", "warm_start.demo_steps=40", "warm_start.epochs=2",
        "n_envs=4", "ppo.n_steps=32", "ppo.batch_size=64", "timesteps=256", "checkpoint_freq=0", "eval.freq=128",
        "eval.episodes=1", "card_eval.episodes=1"])
    config["residual_base_kwargs"]["scmpc"]["threads"] = 1
    run = train(config, tmp_path / "sweep", progress_bar=False, verbose=0)
    warm = run.card["training"]["warm_start"]
    assert warm["controller"] == "scmpc" and warm["demo_env_steps"] == 160 and warm["controller_failures"] == 0
    assert warm["demo_seeds"] == [1_000_000, 1_000_003]  # seeds of their own, not the card's 0..9
    assert warm["cloning"]["epochs"] == 2 and warm["cloning"]["samples"] + warm["cloning"]["heldout_samples"] == 160
    spent = warm["demo_wall_time_s"] + warm["cloning"]["wall_time_s"] + warm["ppo_wall_time_s"]
    assert spent <= run.card["training"]["wall_time_s"] <= run.card["training"]["command_wall_time_s"]
    # the cloned policy was evaluated before PPO's first step, as the first candidate for best/
    assert run.card["training"]["eval_curve"][0][0] == 0
    assert "warm-started by behaviour cloning of scmpc" in run.card["summary"]
    assert "scmpc flew 160 env steps" in (tmp_path / "sweep" / "model_card.md").read_text()


def test_the_command_line_flag_sets_the_controller_and_is_recorded_in_the_command():
    import argparse

    from wall_inspector.train import add_arguments
    from wall_inspector.train_arguments import _command, _config_from_args

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--env", "WallSweep-v0", "--warm-start", "scmpc", "--out", "runs/x"])
    config = _config_from_args(args)
    assert config["warm_start"]["controller"] == "scmpc"
    assert " --warm-start scmpc" in _command(args, config)
    args = parser.parse_args(["--env", "WallSweep-v0", "--warm-start", "scmpc", "--residual", "pid", "--out", "runs/x"])
    with pytest.raises(ValueError, match="use one or the other"):
        _config_from_args(args)
