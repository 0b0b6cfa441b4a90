"""Loading checkpoints: every missing, corrupted or mismatched file is named in the error."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from agents import CheckpointError, CheckpointNotFoundError, load_policy
from agents.checkpoints import save_checkpoint
from agents.config import default_config
from agents.envs import make_vec_env
from agents.train import check_observations, policy_description


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """An untrained PPO model with normalisation statistics from a few hundred steps."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    config = default_config("WallHover")
    venv = VecNormalize(make_vec_env(config, 1, 0))
    venv.reset()
    for _ in range(300):
        venv.step(np.zeros((1, 4), dtype=np.float32))
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=64, device="cpu", seed=0)
    folder = tmp_path_factory.mktemp("ckpt") / "hover"
    save_checkpoint(folder, model, venv, {**policy_description(config), "num_timesteps": 0}, check_observations(config))
    venv.close()
    return folder


def _copy(checkpoint, tmp_path):
    import shutil

    target = tmp_path / "copy"
    shutil.copytree(checkpoint, target)
    return target


def test_valid_checkpoint_loads(checkpoint):
    policy = load_policy(checkpoint)
    obs = np.asarray(json.loads((checkpoint / "policy.json").read_text())["check"]["observations"], dtype=np.float32)
    actions, _ = policy.predict(obs)
    assert actions.shape == (len(obs), 4)


def test_missing_folder_is_named(tmp_path):
    missing = tmp_path / "nothing_here"
    with pytest.raises(CheckpointNotFoundError, match=re.escape(str(missing))):
        load_policy(missing)
    with pytest.raises(FileNotFoundError):  # also a FileNotFoundError for callers that catch that
        load_policy(missing / "model.zip")


@pytest.mark.parametrize("name", ["model.zip", "vecnormalize.pkl", "policy.json"])
def test_missing_file_is_named(checkpoint, tmp_path, name):
    folder = _copy(checkpoint, tmp_path)
    (folder / name).unlink()
    with pytest.raises(CheckpointNotFoundError, match=re.escape(str(folder / name))):
        load_policy(folder)


