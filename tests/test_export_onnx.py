"""PPO agents exported to ONNX: onnxruntime gives the Python agent's actions; the export command's usage errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wall_env  # noqa: F401
from agents import load_policy
from agents.export import ONNX_FILE, OnnxPolicy, export_onnx
from controllers.paper_tables import TABLE_II
from wall_env.observation import OBSERVATION_FIELDS
from wall_inspector.cli import main

SCENARIO = TABLE_II[0]


@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    """The shipped WallSweep agent (whatever its current training) and its ONNX export."""
    source = "WallSweep-v0"
    path = export_onnx(source, tmp_path_factory.mktemp("onnx") / ONNX_FILE)
    return load_policy(source), OnnxPolicy(path)


def _untrained_hover_agent(folder, action_scale: float = 1.0):
    """An untrained agent of another architecture (ReLU, 32-16 units) with far-from-unit statistics; its action
    layer's weights times ``action_scale``."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.checkpoints import save_checkpoint
    from agents.config import default_config
    from agents.envs import make_vec_env
    from agents.train import check_observations, policy_description

    config = default_config("WallHover")
    venv = VecNormalize(make_vec_env(config, 1, 0), clip_obs=3.0)
    venv.reset()
    for _ in range(200):
        venv.step(np.full((1, 4), 0.3, dtype=np.float32))
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=64, device="cpu", seed=1,
                policy_kwargs={"net_arch": [32, 16], "activation_fn": torch.nn.ReLU})
    with torch.no_grad():
        model.policy.action_net.weight.mul_(action_scale)
    save_checkpoint(folder, model, venv, {**policy_description(config), "num_timesteps": 0}, check_observations(config))
    venv.close()
    return folder


@pytest.fixture(scope="module")
def other_agent(tmp_path_factory):
    return _untrained_hover_agent(tmp_path_factory.mktemp("agent") / "hover")


@pytest.fixture(scope="module")
def loud_agent(tmp_path_factory):
    """The same untrained agent with its action layer 100x: most of its raw actions lie beyond the bounds."""
    return _untrained_hover_agent(tmp_path_factory.mktemp("agent") / "loud", action_scale=100.0)


def _observations_around(agent, seed: int, spread: float) -> np.ndarray:
    statistics = agent.vec_normalize.obs_rms
    return (statistics.mean + np.sqrt(statistics.var)
            * np.random.default_rng(seed).normal(0.0, spread, (256, 48))).astype(np.float32)


def test_the_onnx_policy_gives_the_python_agents_actions_over_a_whole_flight(shipped):
    python, exported = shipped
    env = gym.make(SCENARIO.env_id, **SCENARIO.make_kwargs())
    observation, _ = env.reset(seed=201)
    python_actions, onnx_actions, done = [], [], False
    while not done:
        action, _ = python.predict(observation)
        other, _ = exported.predict(observation)
        python_actions.append(action)
        onnx_actions.append(other)
        observation, _, terminated, truncated, _ = env.step(action)
        done = terminated or truncated
    env.close()
    python_actions, onnx_actions = np.asarray(python_actions), np.asarray(onnx_actions)
    assert len(python_actions) == 1700 and onnx_actions.dtype == np.float32
    assert np.max(np.abs(onnx_actions - python_actions)) <= 1e-5
    assert np.ptp(python_actions[:, 0]) > 0.05  # the agent flies (not a constant action)
    batch, _ = exported.predict(np.zeros((3, 48), dtype=np.float32))  # a batch of any size
    assert batch.shape == (3, 4)
    assert exported.metadata["env_id"] == SCENARIO.env_id


def test_a_broken_observation_gives_the_hover_action_and_clipping_holds(shipped):
    python, exported = shipped
    observations = np.random.default_rng(3).normal(0.0, 30.0, (64, 48)).astype(np.float32)  # far out: clipped
    observations[5, OBSERVATION_FIELDS["v_world"].start] = np.nan
    observations[9, OBSERVATION_FIELDS["time"].start] = np.inf
    with pytest.warns(RuntimeWarning, match="non-finite observation"):
        expected, _ = python.predict(observations)
    got, _ = exported.predict(observations)
    np.testing.assert_array_equal(got[[5, 9]], 0.0)
    assert np.max(np.abs(got - expected)) <= 1e-5
    assert np.all(np.abs(got) <= 1.0)


