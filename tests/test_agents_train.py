"""The whole training path on a tiny budget: CLI train, checkpoints, model card, load,
evaluate, resume, and the loaded policy acting exactly like the trained one."""

from __future__ import annotations

import json
import re

import gymnasium as gym
import numpy as np
import pytest
import torch
import yaml

import wall_env  # noqa: F401
from agents import TrainedPolicy, load_policy, policy_factory
from agents.checkpoints import load_model
from agents.config import default_config, validate_config
from agents.evaluate import evaluate_agent
from agents.train import train
from wall_inspector.cli import main

# a few thousand steps: 4 envs x 256 steps per rollout, 2 worker processes
TINY = ["--set", "ppo.n_steps=256", "--set", "ppo.batch_size=512", "--set", "ppo.n_epochs=2",
        "--set", "card_eval.episodes=2", "--eval-episodes", "1", "--eval-freq", "1024",
        "--checkpoint-freq", "2048", "--no-progress", "--quiet"]


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "hover"
    code = main(["train", "--env", "WallInspector/WallHover-v0", "--timesteps", "3072", "--n-envs", "4",
                 "--workers", "2", "--seed", "3", "--out", str(out), *TINY])
    assert code == 0
    return out


def test_cli_run_writes_checkpoints_logs_and_card(cli_run):
    out = cli_run
    for folder in (out, out / "best"):
        for name in ("model.zip", "vecnormalize.pkl", "policy.json"):
            assert (folder / name).is_file(), folder / name
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["000002048"]
    events = list((out / "tb").rglob("events.out.tfevents*"))
    assert events, "no TensorBoard events written"
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    scalars = EventAccumulator(str(events[0].parent)).Reload().Tags()["scalars"]
    for tag in ("rollout/ep_rew_mean", "rollout/collisions_per_episode", "eval/mean_reward", "train/value_loss"):
        assert tag in scalars, tag
    evaluations = np.load(out / "eval" / "evaluations.npz")
    assert list(evaluations["timesteps"]) == [1024, 2048, 3072]

    saved = yaml.safe_load((out / "config.yaml").read_text())
    assert saved["env_id"] == "WallInspector/WallHover-v0"
    assert (saved["n_envs"], saved["n_workers"], saved["seed"], saved["timesteps"]) == (4, 2, 3, 3072)
    assert saved["ppo"]["n_steps"] == 256 and saved["ppo"]["gamma"] == default_config("WallHover")["ppo"]["gamma"]

    card = json.loads((out / "model_card.json").read_text())
    assert card["command"].startswith("wall-inspector train --env WallInspector/WallHover-v0 --algo ppo --timesteps 3072 "
                                      "--n-envs 4")
    training = card["training"]
    assert training["total_timesteps"] == 3072 and training["timesteps_this_run"] == 3072
    assert 0 < training["wall_time_s"] < training["command_wall_time_s"]
    assert training["steps_per_s"] == pytest.approx(3072 / training["wall_time_s"], rel=0.02)
    assert [row[0] for row in training["eval_curve"]] == [1024, 2048, 3072]
    metrics = card["evaluation"]["metrics"]
    assert metrics["episodes"] == 2 and metrics["mean_length_s"] > 0
    assert np.isfinite(metrics["wall_normal_rmse_m"])
    md = (out / "model_card.md").read_text()
    assert card["command"] in md and "wall_normal_rmse_m" in md
    split = training["time_split"]
    assert f"| time split (env steps / rest of the rollouts / updates and callbacks) | {split['env_step_s']} s" in md
    assert "| PyTorch threads (controllers.threads) | setting auto; updates: " in md


def test_cli_checkpoint_loads_and_flies(cli_run):
    policy = load_policy(cli_run / "best")
    assert isinstance(policy, TrainedPolicy) and policy.env_id == "WallInspector/WallHover-v0"
    metrics = evaluate_agent(policy, "WallInspector/WallHover-v0", seeds=[0, 1])
    assert metrics["episodes"] == 2 and metrics["mean_length_s"] > 0.05 and np.isfinite(metrics["mean_return"])
    # same seeds, same deterministic policy (loaded through model.zip this time): the evaluation repeats exactly
    again = evaluate_agent(load_policy(cli_run / "best" / "model.zip"), "WallInspector/WallHover-v0", seeds=[0, 1])
    assert again == metrics
    # and the model card's evaluation is this one, on the card's seeds
    card = json.loads((cli_run / "model_card.json").read_text())
    assert card["evaluation"]["env_kwargs"] == default_config("WallHover")["env_kwargs"]
    assert evaluate_agent(policy_factory(cli_run / "best"), "WallInspector/WallHover-v0", card["evaluation"]["env_kwargs"],
                          seeds=card["evaluation"]["seeds"]) == card["evaluation"]["metrics"]


