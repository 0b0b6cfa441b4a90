"""``--ray``: compare and tune on a local two-node Ray cluster give what the local commands give.

The cluster (``ray.cluster_utils.Cluster``: a head and a worker node, one CPU each, no
dashboard) is started once for the module and shut down at its end.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import optuna
import pytest
import ray
from ray.cluster_utils import Cluster

from wall_inspector.cli import main as cli_main

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cluster():
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    try:
        yield cluster
    finally:
        if ray.is_initialized():
            ray.shutdown()
        cluster.shutdown()


def test_nothing_imports_ray_without_the_flag():
    code = ("import argparse, sys, controllers.paper_tables, controllers.tuning, agents.train; "
            "from wall_inspector import compare, tune, train, bench_ray, ray_backend, tune_on_ray, train_on_ray; "
            "[m.add_arguments(argparse.ArgumentParser()) for m in (compare, tune, train, bench_ray)]; "
            "print('ray' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


@pytest.mark.parametrize("args, message", [
    (["--ray-cpus", "2"], "--ray-cpus needs --ray"),
    (["--ray", "auto", "--ray-cpus", "2"], "--ray-cpus sets the CPUs of an embedded Ray"),
    (["--ray", "--ray-cpus", "0"], "--ray-cpus must be in [1, 4096]"),
])
def test_bad_ray_options_are_one_line_usage_errors(tmp_path, capsys, args, message):
    assert cli_main(["compare", "--out", str(tmp_path / "x"), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "x").exists()


def test_compare_on_a_two_node_cluster_writes_the_local_json_byte_for_byte(cluster, tmp_path):
    common = ["compare", "--tables", "both", "--seeds-i", "1", "--seeds-ii", "2", "--duration", "0.4", "--no-progress",
              "--no-authors"]
    assert cli_main([*common, "--out", str(tmp_path / "local")]) == 0
    assert cli_main([*common, "--out", str(tmp_path / "ray"), "--ray", cluster.address]) == 0
    local, remote = (tmp_path / "local" / "results.json").read_bytes(), (tmp_path / "ray" / "results.json").read_bytes()
    assert local == remote
    assert (tmp_path / "local" / "tables.md").read_bytes() == (tmp_path / "ray" / "tables.md").read_bytes()
    data = json.loads(local)
    # 3 Table I rows x 5 policies (PID, MPC, SC-MPC both forms, PPO) + Table II's 7 (and PPO + SC-MPC and
    # SC-MPC distilled, the agent that learned from SC-MPC: a row of its own)
    assert len(data["runs"]) == 3 * 5 + 7
    assert [r["policy"] for r in data["runs"]].count("SC-MPC distilled (DAgger)") == 1
    assert [e["seed"] for e in data["runs"][-1]["per_episode"]] == [0, 1]
    assert all(run["metrics"]["steps"] == 40 * len(run["per_episode"]) for run in data["runs"])
    assert "solve_ms" not in local.decode()  # timing lives in timing.json
    timing = json.loads((tmp_path / "ray" / "timing.json").read_text())
    sc = next(r for r in timing["runs"] if r["policy"] == "SC-MPC" and "Table II" in r["scenario"])
    assert sc["solve_ms"]["count"] == 80 and 0 < sc["solve_ms"]["median"] < 100
    assert [e["solve_ms"]["count"] for e in sc["per_episode"]] == [40, 40]
    assert timing["flights"]["count"] == 3 * 5 + 7 * 2 and timing["flights"]["executor"].startswith("Ray")
    assert len(timing["flights"]["seconds_each"]) == 29 and all(s > 0 for s in timing["flights"]["seconds_each"])
    assert not ray.is_initialized()  # the command disconnected; the cluster goes on


def test_tune_through_ray_tunes_optuna_searcher(cluster, tmp_path):
    out = tmp_path / "tune"
    code = cli_main(["tune", "--env", "WallHover-v0", "--method", "pid", "--budget-trials", "3", "--seeds", "1000",
                     "--heldout-seeds", "2000", "--set", "duration=0.3", "--out", str(out), "--no-progress",
                     "--ray", cluster.address])
    assert code == 0
    study = optuna.load_study(study_name="tune", storage=f"sqlite:///{out / 'study.db'}")
    trials = study.trials
    assert [t.state for t in trials] == [optuna.trial.TrialState.COMPLETE] * 3
    assert study.user_attrs["env_steps"] == 3 * 30
    from controllers.presets import load_preset
    from controllers.tuning import SearchSpace

    space = SearchSpace("pid", load_preset("paper", method="pid").methods["pid"])
    authors = space.values_of(space.base)
    assert any(t.params == pytest.approx(authors) for t in trials)  # the authors' settings are a trial
    preset = load_preset(out / "preset.yaml")
    assert preset.provenance["used"]["trials"] == 3 and preset.provenance["used"]["env_steps"] == 90
    best = min(trials, key=lambda t: t.value)
    assert preset.methods["pid"]["kp"][0] == pytest.approx(best.params["kp_xy"])
    report = json.loads((out / "report.json").read_text())
    assert report["best_trial"] == best.number and len(report["trials"]) == 3


# ====================================================================== train --ray
STEPS, EVERY = 40960, 4096  # a few seconds of batched training with ten checkpoints: a restart resumes mid-run
TINY_TRAIN = ["train", "--env", "WallHover-v0", "--timesteps", str(STEPS), "--n-envs", "2", "--workers", "1",
              "--set", "ppo.n_steps=128", "--set", "ppo.batch_size=256", "--set", "ppo.n_epochs=1",
              "--set", "card_eval.episodes=1", "--set", "env_kwargs.duration=1.0", "--eval-freq", "1000000",
              "--checkpoint-freq", str(EVERY), "--no-progress", "--quiet"]


def test_train_plans_one_run_per_seed_and_sweep_point(tmp_path):
    import argparse

    from wall_inspector import train as train_command
    from wall_inspector.train_on_ray import plan

    space = tmp_path / "space.yaml"
    space.write_text("ppo.learning_rate: [1.0e-4, 3.0e-4]\nppo.n_epochs: [1]\n")
    parser = argparse.ArgumentParser()
    train_command.add_arguments(parser)
    args = parser.parse_args([*TINY_TRAIN[1:], "--seeds", "0-2", "--sweep", str(space), "--out", str(tmp_path / "o"),
                              "--ray"])
    runs = plan(args)
    assert len(runs) == 6 and len({r["name"] for r in runs}) == 6
    assert sorted((r["config"]["seed"], r["config"]["ppo"]["learning_rate"]) for r in runs) == [
        (s, lr) for s in (0, 1, 2) for lr in (1e-4, 3e-4)]
    assert all(r["config"]["ppo"]["n_epochs"] == 1 for r in runs)
    assert runs[0]["command"].startswith(f"wall-inspector train --env WallInspector/WallHover-v0 --algo ppo --timesteps {STEPS}")


@pytest.mark.parametrize("args, message", [
    (["--seeds", "0-1"], "--seeds needs --ray"),
    (["--ray", "--seeds", "x"], "--seeds must be seeds such as"),
    (["--ray", "--sweep", "/nonexistent.yaml"], "--sweep /nonexistent.yaml: no such file"),
    (["--ray", "--ship"], "--ship is for a single run"),
])
def test_bad_train_ray_options_are_one_line_usage_errors(tmp_path, capsys, args, message):
    out = tmp_path / "runs"
    assert cli_main([*TINY_TRAIN, "--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and not out.exists()


class _KillAtFirstCheckpoint:
    """A Ray Tune callback that SIGKILLs the worker of the first trial whose checkpoint Ray Tune takes.

    It acts on the event itself, not on a guess of how long training takes: a function trial
    waits inside ``tune.report`` until the driver asks for its next result, and Ray Tune calls
    ``on_checkpoint`` in the driver before it does, so the trial is still mid-run, blocked at
    that checkpoint, when it is killed, however fast the machine trains."""

    def __init__(self):
        from ray import tune

        class Callback(tune.Callback):
            def on_checkpoint(inner, iteration, trials, trial, checkpoint, **info):
                result = trial.last_result
                if not self.killed and not result.get("finished"):
                    os.kill(int(result["pid"]), signal.SIGKILL)
                    self.killed.append((trial.trial_id, int(result["timesteps"])))

        self.killed: list = []
        self.callback = Callback()


def test_train_sweep_of_two_trials_survives_a_killed_worker(cluster, tmp_path):
    import argparse

    from wall_inspector import train as train_command
    from wall_inspector import train_on_ray

    space = tmp_path / "space.yaml"
    space.write_text("ppo.learning_rate: [3.0e-4, 1.0e-3]\n")
    out = tmp_path / "runs"
    parser = argparse.ArgumentParser()
    train_command.add_arguments(parser)
    args = parser.parse_args([*TINY_TRAIN[1:], "--sweep", str(space), "--out", str(out), "--ray", cluster.address,
                              "--cpus-per-trial", "1"])
    killer = _KillAtFirstCheckpoint()
    code = train_on_ray.run(args, callbacks=[killer.callback])
    assert code == 0 and len(killer.killed) == 1 and killer.killed[0][1] == EVERY
    rows = json.loads((out / "summary.json").read_text())["runs"]
    assert [r["set"] for r in rows] == [["ppo.learning_rate=0.0003"], ["ppo.learning_rate=0.001"]]
    assert all(r["timesteps"] == STEPS for r in rows)
    restarted = [r for r in rows if r["restarts"]]
    assert len(restarted) == 1 and EVERY <= restarted[0]["resumed_from"] < STEPS  # from its last checkpoint
    for r in rows:
        card = json.loads((out / r["name"] / "model_card.json").read_text())
        assert card["training"]["total_timesteps"] == STEPS
        assert card["training"]["resumed"] is bool(r["restarts"])
        assert card["config"]["ppo"]["learning_rate"] in (3e-4, 1e-3)
        assert (out / r["name"] / "best" / "model.zip").is_file()
    assert "| [ppo.learning_rate=0.001](ppo.learning_rate=0.001/model_card.md) |" in (out / "summary.md").read_text()


def test_makespan_of_the_plan_is_list_scheduling():
    from wall_inspector.bench_ray import makespan

    assert makespan([3.0, 1.0, 1.0, 1.0], 2) == 3.0  # one slot takes the 3 s flight, the other the three 1 s ones
    assert makespan([1.0] * 10, 4) == 3.0 and makespan([2.0] * 3, 16) == 2.0 and makespan([5.0, 5.0], 1) == 10.0
