"""The residual wrapper: the applied action is the base action plus the scaled correction."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wall_env  # noqa: F401
from agents.residual import ResidualActionWrapper, ResidualPolicy, combine
from wall_env.observation import OBSERVATION_FIELDS


class LinearBase:
    """A stand-in base controller: action = W @ p_error + b, with a counter of episode starts."""

    def __init__(self):
        self.bias = np.array([0.05, -0.1, 0.2, 0.0])
        self.episode_starts = 0

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(obs, dtype=float)
        if episode_start is not None and np.any(episode_start):
            self.episode_starts += 1
        action = self.bias - 0.5 * obs[..., OBSERVATION_FIELDS["p_error"]].sum(axis=-1, keepdims=True)
        return np.clip(action, -1, 1), state


def test_combine_numbers():
    base = np.array([0.1, -0.2, 0.9, -0.95])
    correction = np.array([1.0, 0.5, 2.0, -1.0])  # 2.0 is clipped to 1 before scaling
    np.testing.assert_allclose(combine(base, correction, 0.2), [0.3, -0.1, 1.0, -1.0])
    np.testing.assert_allclose(combine(base, correction, [0.1, 0.2, 0.05, 0.3]), [0.2, -0.1, 0.95, -1.0])


def test_wrapper_adds_the_correction_to_the_base_action():
    base = LinearBase()
    env = ResidualActionWrapper(gym.make("WallInspector/WallHover-v0", noise=False), base, scale=0.2)
    assert env.observation_space.shape == (52,)
    obs, _ = env.reset(seed=0)
    assert base.episode_starts == 1
    raw = obs[:48]
    expected_base, _ = LinearBase().predict(raw)
    np.testing.assert_allclose(obs[48:], expected_base, atol=1e-6)  # the base action is observed

    correction = np.array([0.5, -1.0, 0.25, 1.0], dtype=np.float32)
    obs2, _, _, _, info = env.step(correction)
    np.testing.assert_allclose(info["base_action"], expected_base, atol=1e-6)
    np.testing.assert_allclose(info["applied_action"], np.clip(expected_base + 0.2 * correction, -1, 1), atol=1e-6)
    np.testing.assert_allclose(info["applied_action"] - info["base_action"], [0.1, -0.2, 0.05, 0.2], atol=1e-6)
    # the environment really flew the combined action: it reports it as its previous action
    np.testing.assert_allclose(obs2[OBSERVATION_FIELDS["previous_action"]], info["applied_action"], atol=1e-6)
    env.close()


def test_zero_correction_flies_exactly_like_the_base():
    def fly(wrapped: bool):
        env = gym.make("WallInspector/WallHover-v0")
        base = LinearBase()
        if wrapped:
            env = ResidualActionWrapper(env, lambda e: base, scale=0.3)  # built from a factory
        obs, _ = env.reset(seed=4)
        positions = []
        for _ in range(50):
            action = np.zeros(4) if wrapped else base.predict(obs)[0]
            obs, _, terminated, truncated, info = env.step(action)
            positions.append(info["p_world"])
            if terminated or truncated:
                break
        env.close()
        return np.asarray(positions)

    np.testing.assert_allclose(fly(True), fly(False), atol=1e-9)


def test_residual_policy_combines_on_plain_observations():
    class Constant:
        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            assert np.shape(obs)[-1] == 52
            return np.tile([1.0, -1.0, 0.0, 0.5], np.shape(obs)[:-1] + (1,)), None

    policy = ResidualPolicy(LinearBase(), Constant(), scale=0.1)
    obs = np.zeros((3, 48), dtype=np.float32)
    actions, _ = policy.predict(obs)
    np.testing.assert_allclose(actions, np.tile([0.15, -0.2, 0.2, 0.05], (3, 1)), atol=1e-6)
    single, _ = policy.predict(obs[0])
    assert single.shape == (4,)


def test_residual_on_pid_if_available():
    from agents.residual import make_base_controller

    try:
        make_base_controller("pid", gym.make("WallInspector/WallHover-v0"))
    except ImportError as exc:
        pytest.skip(f"the PID controller has not landed yet ({exc})")

    def fly(wrapped: bool, correction=(0.0, 0.0, 0.0, 0.0)):
        correction = np.asarray(correction, dtype=float)
        env = gym.make("WallInspector/WallHover-v0")
        pid = make_base_controller("pid", env)
        if wrapped:
            env = ResidualActionWrapper(env, lambda e: make_base_controller("pid", e), scale=0.2)
        # a start on the reference: a perturbed start 0.16 m from the wall may begin touching it
        obs, _ = env.reset(seed=0, options={"perturb_start": False})
        positions = []
        for _ in range(30):
            action = correction if wrapped else pid.predict(obs)[0]
            obs, _, terminated, truncated, info = env.step(action)
            positions.append(info["p_world"])
            if wrapped:
                np.testing.assert_allclose(info["applied_action"],
                                           np.clip(info["base_action"] + 0.2 * correction, -1, 1))
            if terminated or truncated:
                break
        env.close()
        return np.asarray(positions)

    pid_alone = fly(False)
    np.testing.assert_allclose(fly(True), pid_alone, atol=1e-9)
    # a constant correction of more thrust makes the residual agent climb above the PID's flight
    climbed = fly(True, np.array([1.0, 0.0, 0.0, 0.0]))
    assert climbed[-1, 2] > pid_alone[-1, 2] + 0.01


def test_residual_agent_trains_saves_and_loads_on_pid(tmp_path, monkeypatch):
    from agents import load_policy
    from agents.residual import make_base_controller
    from wall_inspector.cli import main

    try:
        make_base_controller("pid", gym.make("WallInspector/WallHover-v0"))
    except ImportError as exc:
        pytest.skip(f"the PID controller has not landed yet ({exc})")
    out = tmp_path / "res"
    assert main(["train", "--env", "WallHover-v0", "--residual", "pid", "--timesteps", "256", "--n-envs", "2",
                 "--workers", "1", "--out", str(out), "--set", "ppo.n_steps=128", "--set", "ppo.batch_size=128",
                 "--set", "ppo.n_epochs=1", "--set", "card_eval.episodes=1", "--checkpoint-freq", "0",
                 "--no-progress", "--quiet"]) == 0
    with pytest.raises(ValueError, match="pass env="):
        load_policy(out)
    env = gym.make("WallInspector/WallHover-v0")
    policy = load_policy(out, env=env)
    assert isinstance(policy, ResidualPolicy)
    obs, _ = env.reset(seed=2)
    action, _ = policy.predict(obs)
    base_action, _ = make_base_controller("pid", env).predict(obs)
    correction, _ = load_policy(out, env=env).correction.predict(np.concatenate([obs, base_action]).astype(np.float32))
    np.testing.assert_allclose(action, np.clip(base_action + 0.2 * np.clip(correction, -1, 1), -1, 1), atol=1e-6)
    env.close()

    # shipped beside the plain agent, where policy_factory(variant=...) finds it for each env
    import agents.policy
    from agents import policy_factory
    from agents.train import ship

    monkeypatch.setattr(agents.policy, "PRETRAINED_DIR", tmp_path / "pretrained")
    assert ship(out, "WallHover", "pid") == tmp_path / "pretrained" / "wall_hover_residual_pid"
    env = gym.make("WallInspector/WallHover-v0")
    shipped = policy_factory(variant="residual_pid")(env)
    assert isinstance(shipped, ResidualPolicy)
    np.testing.assert_allclose(shipped.predict(obs)[0], action, atol=1e-6)
    env.close()

    # in a comparison table, an SC-MPC base is told the scenario's suction, like the table's SC-MPC
    import json
    import shutil

    import agents.residual
    from controllers.paper_tables import TABLE_I

    scmpc_dir = tmp_path / "as_scmpc"
    shutil.copytree(out / "best", scmpc_dir)
    info = json.loads((scmpc_dir / "policy.json").read_text())
    info["residual"].update(base="scmpc", base_kwargs={"k_s": 4.1, "d_thr": 0.132})
    info["env_id"] = "WallInspector/WallCircle-v0"  # flown on the circle below (agents are checked against the task)
    (scmpc_dir / "policy.json").write_text(json.dumps(info))
    built = []
    monkeypatch.setattr(agents.residual, "make_base_controller",
                        lambda name, env, **kw: built.append((name, kw)) or LinearBase())
    env = gym.make("WallInspector/WallCircle-v0")
    factory = policy_factory(scmpc_dir)
    factory(env, TABLE_I[2])
    factory(env)
    env.close()
    # (its policy.json names no preset: agents saved before presets existed flew the authors' settings)
    assert built[-2:] == [("scmpc", {"preset": "paper", "k_s": 10.0, "d_thr": 0.10}),
                          ("scmpc", {"preset": "paper", "k_s": 4.1, "d_thr": 0.132})]


def test_batched_residual_env_adds_the_correction_to_the_base_action():
    from agents.batched_vec_env import BatchedVecEnv
    from agents.residual import ResidualVecEnv

    base = LinearBase()
    env = ResidualVecEnv(BatchedVecEnv("WallInspector/WallHover-v0", 3), base, scale=0.2)
    assert env.observation_space.shape == (52,)
    env.seed(7)
    obs = env.reset()
    assert base.episode_starts == 1
    expected_base, _ = LinearBase().predict(obs[:, :48])
    np.testing.assert_allclose(obs[:, 48:], expected_base, atol=1e-6)  # the base action is observed
    correction = np.tile(np.array([0.5, -1.0, 0.25, 1.0], dtype=np.float32), (3, 1))
    obs2, _, dones, _ = env.step(correction)
    assert not dones.any()
    # the envs really flew the combined action: they report it as their previous action
    np.testing.assert_allclose(obs2[:, OBSERVATION_FIELDS["previous_action"]],
                               combine(expected_base, correction, 0.2), atol=1e-6)
    env.close()


def test_zero_correction_on_the_batched_env_flies_exactly_like_the_base():
    from agents.batched_vec_env import BatchedVecEnv
    from agents.residual import ResidualVecEnv

    def fly(wrapped: bool):
        venv = BatchedVecEnv("WallInspector/WallHover-v0", 3)
        base = LinearBase()
        env = ResidualVecEnv(venv, base, scale=0.3) if wrapped else venv
        env.seed(4)
        obs = env.reset()
        positions = []
        for _ in range(50):
            action = np.zeros((3, 4), dtype=np.float32) if wrapped else base.predict(obs)[0]
            obs, _, dones, _ = env.step(action)
            positions.append(obs[:, OBSERVATION_FIELDS["p_world"]].copy())
            if dones.any():  # the stand-in base is no real controller: compare up to the first episode end
                break
        env.close()
        return np.asarray(positions)

    wrapped, plain = fly(True), fly(False)
    assert len(wrapped) > 10
    np.testing.assert_allclose(wrapped, plain, atol=1e-9)


def test_residual_training_env_on_the_batched_env_uses_one_scmpc_for_the_batch():
    from agents.config import default_config
    from agents.envs import make_vec_env
    from agents.residual import ResidualVecEnv
    from agents.timing import TimeSplit
    from controllers import SCMPC

    config = default_config("WallSweep-v0")
    config["residual"] = "scmpc"
    venv = make_vec_env(config, 3, 0, vector="batched")
    residual = venv.venv
    assert isinstance(residual, ResidualVecEnv) and isinstance(residual.base, SCMPC)
    obs = venv.reset()
    assert obs.shape == (3, 52)
    for _ in range(20):
        obs, _, dones, _ = venv.step(np.zeros((3, 4), dtype=np.float32))
    assert len(residual.base.iteration_counts) == 21 * 3 and residual.base.failures == 0
    assert TimeSplit(venv).env is residual and residual.step_time_s > residual.base_time_s > 0
    venv.close()