def test_policy_factory_gives_a_predictor_for_an_env(cli_run):
    factory = policy_factory(cli_run)
    env = gym.make("WallInspector/WallHover-v0")
    obs, _ = env.reset(seed=0)
    action, state = factory(env).predict(obs)
    assert action.shape == (4,) and state is None
    env.close()


def test_resume_continues_from_the_latest_checkpoint(cli_run, tmp_path, capsys):
    import shutil

    run = tmp_path / "hover"
    shutil.copytree(cli_run, run)
    before = json.loads((run / "policy.json").read_text())["num_timesteps"]
    assert main(["train", "--resume", str(run), "--timesteps", "5120", "--no-progress", "--quiet"]) == 0
    after = json.loads((run / "policy.json").read_text())
    assert before == 3072 and after["num_timesteps"] == 5120
    card = json.loads((run / "model_card.json").read_text())
    assert card["training"]["resumed"] and card["training"]["timesteps_this_run"] == 2048
    assert card["training"]["total_wall_time_s"] > card["training"]["wall_time_s"]
    # the evaluation history spans both parts of the run
    assert [row[0] for row in card["training"]["eval_curve"]] == [1024, 2048, 3072, 4096, 5120]
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--timesteps", "9000", "--seed", "1"]) == 2
    assert "drop --seed" in capsys.readouterr().err


def test_refuses_to_overwrite_a_run(cli_run, capsys):
    assert main(["train", "--env", "WallHover-v0", "--out", str(cli_run), "--timesteps", "1000"]) == 2
    assert "already holds a run" in capsys.readouterr().err


