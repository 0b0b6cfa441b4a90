"""``wall-inspector train --ray``: training runs as Ray Tune trials, each resuming from its last checkpoint.

The runs: one per seed of ``--seeds`` and/or one per point of the grid of ``--sweep
SPACE.yaml`` (a mapping of configuration keys, as ``--set`` takes them, to lists of
values; the grid is their product), each on top of the configuration the other flags
make. Every run's configuration is checked before Ray starts.

Each trial is :func:`agents.train.train` itself in a Ray worker: every periodic checkpoint
it writes (``--checkpoint-freq``, ``--checkpoint-minutes``) is handed to Ray Tune with the
run's ``config.yaml`` and best model; when a worker dies (a node lost, a process killed),
Ray Tune starts the trial again (up to ``--max-failures`` times) from its last
checkpoint, and the trial continues it with train's own resume (``train(..., resume=True)``),
at the same step count. The finished runs are collected in ``OUT/``: ``OUT/<run>/`` holds
each run's final and best checkpoints, ``config.yaml``, evaluation history and model card;
``OUT/summary.json`` and ``OUT/summary.md`` list the runs with their model cards' figures.
Ray Tune's own records go to ``OUT/ray/``; on a cluster of several machines ``OUT`` must
be on storage every machine sees (a network filesystem), where Ray Tune keeps the
checkpoints.

Resource hints: each trial reserves ``--cpus-per-trial`` CPUs (default
:func:`cpus_per_run`: with ``--vector subprocess`` the run's ``n_workers``, the processes
its environments step in; with the batched env, all in the learner's process, the more of
its ``torch_threads`` and ``rollout_torch_threads`` when set, one when they are ``"auto"``), so Ray never
starts more runs on a node than its CPUs carry; within a trial, the thread rule of
:mod:`controllers.threads` never takes more PyTorch threads than the CPUs reserved for it.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

_COPIED = ("config.yaml", "model.zip", "vecnormalize.pkl", "policy.json", "model_card.json", "model_card.md")
_COPIED_FOLDERS = ("best", "eval")


def _sweep_points(path: str) -> list[list[str]]:
    """The grid of ``--sweep`` as lists of ``--set`` items."""
    import yaml

    file = Path(path)
    if not file.is_file():
        raise ValueError(f"--sweep {path}: no such file")
    try:
        space = yaml.safe_load(file.read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f"--sweep {path}: not YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(space, dict) or not space:
        raise ValueError(f"--sweep {path} must be a mapping of configuration keys to lists of values, "
                         "e.g. {ppo.learning_rate: [1.0e-4, 3.0e-4]}")
    for key, values in space.items():
        if not isinstance(values, list) or not values:
            raise ValueError(f"--sweep {path}: {key} must have a non-empty list of values, got {values!r}")
    keys = list(space)
    return [[f"{k}={json.dumps(v)}" for k, v in zip(keys, point)] for point in itertools.product(*space.values())]


def _name(items: list[str]) -> str:
    text = "_".join(items) or "run"
    return "".join(c if c.isalnum() or c in "-_.=" else "-" for c in text)[:100]


def plan(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Every run's name, ``--set`` items, configuration and repeat command; ``ValueError`` for bad input."""
    from agents import train as agents_train
    from agents.config import apply_overrides
    from wall_env.validation import check_output_folder
    from wall_inspector.train_arguments import _command, _config_from_args
    from wall_inspector.tune import parse_seeds

    if not args.out:
        raise ValueError("--out is required (the folder that collects every run)")
    for flag, value in (("--resume", args.resume), ("--ship", args.ship or None)):
        if value is not None:
            raise ValueError(f"{flag} is for a single run; --ray resumes its trials itself and ships nothing")
    if not 0 <= args.max_failures <= 100:
        raise ValueError(f"--max-failures must be in [0, 100], got {args.max_failures}")
    if args.cpus_per_trial is not None and not 0.01 <= args.cpus_per_trial <= 1024:
        raise ValueError(f"--cpus-per-trial must be in [0.01, 1024], got {args.cpus_per_trial}")
    out = Path(args.out)
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"--out {out} is not empty; choose a new folder for the runs")
    check_output_folder(out, "--out")
    seeds = [[f"seed={s}"] for s in parse_seeds(args.seeds, "--seeds")] if args.seeds else [[]]
    points = _sweep_points(args.sweep) if args.sweep else [[]]
    base = _config_from_args(args)
    runs = []
    for seed_items, point in itertools.product(seeds, points):
        items = point + seed_items
        config = apply_overrides(copy.deepcopy(base), items)
        agents_train.planned_timesteps(config)
        name = _name(items)
        single = copy.copy(args)
        single.set, single.out, single.seed = list(args.set) + items, str(out / name), None
        runs.append({"name": name, "set": items, "config": config,
                     "command": _command(single, config)})
    names = [r["name"] for r in runs]
    if len(set(names)) != len(names):
        raise ValueError("--seeds and --sweep name the same run twice")
    return runs


