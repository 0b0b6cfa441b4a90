"""``wall-inspector bench-train``: how long training takes to reach the target, and how it stands a busy core.

Two measurements, each of the project's own training command run as a user would run it
(``wall-inspector train`` in a child process, its model card read back):

**Time to target** (``--seeds``): one training run per seed with the task's defaults (plus
``--algo``, ``--set``), its model card evaluated on ``--eval-seeds`` (the Table II scenario for the
sweep: task defaults, command noise on). A run reaches the target when its wall-normal RMSE is
at most ``--target-cm`` with no contact step; its time is the training wall time of its model
card (demonstrations, cloning or distillation included; start-up and the final evaluation not).
Printed and written: each run's time, env steps, env steps/s, time split and thread choice, and
over the runs the median and the worst time (the worst is "not reached" when a run missed).

**A busy core** (``--busy-steps``): the same training for a fixed number of env steps (no
evaluation) twice, on the machine as it is and with one core kept busy by a spinning process
that this command starts before and stops after the run (``python -c "while True: pass"``);
the ratio of their env steps per second says how much of its speed training keeps when a
neighbour takes a core.

The load average before and after is recorded beside the figures; figures on a machine shared
with other work are indicative only. ``--json FILE`` writes everything printed.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

DEFAULT_SEEDS = "1000-1004"
DEFAULT_EVAL_SEEDS = "5000-5009"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default="WallInspector/WallSweep-v0", help="task (default: the sweep, Table II)")
    parser.add_argument("--algo", choices=["ppo", "dagger"], default="ppo",
                        help="ppo: learned from scratch (default); dagger: SC-MPC as the teacher")
    parser.add_argument("--seeds", default=DEFAULT_SEEDS,
                        help=f"training seeds of the time-to-target runs, e.g. 1000-1004 or 3,7 (default {DEFAULT_SEEDS}); "
                             "'none' skips them")
    parser.add_argument("--eval-seeds", default=DEFAULT_EVAL_SEEDS,
                        help=f"evaluation seeds of each run's model card, a range A-B (default {DEFAULT_EVAL_SEEDS})")
    parser.add_argument("--target-cm", type=float, default=0.5,
                        help="wall-normal RMSE a run must reach, with no contact (default 0.5 cm)")
    parser.add_argument("--busy-steps", type=int, default=300_000,
                        help="env steps of each busy-core throughput run (default 300000; 0 skips the measurement)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="configuration override passed to every training run (repeatable)")
    parser.add_argument("--out", default=None, help="folder for the runs (default: a temporary folder, removed)")
    parser.add_argument("--json", default=None, metavar="FILE", help="write the figures as JSON")


def _seed_range(text: str, flag: str) -> list[int]:
    from wall_inspector.tune import parse_seeds

    return list(parse_seeds(text, flag))


def _check(args: argparse.Namespace) -> tuple[list[int], range]:
    seeds = [] if args.seeds.strip().lower() == "none" else _seed_range(args.seeds, "--seeds")
    first, sep, last = args.eval_seeds.partition("-")
    try:
        eval_seeds = range(int(first), int(last) + 1) if sep else range(int(first), int(first) + 1)
    except ValueError:
        raise ValueError(f"--eval-seeds must be a range A-B of whole numbers, got {args.eval_seeds!r}") from None
    if len(eval_seeds) < 1 or eval_seeds.start < 0:
        raise ValueError(f"--eval-seeds must be a non-empty range of seeds >= 0, got {args.eval_seeds!r}")
    if not 0.0 < args.target_cm <= 100.0:
        raise ValueError(f"--target-cm must be in (0, 100], got {args.target_cm}")
    if not (args.busy_steps == 0 or 10_000 <= args.busy_steps <= 100_000_000):
        raise ValueError(f"--busy-steps must be 0 (skip) or in [10000, 100000000], got {args.busy_steps}")
    if args.out and Path(args.out).exists() and any(Path(args.out).iterdir()):
        raise ValueError(f"--out {args.out} is not empty; choose a new folder for the runs")
    if args.algo != "ppo" and args.busy_steps:
        args.busy_steps = 0  # a distillation has no PPO steps to count per second: only its time to target
        print("--algo dagger: no busy-core throughput (it has no PPO steps); time to target only", file=sys.stderr)
    if not seeds and not args.busy_steps:
        raise ValueError("nothing to measure: --seeds none and --busy-steps 0")
    from agents import train as agents_train
    from agents.config import apply_overrides, default_config

    config = default_config(args.env)
    config["algo"] = args.algo
    apply_overrides(config, args.set)  # a bad --set stops the command here
    if args.busy_steps and args.algo == "ppo":
        agents_train.planned_timesteps({**config, "timesteps": args.busy_steps})
    return seeds, eval_seeds


def _load() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


def _train(args: argparse.Namespace, out: Path, extra: list[str]) -> dict[str, Any]:
    """One ``wall-inspector train`` in a child process; its model card."""
    command = [sys.executable, "-m", "wall_inspector.cli", "train", "--env", args.env, "--algo", args.algo,
               "--out", str(out), "--no-progress", "--quiet", *extra]
    for item in args.set:
        command += ["--set", item]
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"training failed (exit {done.returncode}): {tail[0]}")
    card = json.loads((out / "model_card.json").read_text())
    card["training"]["process_wall_time_s"] = round(time.perf_counter() - started, 2)
    return card


def _run_row(seed: int, card: dict[str, Any], target_m: float) -> dict[str, Any]:
    from agents.checkpoints import training_env_steps

    t, m = card["training"], card["evaluation"]["metrics"]
    reached = bool(m["wall_normal_rmse_m"] <= target_m and m["collisions"] == 0)
    steps = training_env_steps(t)  # PPO's, a warm start's demonstrations and a teacher's labelled flights
    return {"seed": seed, "reached": reached, "training_wall_time_s": t["wall_time_s"],
            "command_wall_time_s": t.get("command_wall_time_s"), "env_steps": steps,
            "env_steps_per_s": round(steps / max(float(t["wall_time_s"]), 1e-9), 1),
            "wall_normal_rmse_cm": round(100 * m["wall_normal_rmse_m"], 3),
            "collisions": m["collisions"], "completed": m["completed"], "time_split": t.get("time_split"),
            "threads": t.get("threads"), "teacher_labels": (t.get("teacher") or {}).get("labels")}


def time_to_target(args: argparse.Namespace, seeds: list[int], eval_seeds: range, folder: Path) -> dict[str, Any]:
    """One training run per seed (module docstring); rows and their median and worst."""
    rows = []
    for seed in seeds:
        card = _train(args, folder / f"seed{seed}", ["--seed", str(seed), "--set", f"card_eval.seed={eval_seeds.start}",
                                                      "--set", f"card_eval.episodes={len(eval_seeds)}"])
        row = _run_row(seed, card, args.target_cm / 100.0)
        rows.append(row)
        print(f"seed {seed}: {row['training_wall_time_s']:.1f} s, {row['env_steps']:,} env steps "
              f"({row['env_steps_per_s']:,.0f}/s), wall-normal RMSE {row['wall_normal_rmse_cm']:.3f} cm, "
              f"collisions {row['collisions']}: {'target reached' if row['reached'] else 'target NOT reached'}", flush=True)
    times = [r["training_wall_time_s"] for r in rows]
    return {"target": f"wall-normal RMSE <= {args.target_cm} cm and no contact on seeds {eval_seeds.start}-{eval_seeds.stop - 1}",
            "runs": rows, "reached": f"{sum(r['reached'] for r in rows)} of {len(rows)}",
            "median_s": round(statistics.median(times), 2) if times else None,
            "worst_s": (round(max(times), 2) if all(r["reached"] for r in rows) else None) if times else None,
            "slowest_run_s": round(max(times), 2) if times else None}


class Spinner:
    """A child process that keeps one core busy (a Python busy loop) until :meth:`stop`."""

    def __init__(self) -> None:
        self.process: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        self.process = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdout.write('spinning\\n'); "
                                         "sys.stdout.flush()\nwhile True: pass"], stdout=subprocess.PIPE)
        assert self.process.stdout is not None
        self.process.stdout.readline()  # it runs: the busy loop comes right after this line

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait(timeout=30)
        self.process = None

    def __enter__(self) -> Spinner:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def busy_core(args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    """Env steps/s of ``--busy-steps`` of training alone and beside a spinning process."""
    extra = ["--seed", "0", "--timesteps", str(args.busy_steps), "--eval-freq", str(10 * args.busy_steps),
             "--checkpoint-freq", "0", "--checkpoint-minutes", "0", "--set", "card_eval.episodes=1"]
    out: dict[str, Any] = {"env_steps": args.busy_steps}
    for name in ("quiet", "one_core_busy"):
        load = _load()
        if name == "quiet":
            card = _train(args, folder / name, extra)
        else:
            with Spinner():
                card = _train(args, folder / name, extra)
        t = card["training"]
        out[name] = {"env_steps_per_s": t["steps_per_s"], "training_wall_time_s": t["wall_time_s"],
                     "time_split": t.get("time_split"), "threads": t.get("threads"), "load_average_before": load}
        print(f"{name.replace('_', ' ')}: {t['steps_per_s']:,.0f} env steps/s ({t['wall_time_s']:.1f} s for "
              f"{t['total_timesteps']:,} steps; updates on threads {(t.get('threads') or {}).get('updates_on_threads')})",
              flush=True)
    out["ratio"] = round(out["one_core_busy"]["env_steps_per_s"] / max(out["quiet"]["env_steps_per_s"], 1e-9), 3)
    print(f"with one core busy, training keeps {100 * out['ratio']:.0f} % of its quiet throughput")
    return out


def run(args: argparse.Namespace) -> int:
    try:
        seeds, eval_seeds = _check(args)
    except (ValueError, FileNotFoundError) as exc:
        raise SystemExit(str(exc)) from None
    figures: dict[str, Any] = {"env": args.env, "algo": args.algo, "set": list(args.set),
                               "machine": f"{os.cpu_count()} CPUs, affinity {len(os.sched_getaffinity(0))}",
                               "load_average_before": _load()}
    with tempfile.TemporaryDirectory(prefix="bench-train-") as tmp:
        folder = Path(args.out) if args.out else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        try:
            if seeds:
                figures["time_to_target"] = time_to_target(args, seeds, eval_seeds, folder)
            if args.busy_steps:
                figures["busy_core"] = busy_core(args, folder)
        except RuntimeError as exc:
            print(f"wall-inspector bench-train: {exc}", file=sys.stderr)
            return 1
    figures["load_average_after"] = _load()
    ttt = figures.get("time_to_target")
    if ttt:
        worst = f"{ttt['worst_s']:.1f} s" if ttt["worst_s"] is not None else f"not reached (slowest run {ttt['slowest_run_s']:.1f} s)"
        print(f"time to target ({ttt['target']}): reached in {ttt['reached']} runs; median {ttt['median_s']:.1f} s, "
              f"worst {worst}")
    print(f"load average {figures['load_average_before']} before, {figures['load_average_after']} after, "
          f"on {figures['machine']}")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=2))
        print(f"wrote {args.json}")
    return 0