def _stopped_early(out, argv):
    """A run folder as a run leaves it when it dies before its first checkpoint: its configuration, an empty
    TensorBoard folder, no model (what ``train --seed -1`` once left, or a Ctrl-C while its envs were built)."""
    from wall_inspector.train_arguments import _config_from_args, _training_arguments

    parser = __import__("argparse").ArgumentParser()
    _training_arguments(parser)
    config = _config_from_args(parser.parse_args(argv))
    out.mkdir(parents=True)
    (out / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    (out / "tb" / "ppo_1").mkdir(parents=True)
    (out / "tb" / "ppo_1" / "events.out.tfevents.0.first-attempt").write_bytes(b"")


def test_a_run_stopped_before_its_first_checkpoint_starts_again_by_the_same_command_or_resume(tmp_path, capsys):
    argv = ["--env", "WallInspector/WallHover-v0", "--timesteps", "2048", "--n-envs", "4", "--seed", "5", *TINY]
    for k, how in enumerate((["--out"], ["--resume"])):
        out = tmp_path / f"run{k}"
        _stopped_early(out, [*argv, "--out", str(out)])
        again = ["train", *argv, "--out", str(out)] if how == ["--out"] else ["train", "--resume", str(out), "--quiet",
                                                                               "--no-progress"]
        assert main(again) == 0
        assert "stopped before its first checkpoint; starting it again" in capsys.readouterr().err
        assert json.loads((out / "policy.json").read_text())["num_timesteps"] == 2048
        assert not list((out / "tb").rglob("*first-attempt"))  # the first attempt's log is gone, not mixed in
    # another configuration into such a folder is refused, and nothing in it changes
    out = tmp_path / "run2"
    _stopped_early(out, [*argv, "--out", str(out)])
    saved = (out / "config.yaml").read_bytes()
    assert main(["train", *argv[:-len(TINY)], "--set", "ppo.n_epochs=3", *TINY[6:], "--out", str(out)]) == 2
    assert "another configuration that stopped before its first checkpoint" in capsys.readouterr().err
    assert (out / "config.yaml").read_bytes() == saved


def test_a_second_run_into_a_folder_in_use_refuses_and_changes_nothing(cli_run, capsys):
    from wall_env.run_lock import RunLock

    before = {p: p.read_bytes() for p in cli_run.rglob("*") if p.is_file()}
    with RunLock(cli_run, "wall-inspector train"):  # a run holding the folder, as a running train does
        for argv in (["--resume", str(cli_run), "--timesteps", "9000"],
                     ["--env", "WallHover-v0", "--out", str(cli_run), "--timesteps", "4096"]):
            assert main(["train", *argv]) == 2
            err = capsys.readouterr().err
            assert "is in use by 'wall-inspector train'" in err and len(err.strip().splitlines()) == 1
    assert {p: p.read_bytes() for p in cli_run.rglob("*") if p.is_file()} == before


def test_loaded_policy_acts_exactly_like_the_trained_model(tmp_path, capsys):
    config = default_config("WallCircle")
    config.update(timesteps=1024, n_envs=2, n_workers=1, checkpoint_freq=0)
    config["ppo"].update(n_steps=512, batch_size=512, n_epochs=1)
    config["eval"].update(freq=100_000, episodes=1)
    config["card_eval"]["episodes"] = 1
    trained = train(config, tmp_path / "circle", progress_bar=True, verbose=0)
    assert "1.02k/1.02k" in capsys.readouterr().err  # the progress bar counted all 1024 env steps
    assert trained.normalizer.obs_rms.count > 1000  # statistics were learnt, not left at their start

    loaded = load_policy(tmp_path / "circle")  # the final checkpoint
    env = gym.make("WallInspector/WallCircle-v0")
    obs, _ = env.reset(seed=7)
    batch = [obs]
    for _ in range(60):
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        batch.append(obs)
        if terminated or truncated:
            obs, _ = env.reset()
    env.close()
    batch = np.asarray(batch)
    expected, _ = trained.model.predict(trained.normalizer.normalize_obs(batch), deterministic=True)
    actions, _ = loaded.predict(batch)
    np.testing.assert_array_equal(actions, expected)
    single, _ = loaded.predict(batch[5])
    expected_single, _ = trained.model.predict(trained.normalizer.normalize_obs(batch[5]), deterministic=True)
    assert single.shape == (4,)
    np.testing.assert_array_equal(single, expected_single)
    # the normalisation is really applied: raw observations give other actions
    raw, _ = trained.model.predict(batch, deterministic=True)
    assert not np.allclose(raw, expected)


def test_ship_puts_the_best_checkpoint_and_card_where_load_policy_finds_them(cli_run, tmp_path, monkeypatch):
    import agents.policy
    from agents.train import ship

    monkeypatch.setattr(agents.policy, "PRETRAINED_DIR", tmp_path / "pretrained")
    target = ship(cli_run, "WallInspector/WallHover-v0")
    assert target == tmp_path / "pretrained" / "wall_hover"
    # the run evaluated more than once, so its card carries the learning curve, which ships beside it
    assert sorted(p.name for p in target.iterdir()) == ["learning_curve.png", "model.zip", "model_card.json",
                                                       "model_card.md", "policy.json", "vecnormalize.pkl"]
    assert "](learning_curve.png)" in (target / "model_card.md").read_text()
    shipped = load_policy("WallHover-v0")
    best = load_policy(cli_run / "best")
    obs = np.asarray(json.loads((target / "policy.json").read_text())["check"]["observations"], dtype=np.float32)
    np.testing.assert_array_equal(shipped.predict(obs)[0], best.predict(obs)[0])


def test_policy_factory_without_source_picks_the_envs_own_task(cli_run, tmp_path, monkeypatch):
    import shutil

    import agents.policy

    monkeypatch.setattr(agents.policy, "PRETRAINED_DIR", tmp_path)
    shutil.copytree(cli_run / "best", tmp_path / "wall_hover")
    factory = policy_factory()
    env = gym.make("WallInspector/WallHover-v0")
    assert factory(env).path == tmp_path / "wall_hover"
    env.close()
    sweep = gym.make("WallInspector/WallSweep-v0")
    with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path / "wall_sweep_residual_pid"))):
        policy_factory(variant="residual_pid")(sweep)
    sweep.close()


