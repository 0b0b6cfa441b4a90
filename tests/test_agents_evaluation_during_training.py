"""The evaluations during training judge the task, on equal terms: the whole path from its start
(a start-state curriculum shapes training only), the same episodes every time, and the final model
judged too when the run ends between two evaluations."""

from __future__ import annotations

import json

import numpy as np
import pytest
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecNormalize

from agents.callbacks import SameEpisodesEval
from agents.config import default_config
from agents.envs import CURRICULUM_RANGES, evaluation_config, make_vec_env
from agents.lean_ppo import LeanPPO
from agents.train import train


def _sweep_config() -> dict:
    config = default_config("WallSweep")
    config["randomize"] = True
    config["randomize_ranges"] = {"start_time": [0.0, 16.0], "k_s": [2.0, 6.0]}
    return config


def test_evaluation_config_leaves_out_the_curriculum_and_keeps_the_world_randomisation():
    config = _sweep_config()
    judged = evaluation_config(config)
    assert "start_time" in CURRICULUM_RANGES
    assert judged["randomize"] is True and judged["randomize_ranges"] == {"k_s": [2.0, 6.0]}
    assert config["randomize_ranges"] == {"start_time": [0.0, 16.0], "k_s": [2.0, 6.0]}  # the given one untouched
    config["randomize_ranges"] = {"start_time": [0.0, 16.0]}
    assert evaluation_config(config)["randomize"] is False  # nothing left to draw


def test_evaluation_episodes_fly_the_whole_sweep_from_its_start():
    config = _sweep_config()
    config["randomize_ranges"] = {"start_time": [10.0, 16.0]}
    config["env_kwargs"] = {**config["env_kwargs"], "duration": 17.0}
    trained_on = make_vec_env(config, 4, vector="batched")
    judged_on = make_vec_env(evaluation_config(config), 4, vector="batched")
    try:
        time_index = 47  # the observation's time since reset, counted from the episode's start along the reference
        assert np.all(trained_on.reset()[:, time_index] >= 10.0)  # training: 10-16 s along the sweep
        assert np.all(judged_on.reset()[:, time_index] == 0.0)  # judged: from the start
    finally:
        trained_on.close()
        judged_on.close()


def _evaluations(folder, callback_type, **kwargs) -> list[list[float]]:
    config = default_config("WallHover")
    config["env_kwargs"] = {**config["env_kwargs"], "duration": 1.0}
    train_env = VecNormalize(make_vec_env(config, 2, vector="batched"))
    eval_env = VecNormalize(make_vec_env(config, 3, vector="batched"), training=False, norm_reward=False)
    eval_env.seed(11)
    model = LeanPPO("MlpPolicy", train_env, n_steps=64, batch_size=64, seed=0, device="cpu")
    model.set_logger(configure(str(folder), []))  # a folder of its own: None makes one in /tmp
    callback = callback_type(eval_env, n_eval_episodes=3, eval_freq=1, deterministic=True, verbose=0,
                             log_path=str(folder), **kwargs)
    callback.init_callback(model)
    for _ in range(2):
        callback.on_step()
    train_env.close()
    eval_env.close()
    return callback.evaluations_results


def test_every_evaluation_flies_the_same_episodes(tmp_path):
    same = _evaluations(tmp_path / "same", SameEpisodesEval, episode_seed=11)
    assert len(same) == 2 and np.allclose(same[0], same[1], rtol=0, atol=1e-9)
    drawn_on = _evaluations(tmp_path / "sb3", EvalCallback)  # SB3's callback seeds once: the second evaluation meets new starts
    assert not np.allclose(drawn_on[0], drawn_on[1], rtol=0, atol=1e-6)


def _ends_between_evaluations() -> dict:
    """A hover run of 1,536 steps (3 rollouts of 2 x 256) evaluated every 1,024 steps."""
    config = default_config("WallHover")
    config.update(timesteps=1536, n_envs=2, n_workers=1, checkpoint_freq=0, checkpoint_minutes=0.0, seed=5)
    config["ppo"].update(n_steps=256, batch_size=256, n_epochs=1)
    config["eval"].update(freq=1024, episodes=1)
    config["card_eval"]["episodes"] = 1
    return config


def test_the_final_model_is_judged_when_the_run_ends_between_evaluations(tmp_path):
    trained = train(_ends_between_evaluations(), tmp_path / "hover", progress_bar=False, verbose=0)
    curve = trained.card["training"]["eval_curve"]
    assert [row[0] for row in curve] == [1024, 1536]  # the evaluation of 1024 steps, then the final model's
    history = np.load(tmp_path / "hover" / "eval" / "evaluations.npz")
    assert list(history["timesteps"]) == [1024, 1536]
    saved = json.loads((tmp_path / "hover" / "best" / "policy.json").read_text())
    best = max(curve, key=lambda row: row[1])
    assert saved["eval_mean_return"] == pytest.approx(best[1], abs=0.01)
    assert saved["num_timesteps"] == best[0]  # best/ is whichever of the two scored higher


def test_ctrl_c_while_the_final_model_is_judged_resumes_to_the_same_best(tmp_path, monkeypatch):
    import agents.train
    from agents.train import TrainingInterrupted

    whole = train(_ends_between_evaluations(), tmp_path / "whole", progress_bar=False, verbose=0)

    judge = agents.train._evaluate_as_best

    def ctrl_c_at_the_final_judgement(*args, **kwargs):
        if kwargs.get("only_if_better"):
            raise KeyboardInterrupt
        return judge(*args, **kwargs)

    monkeypatch.setattr(agents.train, "_evaluate_as_best", ctrl_c_at_the_final_judgement)
    with pytest.raises(TrainingInterrupted) as stopped:
        train(_ends_between_evaluations(), tmp_path / "stopped", progress_bar=False, verbose=0)
    assert stopped.value.num_timesteps == 1536  # saved with every step trained, the final model not yet judged
    monkeypatch.setattr(agents.train, "_evaluate_as_best", judge)
    resumed = train(_ends_between_evaluations(), tmp_path / "stopped", resume=True, progress_bar=False, verbose=0)
    assert resumed.card["training"]["timesteps_this_run"] == 0
    assert [row[0] for row in resumed.card["training"]["eval_curve"]] == [1024, 1536]  # judged by the resumed run
    assert resumed.card["training"]["eval_curve"] == whole.card["training"]["eval_curve"]
    best = [json.loads((run / "best" / "policy.json").read_text()) for run in (tmp_path / "whole", tmp_path / "stopped")]
    assert best[0]["num_timesteps"] == best[1]["num_timesteps"]
    assert best[0]["eval_mean_return"] == pytest.approx(best[1]["eval_mean_return"], abs=1e-6)
