"""What an agent remembers: stacked observations and a leaky integral of the position error, the same in training
(a VecEnv wrapper) and in flight."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.history import HistorySettings, ObservationHistory, VecObservationHistory


def _obs(n, value):
    obs = np.zeros((n, 48), dtype=np.float32)
    obs[:, 0] = value
    obs[:, 18:21] = value  # p_error
    return obs


def test_frames_stride_and_integral_follow_their_definitions():
    settings = HistorySettings(frames=3, stride=2, integral_time=0.5, control_dt=0.01)
    history = ObservationHistory(settings)
    assert settings.size == 3 * 48 + 3
    out = [history(_obs(2, k), np.array([k == 0, k == 0])) for k in range(6)]
    # at step 5 the frames are the observations of steps 1, 3, 5 (2 apart, newest last)
    assert out[5][:, [0, 48, 96]].tolist() == [[1, 3, 5]] * 2
    # before the episode has them, the first observation stands in
    assert out[1][0, [0, 48, 96]].tolist() == [0, 0, 1]
    decay = math.exp(-0.01 / 0.5)
    integral = 0.0
    for k in range(6):
        integral = decay * integral + 0.01 * k
    assert out[5][0, -3:] == pytest.approx([integral] * 3)
    restarted = history(_obs(2, 7), np.array([True, False]))
    assert restarted[0, [0, 48, 96]].tolist() == [7, 7, 7] and restarted[0, -1] == pytest.approx(0.07)
    assert restarted[1, [0, 48, 96]].tolist() == [2, 4, 7]  # steps 2, 4 and the new one


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match=r"history.frames must be an integer in \[1, 64\]"):
        HistorySettings(frames=0)
    with pytest.raises(ValueError, match="history takes"):
        HistorySettings.from_spec({"length": 3})


def test_the_wrapper_gives_an_ended_episode_its_own_last_inputs():
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    import wall_env  # noqa: F401

    venv = DummyVecEnv([lambda: gym.make("WallInspector/WallHover-v0", duration=0.05)])
    wrapped = VecObservationHistory(venv, HistorySettings(frames=2, integral_time=1.0))
    # a seeded start clear of the wall: about 4 % of WallHover's unseeded starts touch the wall within the
    # 5 steps and end early (a busy-machine fresh-clone run went red on one)
    wrapped.seed(1)
    first = wrapped.reset()
    assert first.shape == (1, 2 * 48 + 3) and np.array_equal(first[0, :48], first[0, 48:96])
    for _ in range(5):
        features, _, dones, infos = wrapped.step(np.zeros((1, 4)))
    assert dones[0] and infos[0]["TimeLimit.truncated"]  # the episode's 5 steps ran out, on the last one
    assert infos[0]["terminal_observation"].shape == (2 * 48 + 3,)
    # the new episode starts its own memory: both frames are its first observation
    assert np.array_equal(features[0, :48], features[0, 48:96])


def test_an_agent_trained_with_a_history_loads_flies_and_exports_with_it(tmp_path):
    import gymnasium as gym

    import agents
    import wall_env  # noqa: F401
    from wall_inspector.cli import main as cli_main

    out = tmp_path / "run"
    code = cli_main(["train", "--env", "WallHover-v0", "--timesteps", "4096", "--n-envs", "8", "--seed", "2",
                     "--set", "ppo.n_steps=256", "--set", "ppo.batch_size=512", "--set", "ppo.n_epochs=1",
                     "--set", "card_eval.episodes=1", "--eval-episodes", "1", "--eval-freq", "100000",
                     "--set", "history.frames=3", "--set", "history.stride=2", "--set", "history.integral_time=0.5",
                     "--no-progress", "--quiet", "--out", str(out)])
    assert code == 0
    policy = agents.load_policy(out)  # verify=True: the recorded check inputs give the recorded actions
    assert policy.history is not None and policy.observation_size == 48
    assert policy.model.observation_space.shape == (3 * 48 + 3,)
    envs = gym.make_vec("WallInspector/WallHover-v0", num_envs=3, vectorization_mode="vector_entry_point")
    obs, _ = envs.reset(seed=[1, 2, 3])
    reference = ObservationHistory(policy.history.settings)  # the memory the agent keeps, kept by hand
    last_time = np.full(3, np.inf)
    for _ in range(60):
        actions, _ = policy.predict(obs)  # no episode_start: a reset shows as the time going back
        features = reference(obs, obs[:, 47] < last_time)
        last_time = obs[:, 47].copy()
        expected, _ = policy.model.predict(policy.normalize(features), deterministic=True)
        np.testing.assert_allclose(actions, expected, atol=1e-7)
        obs, *_ = envs.step(actions)

    from agents.export import OnnxPolicy, export_onnx

    onnx = OnnxPolicy(export_onnx(out, tmp_path / "policy.onnx"))
    assert onnx.input_size == 3 * 48 + 3 and '"frames": 3' in onnx.metadata["history"]
    assert onnx.observation_size == 48  # it takes the env's observations and keeps the history, as the policy does