def test_ctrl_c_saves_everything_and_resume_goes_on_from_the_same_step(tmp_path):
    """Ctrl-C (SIGINT to the whole process group, workers included, as a terminal sends it) to a
    real ``wall-inspector train`` process, then ``--resume``."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "run"
    command = [sys.executable, "-m", "wall_inspector.cli", "train", "--env", "WallHover-v0", "--timesteps", "1000000",
               "--n-envs", "2", "--workers", "1", "--set", "ppo.n_steps=256", "--set", "ppo.batch_size=256",
               "--set", "ppo.n_epochs=1", "--eval-freq", "512", "--eval-episodes", "1", "--no-progress", "--quiet",
               "--out", str(out)]
    # The child gets SIGINT's default disposition, as a terminal's foreground job has: a test run started
    # in the background by a non-interactive shell inherits SIGINT ignored, and Python then never turns
    # Ctrl-C into KeyboardInterrupt. faulthandler: a hang after Ctrl-C ends with every thread's stack
    # on stderr (SIGABRT below).
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                               env={**os.environ, "PYTHONFAULTHANDLER": "1"},
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        while not (out / "eval" / "evaluations.npz").exists():  # training is under way
            assert process.poll() is None and time.monotonic() < deadline, process.communicate()
            time.sleep(0.1)
        os.killpg(process.pid, signal.SIGINT)
        try:
            _, err = process.communicate(timeout=180)  # saving under a heavily loaded machine can be slow
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGABRT)
            _, err = process.communicate(timeout=60)
            pytest.fail(f"no exit within 180 s of Ctrl-C; the stacks at that moment:\n{err}")
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, err
    assert "Traceback" not in err
    saved = sorted((out / "checkpoints").iterdir())
    assert len(saved) == 1
    steps = json.loads((saved[0] / "policy.json").read_text())["num_timesteps"]
    assert steps >= 512 and saved[0].name == f"{steps:09d}"
    assert sorted(p.name for p in saved[0].iterdir()) == ["model.zip", "policy.json", "vecnormalize.pkl"]
    assert f"interrupted at {steps} env steps" in err and f"wall-inspector train --resume {out}" in err
    load_policy(saved[0])  # a complete, consistent checkpoint

    assert main(["train", "--resume", str(out), "--timesteps", str(steps + 512), "--no-progress", "--quiet"]) == 0
    card = json.loads((out / "model_card.json").read_text())
    assert card["training"]["resumed"] and card["training"]["timesteps_this_run"] == 512
    assert card["training"]["total_timesteps"] == steps + 512  # the count went on from the interrupted one
    assert json.loads((out / "policy.json").read_text())["num_timesteps"] == steps + 512


def test_short_run_keeps_to_its_steps_checkpoints_by_wall_time_and_an_honest_card(tmp_path, capsys):
    config = default_config("WallHover")
    config.update(timesteps=1500, n_envs=2, n_workers=1, checkpoint_freq=0, checkpoint_minutes=0.0005)  # 30 ms
    config["ppo"].update(n_steps=256, batch_size=256, n_epochs=1)
    config["eval"].update(freq=100_000, episodes=1)  # no evaluation during the run
    config["card_eval"]["episodes"] = 1
    trained = train(config, tmp_path / "hover", progress_bar=True, verbose=0)
    bar = capsys.readouterr().err
    # whole rollouts of 512 steps within the 1500 asked for: 1024, and the bar ends at its total
    assert trained.model.num_timesteps == 1024 and trained.card["training"]["total_timesteps"] == 1024
    assert "1.02k/1.02k" in bar and "1.5k" not in bar and "1.54k" not in bar
    # checkpoints by wall time although checkpoints by steps are off
    saved = sorted((tmp_path / "hover" / "checkpoints").iterdir())
    assert len(saved) >= 2 and all((folder / "vecnormalize.pkl").is_file() for folder in saved)
    assert "nan" not in trained.card["checkpoint"]
    assert "no evaluation ran during training" in trained.card["checkpoint"]
    git = trained.card["training"]
    if git["git_commit"]:  # inside a checkout: the files that differed are listed, not hidden
        assert isinstance(git["git_uncommitted"], list)
        md = (tmp_path / "hover" / "model_card.md").read_text()
        assert all(name in md for name in git["git_uncommitted"])


def test_resumed_run_is_not_shipped_from_a_dirty_tree_either(cli_run, monkeypatch, capsys):
    import agents.train

    monkeypatch.setattr(agents.train, "git_state", lambda: {"commit": "abc", "uncommitted": ["wall_env/env.py"]})
    before = sorted(p.name for p in cli_run.rglob("*"))
    assert main(["train", "--resume", str(cli_run), "--timesteps", "9216", "--ship"]) == 2
    assert "wall_env/env.py differ from it; commit first" in capsys.readouterr().err
    assert sorted(p.name for p in cli_run.rglob("*")) == before  # nothing trained, nothing written


def test_learning_rate_falls_linearly_to_its_final_value_over_the_planned_steps(tmp_path):
    config = default_config("WallHover")
    config.update(timesteps=2048, n_envs=2, n_workers=1, checkpoint_freq=0, checkpoint_minutes=0.0)
    config["ppo"].update(n_steps=256, batch_size=256, n_epochs=1, learning_rate=1.0e-3, learning_rate_final=1.0e-4)
    config["eval"].update(freq=100_000, episodes=1)
    config["card_eval"]["episodes"] = 1
    checks_before = torch.distributions.Distribution._validate_args
    trained = train(config, tmp_path / "hover", progress_bar=False, verbose=0)
    # distributions ran unchecked during learning only; Adam runs fused with SB3's eps
    assert torch.distributions.Distribution._validate_args == checks_before
    assert trained.model.policy.optimizer.defaults["fused"] and trained.model.policy.optimizer.defaults["eps"] == 1e-5
    # SB3 gives the schedule the share of the planned steps still to go: 1 at the start, 0 at the end
    schedule = trained.model.lr_schedule
    assert [schedule(f) for f in (1.0, 0.5, 0.0)] == pytest.approx([1.0e-3, 5.5e-4, 1.0e-4])
    # the last of the four updates (after 2048 of 2048 steps) ran at the final rate
    assert trained.model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(1.0e-4)
    # the schedule is saved with the model, so a resumed run goes on along it
    loaded, _, _ = load_model(tmp_path / "hover")
    assert loaded.lr_schedule(0.25) == pytest.approx(3.25e-4)


def test_final_learning_rate_above_the_initial_one_is_refused():
    config = default_config("WallHover")
    config["ppo"].update(learning_rate=1.0e-3, learning_rate_final=2.0e-3)
    with pytest.raises(ValueError, match=r"ppo.learning_rate_final must be in \[0.0, 0.001\], got 0.002"):
        validate_config(config)


class _Watch:
    """A CpuWatch stand-in: other processes' load as a test sets it."""

    def __init__(self, busy: float, cpus: int = 2):
        self.busy, self.cpus = busy, list(range(cpus))

    def busy_elsewhere(self) -> float:
        return self.busy


