"""Rollouts flown in a worker process while the learner updates (agents.rollout_worker): collected exactly as the
learner collects one, acting with the weights handed over, replayed to the callbacks step by step, and closed cleanly."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback

from agents.config import apply_overrides, default_config
from agents.envs import make_training_env
from agents.learner import make_ppo
from agents.rollout_worker import BUFFER_ARRAYS, RolloutWorker, WorkerError
from agents.train import train


def _config(**changes) -> dict:
    config = default_config("WallSweep")
    config.update(n_envs=4, timesteps=4 * 32 * 3, seed=3, checkpoint_freq=0, checkpoint_minutes=0.0, rollout_worker=True)
    config["ppo"].update(n_steps=32, batch_size=64, n_epochs=2)
    config["eval"].update(freq=4 * 32 * 2, episodes=1)
    config["card_eval"]["episodes"] = 1
    config.update(changes)
    return config


class _Steps(BaseCallback):
    def __init__(self) -> None:
        super().__init__()
        self.calls = 0
        self.ended = 0

    def _on_step(self) -> bool:
        self.calls += 1
        self.ended += int(np.sum(self.locals["dones"]))
        assert len(self.locals["infos"]) == self.training_env.num_envs
        return True


def test_the_workers_first_rollout_is_the_one_the_learner_collects_itself():
    config = _config()
    learner = make_ppo(config, make_training_env(config), None)
    learner._setup_learn(10_000, callback=None)
    assert learner.collect_rollouts(learner.env, learner._init_callback(_Steps()), learner.rollout_buffer, 32)
    with RolloutWorker(config) as worker:
        worker.fly(learner.policy)  # the same initial weights (the same seed builds them)
        rollout = worker.collect()
    for name in BUFFER_ARRAYS:
        np.testing.assert_allclose(rollout.arrays[name], getattr(learner.rollout_buffer, name), rtol=1e-6, atol=1e-6,
                                   err_msg=name)
    np.testing.assert_allclose(rollout.obs_rms.mean, learner.get_vec_normalize_env().obs_rms.mean, rtol=1e-9)
    assert rollout.dones.shape == (32, 4)


def test_a_rollout_acts_with_the_weights_handed_over():
    config = _config()
    learner = make_ppo(config, make_training_env(config), None)
    with RolloutWorker(config) as worker:
        worker.fly(learner.policy)
        first = worker.collect()
        with torch.no_grad():
            learner.policy.log_std.fill_(-3.0)  # a narrower policy: exp(-3) = 0.05 against exp(-1) = 0.37
            learner.policy.action_net.bias.add_(0.2)
        worker.fly(learner.policy)
        second = worker.collect()
    obs = torch.as_tensor(second.arrays["observations"].reshape(-1, 48))
    actions = torch.as_tensor(second.arrays["actions"].reshape(-1, 4))
    with torch.no_grad():
        values, log_prob, _ = learner.policy.evaluate_actions(obs, actions)
        mean = learner.policy.get_distribution(obs).distribution.mean
    # the recorded log-probabilities and values are those of the handed-over policy
    np.testing.assert_allclose(second.arrays["log_probs"].reshape(-1), log_prob.numpy(), rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(second.arrays["values"].reshape(-1), values.numpy().reshape(-1), rtol=1e-5, atol=1e-5)
    assert (actions - mean).std().item() == pytest.approx(np.exp(-3.0), rel=0.15)
    assert (first.arrays["actions"].reshape(-1, 4) - mean.numpy()).std() > 0.25  # the first flew the wide policy


def test_a_run_with_the_worker_keeps_the_workers_statistics_and_reports_its_time(tmp_path):
    run = train(_config(), tmp_path / "run", progress_bar=False, verbose=0)
    card = run.card["training"]
    assert card["rollout_worker"] is True and card["total_timesteps"] == 384
    split = card["time_split"]
    assert split["env_step_s"] > 0.0 and split["waiting_for_rollouts_s"] >= 0.0
    assert [row[0] for row in card["eval_curve"]] == [256, 384]  # evaluations replayed at their steps, then the final one
    # the learner's statistics are the worker's after the last rollout learned from: the first reset's 4
    # observations and 3 rollouts of 32 steps x 4 envs (the rollout in flight at the end is dropped)
    assert run.normalizer.obs_rms.count == pytest.approx(4 + 384, abs=0.01)
    assert run.model.rollout_worker is None  # closed with the run; the model goes on alone


def test_the_callbacks_see_every_step_of_the_workers_rollouts():
    config = _config()
    config["env_kwargs"] = {**config["env_kwargs"], "duration": 0.3}
    config["randomize_ranges"] = {"start_time": [0.0, 0.29]}
    learner = make_ppo(config, make_training_env(config), None)
    steps = _Steps()
    with RolloutWorker(config) as worker:
        learner.rollout_worker = worker
        learner.learn(total_timesteps=256, callback=steps)
    assert steps.calls == 256 // 4 and learner.num_timesteps == 256
    # every episode that ended in the worker (0.3 s: 30 steps each) reached the learner's episode statistics
    assert steps.ended >= 8 and len(learner.ep_info_buffer) == steps.ended


def test_the_same_seed_trains_the_same_weights_with_the_worker(tmp_path):
    runs = [train(_config(), tmp_path / name, progress_bar=False, verbose=0) for name in ("a", "b")]
    for (name, a), b in zip(runs[0].model.policy.state_dict().items(), runs[1].model.policy.state_dict().values()):
        assert torch.equal(a, b), name
    assert runs[0].card["training"]["eval_curve"] == runs[1].card["training"]["eval_curve"]


def test_a_worker_that_cannot_build_its_env_says_why():
    config = _config()
    config["env_kwargs"] = {**config["env_kwargs"], "standoff": -1.0}  # refused by the env, in the worker
    worker = RolloutWorker(config)
    try:
        with pytest.raises(WorkerError, match="standoff"):
            worker.fly(make_ppo(_config(), make_training_env(_config()), None).policy)
    finally:
        worker.close()
    assert not worker.process.is_alive()


def test_closing_with_a_rollout_in_flight_ends_the_worker_cleanly():
    config = _config()
    learner = make_ppo(config, make_training_env(config), None)
    worker = RolloutWorker(config)
    worker.fly(learner.policy)
    worker.close()  # the worker finishes its rollout, which is dropped, then reads the close
    assert worker.process.exitcode == 0  # it returned; not terminated
    with pytest.raises(WorkerError, match="closed"):
        worker.fly(learner.policy)


def test_the_rollout_worker_setting_is_checked():
    with pytest.raises(ValueError, match="rollout_worker"):
        apply_overrides(default_config("WallSweep"), ["rollout_worker=3"])


def test_a_run_that_may_use_one_core_keeps_its_rollouts_in_one_process(tmp_path):
    run = train(_config(), tmp_path / "run", progress_bar=False, verbose=0, most_threads=1)  # a Ray trial of one CPU
    assert run.card["training"]["rollout_worker"] is False
    assert "waiting_for_rollouts_s" not in run.card["training"]["time_split"]
    assert run.card["training"]["total_timesteps"] == 384