def _both_actions(agent, path, seed: int) -> tuple[np.ndarray, np.ndarray, OnnxPolicy]:
    """The Python agent's and its ONNX export's actions on 256 observations around its statistics."""
    python, exported = load_policy(agent), OnnxPolicy(export_onnx(agent, path))
    observations = _observations_around(python, seed=seed, spread=2.0)
    return python.predict(observations)[0], exported.predict(observations)[0], exported


def test_actions_beyond_the_bounds_are_clipped_as_python_clips_them(loud_agent, tmp_path):
    expected, got, _ = _both_actions(loud_agent, tmp_path / "loud.onnx", seed=5)
    assert np.max(np.abs(got - expected)) <= 1e-5
    assert np.all(np.abs(got) <= 1.0)
    assert np.mean(np.abs(got) == 1.0) > 0.3  # the action space's bounds, reached by many actions
    assert np.any((np.abs(got) > 0.0) & (np.abs(got) < 1.0))  # and the rest passed through


def test_any_agent_folder_exports_with_its_own_network_and_statistics(other_agent, tmp_path):
    expected, got, exported = _both_actions(other_agent, tmp_path / "hover.onnx", seed=4)
    assert np.max(np.abs(got - expected)) <= 1e-5
    assert exported.metadata["env_id"] == "WallInspector/WallHover-v0"


def test_a_residual_agent_is_refused_with_the_reason(tmp_path):
    with pytest.raises(ValueError, match="residual agent on top of 'scmpc'"):
        export_onnx("agents/pretrained/wall_sweep_residual_scmpc", tmp_path / ONNX_FILE)
    assert not (tmp_path / ONNX_FILE).exists()


def _one_line_error(capsys) -> str:
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1, captured.err
    assert captured.err.startswith("wall-inspector export: error: ")
    assert "Traceback" not in captured.err
    return captured.err


@pytest.mark.parametrize(("args", "message"), [
    (["ppo", "--agent", "{tmp}/no-such-agent"], "no-such-agent: no such folder, and not a task name"),
    (["fly-me", ], "argument method: invalid choice: 'fly-me'"),
    (["scmpc", "--out", "{tmp}/a-file"], "--out {tmp}/a-file: exists and is not a folder"),
    (["ppo", "--out", "{tmp}/a-file"], "--out {tmp}/a-file: exists and is not a folder"),
    (["scmpc", "--env", "Moon-v0"], "unknown task 'Moon-v0'"),
    (["mpc", "--k-s", "4"], "--k-s only applies to scmpc"),
    (["ppo", "--model", "m.json"], "--model only applies to scmpc or mpc"),
    (["scmpc", "--k-s", "-1"], "k_s must be in [0, 200] N/m"),
    (["scmpc", "--preset", "{tmp}/none.yaml"], "preset file {tmp}/none.yaml does not exist"),
])
def test_export_rejects_bad_input_in_one_line(args, message, tmp_path, capsys):
    (tmp_path / "a-file").write_text("mine")
    args = [a.format(tmp=tmp_path) for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "out")]
    assert main(["export", *args]) == 2
    assert message.format(tmp=tmp_path) in _one_line_error(capsys)
    assert not (tmp_path / "out").exists()
    assert (tmp_path / "a-file").read_text() == "mine"  # a file the user gave is never touched


def test_export_writes_the_onnx_file_it_announces(tmp_path, capsys):
    assert main(["export", "ppo", "--out", str(tmp_path / "ppo")]) == 0
    out = capsys.readouterr().out
    assert f"wrote {tmp_path / 'ppo' / ONNX_FILE}" in out
    assert OnnxPolicy(tmp_path / "ppo" / ONNX_FILE).observation_size == 48