def test_rollouts_and_updates_run_on_their_own_thread_counts():
    from agents.callbacks import TorchThreads

    before = torch.get_num_threads()
    try:
        threads = TorchThreads(rollout=1, update=2, n_envs=32)
        threads.watch = _Watch(busy=1.9)  # explicit settings win whatever the machine does
        threads.on_rollout_start()
        assert torch.get_num_threads() == 1
        threads.on_rollout_end()
        assert torch.get_num_threads() == 2
        assert threads.report()["first_choice"]["update"]["reason"] == "set explicitly"
    finally:
        torch.set_num_threads(before)


def test_auto_threads_follow_the_free_cores_update_by_update():
    from agents.callbacks import TorchThreads

    before = torch.get_num_threads()
    try:
        threads = TorchThreads(rollout="auto", update="auto", n_envs=32)
        threads.watch = watch = _Watch(busy=0.05)
        used = []
        for busy in (0.05, 1.0, 0.6, 0.1):  # quiet, a neighbour takes a core, it eases, it leaves
            watch.busy = busy
            threads.on_rollout_start()
            assert torch.get_num_threads() == 1  # 32 observations: one thread, whatever is free
            threads.on_rollout_end()
            used.append(torch.get_num_threads())
        # 1.95 free: two; 1.0 free: one; 1.4 free (less than 0.75 of a core left for a second): one; 1.9: two
        assert used == [2, 1, 1, 2]
        report = threads.report()
        assert report["updates_on_threads"] == {"1": 2, "2": 2} and report["rollouts_on_threads"] == {"1": 4}
        assert report["busy_elsewhere_cores"]["max"] == 1.0
        assert "1.95 of 2 allowed cores free" in report["first_choice"]["update"]["reason"]
        capped = TorchThreads(rollout="auto", update="auto", n_envs=32, most=1)  # a Ray trial given one CPU
        capped.watch = _Watch(busy=0.0)
        capped.on_rollout_end()
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)


def test_a_run_writes_its_thread_choice_into_the_model_card(tmp_path):
    config = default_config("WallHover")
    config.update(timesteps=1024, n_envs=2, n_workers=1, checkpoint_freq=0, checkpoint_minutes=0.0)
    config["ppo"].update(n_steps=256, batch_size=256, n_epochs=1)
    config["eval"].update(freq=100_000, episodes=1)
    config["card_eval"]["episodes"] = 1
    card = train(config, tmp_path / "hover", progress_bar=False, verbose=0).card
    threads = card["training"]["threads"]
    assert threads["settings"] == {"rollout": "auto", "update": "auto"}
    assert threads["at_start"]["setting"] == "auto" and 1 <= threads["at_start"]["threads"] <= 2
    assert sum(threads["updates_on_threads"].values()) == 2  # two rollouts of 512 steps, an update after each
    assert "allowed cores free" in threads["first_choice"]["update"]["reason"]
    forced = train({**config, "torch_threads": 1}, tmp_path / "forced", progress_bar=False, verbose=0).card
    assert forced["training"]["threads"]["updates_on_threads"] == {"1": 2}