def cpus_per_run(config: dict[str, Any]) -> int:
    """The CPUs a training run keeps busy: its worker processes with ``vector: subprocess``, else (one batched
    env in the learner's process) the learner's PyTorch threads: the more of updates and rollouts when set
    explicitly, one for ``"auto"`` (the thread rule then keeps the run within the CPUs Ray gave it)."""
    from agents.envs import vector_kind

    if vector_kind(config) == "subprocess":
        return max(1, int(config["n_workers"]))
    explicit = [int(config[key]) for key in ("torch_threads", "rollout_torch_threads") if config[key] != "auto"]
    return max([1, *explicit])


def _report_checkpoint(run_dir: Path, folder: Path | None, metrics: dict[str, Any]) -> None:
    """Hand ``folder`` (a checkpoint of train's; ``None``: the finished run) to Ray Tune with what resuming needs."""
    from ray import tune

    with tempfile.TemporaryDirectory() as tmp:
        target = Path(tmp)
        for name in _COPIED:
            if (run_dir / name).is_file() and (folder is None or name == "config.yaml"):
                shutil.copy2(run_dir / name, target / name)
        for name in _COPIED_FOLDERS:
            if (run_dir / name).is_dir():
                shutil.copytree(run_dir / name, target / name)
        if folder is not None:
            shutil.copytree(folder, target / "checkpoints" / folder.name)
        tune.report(metrics, checkpoint=tune.Checkpoint.from_directory(tmp))


def _trial(params: dict[str, Any], runs: list[dict[str, Any]], cpus: float = 1.0) -> None:
    """One training run as a Ray Tune trial (see the module docstring)."""
    from ray import tune

    from agents.checkpoints import read_json
    from agents.train import train

    spec = runs[params["run"]]
    run_dir = Path(os.getcwd()) / spec["name"]
    resumed_from = 0
    checkpoint = tune.get_checkpoint()
    if checkpoint is not None:  # the trial was started again: go on from its last checkpoint
        if run_dir.exists():
            shutil.rmtree(run_dir)
        with checkpoint.as_directory() as saved:
            shutil.copytree(saved, run_dir)
        steps = [int(read_json(p).get("num_timesteps", 0)) for p in run_dir.glob("checkpoints/*/policy.json")]
        resumed_from = max(steps, default=0)

    def hand_over(folder: Path) -> None:
        steps = int(read_json(folder / "policy.json").get("num_timesteps", 0))
        _report_checkpoint(run_dir, folder, {"timesteps": steps, "finished": False, "resumed_from": resumed_from})

    # the thread rule (controllers.threads) within the CPUs Ray reserved for this trial
    result = train(spec["config"], run_dir, resume=checkpoint is not None, progress_bar=False, verbose=0,
                   command=spec["command"], on_checkpoint=hand_over, most_threads=max(1, int(cpus)))
    training, metrics = result.card["training"], result.card["evaluation"]["metrics"]
    _report_checkpoint(run_dir, None, {
        "timesteps": int(training["total_timesteps"]), "finished": True, "resumed_from": resumed_from,
        "wall_time_s": float(training["total_wall_time_s"]), "mean_return": float(metrics["mean_return"]),
        "wall_normal_rmse_m": float(metrics["wall_normal_rmse_m"]), "collisions": int(metrics["collisions"])})