def test_corrupted_model_is_named(checkpoint, tmp_path):
    folder = _copy(checkpoint, tmp_path)
    data = (folder / "model.zip").read_bytes()
    (folder / "model.zip").write_bytes(data[: len(data) // 2])  # a truncated download
    with pytest.raises(CheckpointError, match=re.escape(str(folder / "model.zip")) + ".*corrupted"):
        load_policy(folder)
    (folder / "model.zip").write_bytes(b"not a zip at all")
    with pytest.raises(CheckpointError, match=re.escape(str(folder / "model.zip"))):
        load_policy(folder / "model.zip")


@pytest.mark.parametrize("name", ["vecnormalize.pkl", "policy.json"])
def test_corrupted_statistics_or_description_is_named(checkpoint, tmp_path, name):
    folder = _copy(checkpoint, tmp_path)
    data = (folder / name).read_bytes()
    (folder / name).write_bytes(data[: len(data) // 3])
    with pytest.raises(CheckpointError, match=re.escape(str(folder / name)) + ".*corrupted"):
        load_policy(folder)


def test_statistics_that_do_not_belong_to_the_model_are_refused(checkpoint, tmp_path):
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.checkpoints import save_vecnormalize, vecnormalize_from_json

    folder = _copy(checkpoint, tmp_path)
    stats = VecNormalize.load(str(folder / "vecnormalize.pkl"), make_vec_env(default_config("WallHover"), 1, 0))
    stats.obs_rms.mean = stats.obs_rms.mean + 0.5
    stats.save(str(folder / "vecnormalize.pkl"))
    stats.close()
    with pytest.raises(CheckpointError, match=re.escape(str(folder / "vecnormalize.pkl")) + ".*do not belong together"):
        load_policy(folder)
    from gymnasium import spaces

    state = {"norm_obs": True, "clip_obs": 10.0, "clip_reward": 10.0, "gamma": 0.99, "epsilon": 1e-8,
             "obs_mean": [0.0] * 10, "obs_var": [1.0] * 10, "obs_count": 1.0, "ret_mean": 0.0, "ret_var": 1.0,
             "ret_count": 1.0}
    short = vecnormalize_from_json(state, spaces.Box(-1, 1, (10,)), spaces.Box(-1, 1, (4,)))
    save_vecnormalize(short, folder / "vecnormalize.pkl")
    with pytest.raises(CheckpointError, match="statistics for 10 observation entries"):
        load_policy(folder)
    (folder / "vecnormalize.pkl").write_bytes(__import__("pickle").dumps({"not": "a VecNormalize"}))
    with pytest.raises(CheckpointError, match="not a VecNormalize pickle"):
        load_policy(folder)


def test_task_without_shipped_checkpoint_names_the_expected_folder(monkeypatch, tmp_path):
    import agents.policy

    monkeypatch.setattr(agents.policy, "PRETRAINED_DIR", tmp_path / "pretrained")
    with pytest.raises(CheckpointNotFoundError, match=re.escape(str(tmp_path / "pretrained" / "wall_sweep"))):
        load_policy("WallInspector/WallSweep-v0")


def test_checkpoint_of_the_earlier_json_format_is_named_and_upgraded_exactly(checkpoint, tmp_path):
    """How the shipped agents were converted: normalization.json -> vecnormalize.pkl, same actions."""
    from agents.checkpoints import read_vecnormalize, upgrade_checkpoint

    folder = _copy(checkpoint, tmp_path)
    stats = read_vecnormalize(folder / "vecnormalize.pkl")
    (folder / "normalization.json").write_text(json.dumps({
        "format": 1, "norm_obs": True, "norm_reward": True, "clip_obs": stats.clip_obs, "clip_reward": stats.clip_reward,
        "epsilon": stats.epsilon, "gamma": stats.gamma, "obs_mean": stats.obs_rms.mean.tolist(),
        "obs_var": stats.obs_rms.var.tolist(), "obs_count": stats.obs_rms.count, "ret_mean": float(stats.ret_rms.mean),
        "ret_var": float(stats.ret_rms.var), "ret_count": stats.ret_rms.count}))
    (folder / "vecnormalize.pkl").unlink()
    with pytest.raises(CheckpointError, match="earlier format.*upgrade_checkpoint"):
        load_policy(folder)
    assert upgrade_checkpoint(folder) == folder / "vecnormalize.pkl"
    upgraded = read_vecnormalize(folder / "vecnormalize.pkl")
    np.testing.assert_array_equal(upgraded.obs_rms.mean, stats.obs_rms.mean)  # bit for bit
    np.testing.assert_array_equal(upgraded.obs_rms.var, stats.obs_rms.var)
    obs = np.asarray(json.loads((folder / "policy.json").read_text())["check"]["observations"], dtype=np.float32)
    np.testing.assert_array_equal(load_policy(folder).predict(obs)[0], load_policy(checkpoint).predict(obs)[0])


def test_a_model_card_with_an_evaluation_history_carries_its_learning_curve(tmp_path):
    from matplotlib.image import imread

    from agents.checkpoints import write_model_card
    from agents.learning_curve import LEARNING_CURVE_PNG, shipped_timesteps

    card = {"env_id": "WallInspector/WallSweep-v0", "checkpoint": "best/ at 300000 timesteps (best mean evaluation "
            "return 90.0)", "config": {"eval": {"episodes": 5}},
            "training": {"eval_curve": [[100000, 10.0, 50.0], [200000, 40.0, 80.0], [300000, 90.0, 170.0],
                                        [200000, 45.0, 85.0], [400000, 80.0, 160.0]]}}  # resumed from 200k
    _, md = write_model_card(tmp_path, card)
    text = md.read_text()
    assert f"![Mean evaluation return and episode length against env steps]({LEARNING_CURVE_PNG})" in text
    assert "5 evaluation episodes at each point" in text and "on the training's settings" in text
    picture = imread(tmp_path / LEARNING_CURVE_PNG)
    assert picture.shape[0] > 300 and picture.shape[1] > 600 and picture.std() > 0.05  # drawn, not blank
    assert shipped_timesteps(card["checkpoint"]) == 300000 and shipped_timesteps("best/") is None
    # one evaluation is no curve: no picture and no section
    (tmp_path / LEARNING_CURVE_PNG).unlink()
    _, md = write_model_card(tmp_path, {**card, "training": {"eval_curve": [[100000, 10.0, 50.0]]}})
    assert "Learning curve" not in md.read_text() and not (tmp_path / LEARNING_CURVE_PNG).exists()


def test_every_shipped_ppo_agent_with_an_evaluation_history_has_its_learning_curve():
    from agents.checkpoints import read_json
    from agents.learning_curve import LEARNING_CURVE_PNG, card_curve
    from agents.policy import PRETRAINED_DIR

    folders = [f for f in sorted(PRETRAINED_DIR.iterdir()) if (f / "model_card.json").is_file()]
    with_curve = [f for f in folders if card_curve(read_json(f / "model_card.json")) is not None]
    assert len(with_curve) >= 4
    for folder in with_curve:
        assert (folder / LEARNING_CURVE_PNG).is_file(), folder
        assert f"]({LEARNING_CURVE_PNG})" in (folder / "model_card.md").read_text(), folder


def test_an_optimiser_state_that_ctrl_c_left_half_made_is_not_saved(tmp_path):
    """Adam makes a parameter's state at its first step, ``step`` before its moments: a Ctrl-C between them
    used to be saved, and the resumed run failed in its first update with KeyError: 'exp_avg'."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from agents.checkpoints import drop_half_made_optimizer_state

    venv = VecNormalize(DummyVecEnv([lambda: __import__("gymnasium").make("CartPole-v1")]))
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    optimizer = model.policy.optimizer
    params = [p for group in optimizer.param_groups for p in group["params"]]
    for p in params[:3]:  # three parameters stepped, the fourth interrupted half-way
        optimizer.state[p] = {"step": torch.tensor(1.0), "exp_avg": torch.zeros_like(p), "exp_avg_sq": torch.zeros_like(p)}
    optimizer.state[params[3]] = {"step": torch.tensor(0.0)}
    save_checkpoint(tmp_path / "ckpt", model, venv, {"env_id": "CartPole-v1"})
    loaded = PPO.load(tmp_path / "ckpt" / "model.zip", device="cpu")
    loss = sum((p * p).sum() for p in loaded.policy.parameters())
    loss.backward()
    loaded.policy.optimizer.step()  # raised KeyError: 'exp_avg' with the half-made state saved
    kept = loaded.policy.optimizer.state
    assert all({"exp_avg", "exp_avg_sq"} <= set(kept[p]) for p in loaded.policy.parameters())
    # a complete state is left alone
    assert drop_half_made_optimizer_state(model.policy.optimizer) == []
    assert len([p for p in params if p in optimizer.state]) == 3
