"""wall-inspector bench-train: its arguments, its competing process, and its figures from real model cards."""

from __future__ import annotations

import json
import os
import time

import pytest

from wall_inspector import bench_train
from wall_inspector.cli import main


@pytest.mark.parametrize("argv, message", [
    (["--target-cm", "0"], "--target-cm must be in (0, 100], got 0.0"),
    (["--busy-steps", "50"], "--busy-steps must be 0 (skip) or in [10000, 100000000], got 50"),
    (["--seeds", "none", "--busy-steps", "0"], "nothing to measure"),
    (["--eval-seeds", "a-b"], "--eval-seeds must be a range A-B of whole numbers, got 'a-b'"),
    (["--set", "ppo.n_steps=0"], "ppo.n_steps must be a positive integer, got 0"),
    (["--env", "NoSuchTask-v0"], "NoSuchTask"),
])
def test_bad_arguments_stop_the_command_with_one_line(argv, message, capsys):
    assert main(["bench-train", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="reads the spinner's CPU time from /proc")
def test_the_competing_process_spins_until_it_is_stopped():
    spinner = bench_train.Spinner()
    spinner.start()
    process = spinner.process
    assert process is not None and process.poll() is None
    first = _ticks(process.pid)
    while _ticks(process.pid) < first + 5:  # it burns CPU: wait for five clock ticks of it
        time.sleep(0.01)
    spinner.stop()
    assert process.poll() is not None and spinner.process is None
    spinner.stop()  # stopping twice is harmless


def _ticks(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as handle:
        fields = handle.read().rpartition(")")[2].split()
    return float(fields[11]) + float(fields[12])


def test_median_and_worst_come_from_the_runs_and_a_miss_has_no_worst(monkeypatch, tmp_path):
    cards = {1: (30.0, 0.004, 0), 2: (50.0, 0.003, 0), 3: (40.0, 0.0045, 0), 4: (20.0, 0.009, 0), 5: (25.0, 0.002, 3)}

    def fake_train(args, out, extra):
        seed = int(extra[extra.index("--seed") + 1])
        seconds, rmse, contacts = cards[seed]
        return {"training": {"wall_time_s": seconds, "total_timesteps": 1000, "steps_per_s": 1000 / seconds},
                "evaluation": {"metrics": {"wall_normal_rmse_m": rmse, "collisions": contacts, "completed": 1.0}}}

    monkeypatch.setattr(bench_train, "_train", fake_train)
    args = type("Args", (), {"target_cm": 0.5})()
    result = bench_train.time_to_target(args, [1, 2, 3], range(5000, 5010), tmp_path)
    assert result["reached"] == "3 of 3" and result["median_s"] == 40.0 and result["worst_s"] == 50.0
    missed = bench_train.time_to_target(args, [1, 4, 5], range(5000, 5010), tmp_path)
    # seed 4 is too far from the wall's reference, seed 5 touched it: no worst time, only the slowest run
    assert missed["reached"] == "1 of 3" and missed["worst_s"] is None and missed["slowest_run_s"] == 30.0
    assert [r["reached"] for r in missed["runs"]] == [True, False, False]


def test_one_real_run_from_seed_to_json(tmp_path, capsys):
    out = tmp_path / "figures.json"
    code = main(["bench-train", "--env", "WallInspector/WallHover-v0", "--seeds", "7", "--busy-steps", "0",
                 "--eval-seeds", "3-4", "--target-cm", "50", "--json", str(out), "--out", str(tmp_path / "runs"),
                 "--set", "timesteps=1024", "--set", "n_envs=2", "--set", "ppo.n_steps=256", "--set", "ppo.batch_size=256",
                 "--set", "ppo.n_epochs=1", "--set", "eval.episodes=1"])
    assert code == 0
    figures = json.loads(out.read_text())
    run = figures["time_to_target"]["runs"][0]
    card = json.loads((tmp_path / "runs" / "seed7" / "model_card.json").read_text())
    assert run["seed"] == 7 and run["env_steps"] == 1024 == card["training"]["total_timesteps"]
    assert card["evaluation"]["seeds"] == [3, 4]  # the card was evaluated on the seeds asked for
    assert run["training_wall_time_s"] == card["training"]["wall_time_s"] > 0
    assert run["wall_normal_rmse_cm"] == round(100 * card["evaluation"]["metrics"]["wall_normal_rmse_m"], 3)
    assert figures["time_to_target"]["median_s"] == run["training_wall_time_s"]
    assert len(figures["load_average_before"]) == 3
    printed = capsys.readouterr().out
    assert "seed 7:" in printed and "time to target" in printed and f"wrote {out}" in printed