def _summary_markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| run | settings | timesteps | training wall time (min) | mean return | wall-normal RMSE (cm) | "
             "collisions | restarts from a checkpoint |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if r.get("error"):
            lines.append(f"| {r['name']} | {' '.join(r['set']) or '-'} | failed: {r['error']} | | | | | |")
            continue
        lines.append(f"| [{r['name']}]({r['name']}/model_card.md) | {' '.join(r['set']) or '-'} | {r['timesteps']:,} | "
                     f"{r['wall_time_s'] / 60:.1f} | {r['mean_return']:.1f} | {100 * r['wall_normal_rmse_m']:.2f} | "
                     f"{r['collisions']} | {r['restarts']} (last from step {r['resumed_from']:,}) |")
    return "\n".join(lines) + "\n"


def run(args: argparse.Namespace, *, callbacks: list[Any] | None = None) -> int:
    """The command's body. ``callbacks``: further Ray Tune callbacks (``ray.tune.Callback``) for the
    run, e.g. a logger; they run in this process, where Ray Tune handles each trial's results."""
    from wall_inspector import ray_backend

    try:
        ray_backend.check_arguments(args)
        runs = plan(args)
        from agents.train import check_observations

        check_observations(runs[0]["config"])  # builds the env once: settings it refuses stop the command here
    except (ValueError, FileNotFoundError) as exc:
        raise SystemExit(str(exc)) from None
    out = Path(args.out).resolve()
    cpus = float(args.cpus_per_trial if args.cpus_per_trial is not None else cpus_per_run(runs[0]["config"]))
    print(f"{len(runs)} training runs as Ray Tune trials, {cpus:g} CPU(s) each; collected in {out}", file=sys.stderr)

    from ray import tune

    with ray_backend.session(args.ray, args.ray_cpus):
        tuner = tune.Tuner(
            tune.with_resources(tune.with_parameters(_trial, runs=runs, cpus=cpus), {"cpu": cpus}),
            param_space={"run": tune.grid_search(list(range(len(runs))))},
            tune_config=tune.TuneConfig(num_samples=1),
            run_config=tune.RunConfig(name="ray", storage_path=str(out / "ray"), verbose=0 if args.quiet else 1,
                                      failure_config=tune.FailureConfig(max_failures=args.max_failures),
                                      callbacks=list(callbacks or [])),
        )
        grid = tuner.fit()
    rows = []
    for i in range(len(grid)):
        result = grid[i]
        spec = runs[int((result.config or {})["run"])]
        metrics = result.metrics or {}
        row: dict[str, Any] = {"name": spec["name"], "set": spec["set"], "command": spec["command"]}
        if not metrics.get("finished") or result.checkpoint is None:
            row["error"] = str(result.error or "did not finish").splitlines()[0][:200]
        else:
            result.checkpoint.to_directory(str(out / spec["name"]))
            history = result.metrics_dataframe
            restarts = int(history["resumed_from"].nunique() - 1) if history is not None and len(history) else 0
            # a trial that finished from a checkpoint was restarted at least once, even when Ray Tune's history lost
            # the result reported before its worker died (a loaded machine, CI stop 47)
            restarts = max(restarts, int(metrics["resumed_from"] > 0))
            row.update({k: metrics[k] for k in ("timesteps", "wall_time_s", "mean_return", "wall_normal_rmse_m",
                                                "collisions", "resumed_from")}, restarts=restarts)
        rows.append(row)
    rows.sort(key=lambda r: [r2["name"] for r2 in runs].index(r["name"]))
    (out / "summary.json").write_text(json.dumps({"runs": rows}, indent=2))
    (out / "summary.md").write_text(_summary_markdown(rows))
    print(_summary_markdown(rows))
    print(f"wrote {out / 'summary.md'}, {out / 'summary.json'} and a folder per run in {out}")
    return 0 if all(not r.get("error") for r in rows) else 1
