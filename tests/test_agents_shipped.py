"""The shipped agents as a Stable-Baselines3 user meets them: loaded with SB3 alone, given a
NaN observation, loaded for the wrong task."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest

import wall_env  # noqa: F401  (registers the tasks)
from agents import load_policy, pretrained_path
from agents.policy import TaskMismatchError, policy_factory

SWEEP = "WallInspector/WallSweep-v0"


def _readme_snippet(containing: str) -> str:
    """The documented Python block holding ``containing`` (docs/guide/agents.md), as printed."""
    from tests.docs_pages import block_containing

    return block_containing(containing, "python").code


def test_shipped_agent_flies_with_the_readmes_plain_stable_baselines3_loading(monkeypatch):
    """The README's two lines, ``PPO.load`` + ``VecNormalize.load``, run as written: nothing
    from this package but the environment registration."""
    from pathlib import Path

    snippet = _readme_snippet("VecNormalize.load")
    assert "import agents" not in snippet
    monkeypatch.chdir(Path(__file__).resolve().parent.parent)  # the README's paths are relative to the repository
    namespace: dict = {}
    exec(compile(snippet, "README.md", "exec"), namespace)
    model, env = namespace["model"], namespace["env"]
    assert not env.training and not env.norm_reward  # evaluation mode as saved: frozen statistics, raw rewards
    env.seed(0)
    obs = env.reset()
    contacts, steps, total = 0, 0, 0.0
    while True:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, done, info = env.step(action)
        contacts += int(info[0]["collision"])
        total += float(reward[0])
        steps += 1
        if done[0]:
            break
    env.close()
    assert steps == 1700  # the whole 17 s sweep: no early end
    assert contacts == 0
    # the env's default reward weights (position 2 /m): near the maximum of 1 per step; without
    # the statistics the same model hits the wall within a second (return about 40)
    assert total > 1500


def test_load_policy_and_sb3_loading_give_the_same_actions():
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    folder = pretrained_path("WallHover-v0")
    policy = load_policy("WallHover-v0")
    model = PPO.load(folder / "model.zip", device="cpu")
    venv = VecNormalize.load(str(folder / "vecnormalize.pkl"), make_vec_env("WallInspector/WallHover-v0", n_envs=1))
    raw = np.asarray(policy.info["check"]["observations"], dtype=np.float32)
    expected, _ = model.predict(venv.normalize_obs(raw), deterministic=True)
    np.testing.assert_array_equal(policy.predict(raw)[0], expected)
    venv.close()


def test_ppo_agent_given_nan_observation_hovers_with_a_counted_warning():
    policy = load_policy("WallHover-v0")
    env = gym.make("WallInspector/WallHover-v0")
    obs, _ = env.reset(seed=0)
    env.close()
    good, _ = policy.predict(obs)
    bad = obs.copy()
    bad[3] = np.nan
    with pytest.warns(RuntimeWarning, match="non-finite observation"):
        action, _ = policy.predict(bad)
    np.testing.assert_array_equal(action, np.zeros(4, dtype=np.float32))  # hover thrust, zero body rates
    assert policy.failures == 1
    with pytest.warns(RuntimeWarning):
        batch, _ = policy.predict(np.stack([obs, bad, np.full_like(obs, np.inf)]))
    assert batch.shape == (3, 4) and np.all(np.isfinite(batch))
    np.testing.assert_array_equal(batch[0], good)  # the healthy row is untouched
    np.testing.assert_array_equal(batch[1:], 0.0)
    assert policy.failures == 3 and len(policy.failure_log) == 3


def test_residual_agent_given_nan_observation_falls_back_to_its_base_hover():
    env = gym.make(SWEEP)
    policy = load_policy(pretrained_path(SWEEP, "residual_scmpc"), env=env)
    obs, _ = env.reset(seed=0)
    bad = obs.copy()
    bad[0] = np.nan
    with pytest.warns(RuntimeWarning, match="non-finite observation"):
        action, _ = policy.predict(bad)
    env.close()
    assert action.shape == (4,) and np.all(np.isfinite(action))
    assert policy.failures == 2  # the SC-MPC base and the correction each counted it
    # the correction added nothing: the action is the base controller's hover
    with pytest.warns(RuntimeWarning):
        hover, _ = policy.base.predict(bad)
    np.testing.assert_allclose(action, hover, atol=1e-6)


def test_agent_loaded_for_another_task_is_refused():
    hover_env = gym.make("WallInspector/WallHover-v0")
    with pytest.raises(TaskMismatchError, match="trained on WallInspector/WallSweep-v0.*WallInspector/WallHover-v0"):
        load_policy(SWEEP, env=hover_env)
    with pytest.raises(TaskMismatchError):
        policy_factory(SWEEP)(hover_env)
    with pytest.warns(RuntimeWarning, match="trained on WallInspector/WallSweep-v0"):
        policy = load_policy(SWEEP, env=hover_env, allow_other_task=True)
    assert policy.env_id == SWEEP
    assert load_policy("WallHover-v0", env=hover_env).env_id == "WallInspector/WallHover-v0"  # its own task: fine
    hover_env.close()


def test_shipped_model_cards_name_their_commit_and_say_what_differed():
    import json

    from agents.policy import PRETRAINED_DIR

    cards = sorted(PRETRAINED_DIR.glob("*/model_card.json"))
    assert {path.parent.name for path in cards} == {
        "wall_hover", "wall_circle", "wall_sweep", "wall_sweep_residual_scmpc", "wall_sweep_teacher_scmpc",
        "wall_sweep_warm_start_scmpc", "facade", "pier"}
    for path in cards:
        training = json.loads(path.read_text())["training"]
        assert re.fullmatch(r"[0-9a-f]{40}", training["git_commit"]), path  # a commit, nothing vague appended
        md = (path.parent / "model_card.md").read_text()
        assert "(with uncommitted changes)" not in md
        if training.get("git_uncommitted"):
            assert f"{training['git_commit']} plus uncommitted changes" in md


@pytest.mark.parametrize("residual, warm_start, teacher, folder", [
    (None, None, None, "wall_sweep"), ("scmpc", None, None, "wall_sweep_residual_scmpc"),
    (None, "scmpc", None, "wall_sweep_warm_start_scmpc"), (None, None, "scmpc", "wall_sweep_teacher_scmpc"),
])
def test_ship_keeps_each_kind_of_agent_in_its_own_folder(tmp_path, monkeypatch, residual, warm_start, teacher, folder):
    """A warm-started or distilled agent learned from the controller it is compared with, so shipping it
    never replaces the agent that learned the task alone (the comparison's PPO)."""
    import agents.policy
    from agents.train import ship

    monkeypatch.setattr(agents.policy, "PRETRAINED_DIR", tmp_path / "pretrained")
    run = tmp_path / "run"
    (run / "best").mkdir(parents=True)
    for name in ("model.zip", "vecnormalize.pkl", "policy.json"):
        (run / "best" / name).write_text(name)
    for name in ("model_card.json", "model_card.md"):
        (run / name).write_text(name)
    target = ship(run, SWEEP, residual, warm_start, teacher)
    assert target == tmp_path / "pretrained" / folder
    assert sorted(p.name for p in target.iterdir()) == sorted(
        ["model.zip", "vecnormalize.pkl", "policy.json", "model_card.json", "model_card.md"])


def test_fly_loads_agents_through_load_policy_with_their_statistics(tmp_path):
    import shutil

    from agents import CheckpointNotFoundError, TrainedPolicy
    from discovery.fly import make_policy

    env = gym.make("WallInspector/WallHover-v0")
    folder = pretrained_path("WallHover-v0")
    for source in (folder, folder / "model.zip"):
        policy = make_policy(str(source), env)
        assert isinstance(policy, TrainedPolicy) and policy.path == folder
    # a model saved by Stable-Baselines3 alone: with vecnormalize.pkl beside it, flown as the checkpoint is
    shutil.copy(folder / "model.zip", tmp_path / "model.zip")
    shutil.copy(folder / "vecnormalize.pkl", tmp_path / "vecnormalize.pkl")
    obs = np.asarray(load_policy(folder).info["check"]["observations"], dtype=np.float32)
    plain = make_policy(str(tmp_path / "model.zip"), env)
    np.testing.assert_array_equal(plain.predict(obs)[0], load_policy(folder).predict(obs)[0])
    # without it, the raw observations are used, and the user is told so
    (tmp_path / "vecnormalize.pkl").unlink()
    with pytest.warns(RuntimeWarning, match="no vecnormalize.pkl beside it"):
        raw = make_policy(str(tmp_path / "model.zip"), env)
    assert raw.vec_normalize is None
    # a checkpoint folder with a file missing is refused with the file's name
    (tmp_path / "policy.json").write_text((folder / "policy.json").read_text())
    with pytest.raises(CheckpointNotFoundError, match="vecnormalize.pkl"):
        make_policy(str(tmp_path), env)
    with pytest.raises(TaskMismatchError):
        make_policy(str(pretrained_path(SWEEP)), env)
    env.close()


def test_the_budget_counts_the_development_runs_a_model_card_records():
    import json

    from agents import pretrained_path
    from wall_inspector.compare import budget_markdown, budgets

    card = json.loads((pretrained_path("WallSweep") / "model_card.json").read_text())
    runs = card["development"]["runs"]
    rows = [r for r in budgets("tuned", ["WallSweep"], with_ppo=True) if r["method"] == "PPO"]
    assert [r["settings"] for r in rows] == ["shipped agent", f"{len(runs)} development runs (not shipped)"]
    assert rows[1]["env_steps"] == sum(r["env_steps"] for r in runs)
    assert rows[1]["wall_time_s"] == sum(r["wall_time_s"] for r in runs)
    assert "development runs (not shipped)" in budget_markdown(rows)
    circle = [r for r in budgets("tuned", ["WallCircle"], with_ppo=True) if r["method"] == "PPO"]
    circle_runs = json.loads((pretrained_path("WallCircle") / "model_card.json").read_text())["development"]["runs"]
    assert len(circle_runs) == 1 and circle[1]["settings"] == "1 development run (not shipped)"
