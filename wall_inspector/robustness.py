"""``wall-inspector robustness``: every method, told only the nominal model, over a grid of true worlds.

Flies PID, MPC, SC-MPC, the adaptive SC-MPC (all tuned presets, told the paper's
``k_s`` 4.1 N/m and ``d_thr`` 0.132 m), the shipped PPO agent and the reference (SC-MPC
told each world's true suction and push) in every world of
:data:`controllers.robustness.DEFAULT_GRID`, and the authors' settings under the
realistic profile; each (world, method) cell flies all seeds as rows of one batched env.
Writes ``robustness.md`` (the table, the realistic profile beside the paper's real-flight
ratios, the checks; ``wall-inspector readme --set robustness=OUT/robustness.md`` copies
it into the README), ``robustness.json`` and ``robustness.png`` (the heat map) to ``--out``.

``--workers N`` flies cells in N processes (default: the CPUs this process may use);
``--ray [ADDRESS]`` flies every cell as a Ray task instead.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controllers.robustness import Method, World


@dataclass(frozen=True)
class PPOAgent(Method):
    """A trained agent (``source``: a task name for the shipped agent, or a checkpoint folder)."""

    source: str = "WallSweep-v0"
    label: str = "PPO"

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.label

    def make(self, envs: Any, world: World) -> Any:
        import agents

        return agents.load_policy(self.source, env=envs)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from wall_inspector import ray_backend

    parser.add_argument("--out", default="out/robustness", help="folder for robustness.md, .json and .png")
    parser.add_argument("--seeds", default="90000-90004",
                        help="evaluation seeds, e.g. 90000-90004 or 1,5,9 (default: 90000-90004; use seeds that "
                             "nothing you compare was developed on)")
    parser.add_argument("--groups", default=None, metavar="G[,G...]",
                        help="only these groups of worlds: suction, push, gusts, latency, sensing, motor lag, realistic")
    parser.add_argument("--ppo", default="WallSweep-v0", metavar="AGENT",
                        help="the PPO agent: a task name for the shipped agent (default) or a checkpoint folder")
    parser.add_argument("--no-ppo", action="store_true", help="leave out the PPO agent")
    parser.add_argument("--card", action="store_true",
                        help="write the PPO agent's rows and checks into its model card (model_card.md and .json)")
    parser.add_argument("--no-authors", action="store_true",
                        help="leave out the authors' settings under the realistic profile")
    parser.add_argument("--duration", type=float, default=None,
                        help="shorten every flight to this many seconds (a quick look; not the acceptance figures)")
    parser.add_argument("--workers", type=int, default=None,
                        help="processes that fly cells at once (default: the CPUs this process may use)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    ray_backend.add_arguments(parser, "every (world, method) cell is a Ray task")


def _checked(args: argparse.Namespace) -> tuple[list[int], list[World], int]:
    from controllers.robustness import DEFAULT_GRID
    from wall_env.validation import check_output_folder
    from wall_inspector import ray_backend
    from wall_inspector.tune import parse_seeds

    try:
        ray_backend.check_arguments(args)
        seeds = parse_seeds(args.seeds, "--seeds")
        groups = sorted({w.group for w in DEFAULT_GRID})
        chosen = groups if args.groups is None else [g.strip() for g in args.groups.split(",") if g.strip()]
        unknown = sorted(set(chosen) - set(groups))
        if unknown or not chosen:
            raise ValueError(f"--groups must name some of {groups}, got {args.groups!r}")
        if args.duration is not None and not 0.05 <= args.duration <= 60:
            raise ValueError(f"--duration must be in [0.05, 60] s, got {args.duration}")
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        workers = cpus if args.workers is None else args.workers
        if not 1 <= workers <= 256:
            raise ValueError(f"--workers must be in [1, 256], got {workers}")
        if args.ray is not None and args.workers is not None:
            raise ValueError("--workers is for flights on this machine; with --ray, Ray decides")
        check_output_folder(Path(args.out), "--out")
        if not args.no_ppo:
            from agents.policy import _resolve

            folder = _resolve(args.ppo)  # a task name without a shipped agent raises here
            if not (folder / "model.zip").is_file():
                raise ValueError(f"--ppo {args.ppo}: no agent there ({folder / 'model.zip'} does not exist)")
            if args.card and not (folder / "model_card.json").is_file():
                raise ValueError(f"--card: {folder} has no model_card.json to write into")
        elif args.card:
            raise ValueError("--card writes the PPO agent's results into its model card; it cannot go with --no-ppo")
    except (ValueError, FileNotFoundError) as exc:
        raise SystemExit(str(exc)) from None
    return seeds, [w for w in DEFAULT_GRID if w.group in chosen], workers


def _ray_executor(address: str, cpus: int | None):
    from controllers.robustness import fly_cell

    def run(jobs, seeds, duration, on_cell):
        import ray

        from wall_inspector import ray_backend

        with ray_backend.session(address, cpus):
            remote = ray.remote(num_cpus=ray_backend.CPUS_PER_FLIGHT, max_retries=ray_backend.FLIGHT_RETRIES)(fly_cell)
            refs = [remote.remote(world, method, list(seeds), duration) for world, method in jobs]
            results = []
            for ref in refs:
                results.append(ray.get(ref))
                on_cell()
            return results

    return run


def run(args: argparse.Namespace) -> int:
    seeds, worlds, workers = _checked(args)
    from wall_inspector.cli import lock_run_folder

    with lock_run_folder(args.out, "wall-inspector robustness"):
        return _run(args, seeds, worlds, workers)


def _run(args: argparse.Namespace, seeds: list[int], worlds: list[World], workers: int) -> int:
    from controllers.robustness import authors_methods, default_methods, local_executor, run_grid, write_outputs

    methods: dict[str, Method] = default_methods()
    if not args.no_ppo:
        methods = {**{k: v for k, v in methods.items() if k != "SC-MPC told the truth"}, "PPO": PPOAgent(args.ppo),
                   "SC-MPC told the truth": methods["SC-MPC told the truth"]}
    extra = [] if args.no_authors else [(w, m) for w in worlds if w.group == "realistic"
                                        for m in authors_methods().values()]
    executor = _ray_executor(args.ray, args.ray_cpus) if args.ray is not None else local_executor(workers)
    print(f"{len(worlds) * len(methods) + len(extra)} cells of {len(seeds)} flights "
          f"({'Ray' if args.ray is not None else f'{workers} process(es)'})", file=sys.stderr)
    start = time.perf_counter()
    results = run_grid(worlds, methods, seeds, duration=args.duration, executor=executor,
                       progress=not args.no_progress, extra=extra)
    seconds = time.perf_counter() - start
    text, checks = write_outputs(results, seeds, args.out, seconds)
    print(text)
    print(f"wrote {Path(args.out) / 'robustness.md'}, robustness.json and robustness.png")
    if args.card:
        from agents.checkpoints import set_robustness
        from agents.policy import _resolve
        from controllers.robustness import method_report

        card = set_robustness(_resolve(args.ppo), method_report(results, "PPO", seeds, checks),
                              {"seeds": [int(s) for s in seeds],
                               "checks": [c for c in checks if c["check"].startswith("PPO")]})
        print(f"wrote the PPO rows into {card}")
    return 0
