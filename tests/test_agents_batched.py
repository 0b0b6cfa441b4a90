"""Stable-Baselines3 on the batched env: PPO, VecNormalize, VecMonitor, EvalCallback, evaluate_policy."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from agents.batched_vec_env import BatchedVecEnv
from agents.config import default_config
from agents.envs import make_vec_env

SWEEP = "WallInspector/WallSweep-v0"


def test_rows_fly_as_single_envs_seeded_the_sb3_way():
    venv = BatchedVecEnv(SWEEP, 3)
    venv.seed(21)  # SB3: env k gets seed 21 + k at the next reset
    obs = venv.reset()
    actions = np.random.default_rng(0).uniform(-0.2, 0.2, (30, 3, 4)).astype(np.float32)
    batched = [obs]
    for a in actions:
        obs, _, dones, _ = venv.step(a)
        assert not dones.any()
        batched.append(obs)
    for k in range(3):
        env = gym.make(SWEEP)
        single = [env.reset(seed=21 + k)[0]] + [env.step(a[k])[0] for a in actions]
        np.testing.assert_allclose(np.array(batched)[:, k], single, atol=1e-6)
        env.close()
    venv.close()


def test_episode_ends_reset_in_the_same_step_with_sb3s_infos():
    venv = VecMonitor(BatchedVecEnv(SWEEP, 2, duration=0.05, standoff=0.4, noise=False), info_keywords=("collisions",))
    venv.seed(0)
    venv.reset()
    for _ in range(4):
        _, _, dones, _ = venv.step(np.zeros((2, 4), dtype=np.float32))
        assert not dones.any()
    obs, rewards, dones, infos = venv.step(np.zeros((2, 4), dtype=np.float32))
    assert dones.all()
    for k in range(2):
        assert infos[k]["TimeLimit.truncated"] is True
        assert infos[k]["terminal_observation"][47] == pytest.approx(0.05)  # time of the last step
        assert obs[k, 47] == 0.0  # already the next episode's first observation
        assert infos[k]["episode"]["l"] == 5 and infos[k]["episode"]["collisions"] == 0
        assert infos[k]["episode"]["r"] == pytest.approx(5 * 1.0, abs=0.5)


def test_ppo_vecnormalize_evalcallback_and_evaluate_policy_take_the_batched_env(tmp_path):
    config = default_config(SWEEP)
    train_env = VecNormalize(make_vec_env(config, 16, vector="batched"), gamma=0.99)
    eval_env = VecNormalize(make_vec_env(config, 2, vector="batched"), training=False, norm_reward=False)
    model = PPO("MlpPolicy", train_env, n_steps=64, batch_size=256, n_epochs=1, seed=0, device="cpu")
    callback = EvalCallback(eval_env, n_eval_episodes=2, eval_freq=64, log_path=str(tmp_path), verbose=0)
    model.learn(total_timesteps=2048, callback=callback)
    assert model.num_timesteps >= 2048 and len(callback.evaluations_results) >= 1
    assert np.all(train_env.obs_rms.count > 2048)  # the statistics saw every batched step
    rewards, lengths = evaluate_policy(model, eval_env, n_eval_episodes=4, return_episode_rewards=True)
    assert len(rewards) == 4 and all(np.isfinite(rewards)) and all(n >= 1 for n in lengths)
    train_env.close()
    eval_env.close()


def test_residual_agents_run_on_the_batched_env_with_one_base_controller():
    from agents.residual import ResidualVecEnv
    from controllers import PID

    config = {**default_config(SWEEP), "residual": "pid"}
    venv = make_vec_env(config, 4, vector="batched")
    assert isinstance(venv.venv, ResidualVecEnv) and isinstance(venv.venv.base, PID)
    obs = venv.reset()
    assert obs.shape == (4, 52)
    obs, rewards, dones, _ = venv.step(np.zeros((4, 4), dtype=np.float32))
    assert obs.shape == (4, 52) and np.all(np.isfinite(rewards)) and not dones.any()
    venv.close()


def test_a_controllers_predict_takes_a_batch_of_observations_from_the_batched_env():
    from controllers import PID

    env = gym.make(SWEEP)
    venv = BatchedVecEnv(SWEEP, 6)
    venv.seed(3)
    obs = venv.reset()
    pid = PID.from_env(env)
    actions, _ = pid.predict(obs)
    assert actions.shape == (6, 4)
    for k in range(6):  # the same as one observation at a time
        np.testing.assert_allclose(PID.from_env(env).predict(obs[k])[0], actions[k], atol=1e-6)
    ended = np.zeros(6, dtype=bool)
    for _ in range(300):  # and it flies the batch: 3 s of the sweep without an episode end
        obs, _, dones, _ = venv.step(pid.predict(obs)[0])
        ended |= dones
    assert not ended.any()
    env.close()
    venv.close()


def test_train_uses_the_batched_env_by_default_and_its_card_splits_the_time(tmp_path):
    from agents.train import train

    config = default_config("WallHover")
    assert config["vector"] == "batched"
    config.update(timesteps=2048, n_envs=16, checkpoint_freq=0)
    config["ppo"].update(n_steps=64, batch_size=512, n_epochs=1)
    config["eval"].update(freq=100_000, episodes=1)
    config["card_eval"]["episodes"] = 1
    card = train(config, tmp_path / "hover", progress_bar=False, verbose=0).card
    training = card["training"]
    assert training["vector"] == "batched" and training["total_timesteps"] >= 2048
    split = training["time_split"]
    parts = split["env_step_s"] + split["rollout_other_s"] + split["update_and_callbacks_s"]
    assert split["env_step_s"] > 0 and parts == pytest.approx(split["total_s"], abs=0.05)
    assert split["env_step_share"] + split["rollout_other_share"] + split["update_and_callbacks_share"] == \
        pytest.approx(1.0, abs=0.01)
