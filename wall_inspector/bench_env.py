"""``wall-inspector bench-env``: environment speed with random actions.

For every task with its default settings: env steps per second in one process with
random actions (resets included, through ``gym.make`` and its wrappers), the median
``reset()`` time, and the steps per second of a 2-process vector env
(``gymnasium.vector.AsyncVectorEnv``). ``--json`` writes the figures.

``--batched`` measures the batched env instead (:mod:`wall_inspector.bench_env_batched`):
its scaling curve over the number of vehicles, beside the single env in the same run.
The measurements are :mod:`wall_env.benchmark`'s and :mod:`wall_env.benchmark_batched`'s;
this module reads the options, prints the figures and writes them.
"""

from __future__ import annotations

import argparse
import json
import os
import platform

import wall_env
from wall_env.benchmark import TARGET_RESET_MS, TARGET_STEPS_PER_S, measure_single, measure_vector
from wall_env.validation import check_output_folder


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--steps", type=int, default=20000, help="env steps per measurement (default 20000)")
    parser.add_argument("--envs", nargs="*", default=list(wall_env.ENV_IDS), help="environment ids (default: all)")
    parser.add_argument("--n-envs", type=int, default=2, help="processes of the vector env (default 2)")
    parser.add_argument("--json", metavar="FILE", help="write the figures to this JSON file")
    parser.add_argument("--markdown", metavar="FILE", help="write the table as Markdown (for `wall-inspector readme`)")
    parser.add_argument("--batched", action="store_true",
                        help="the batched env's scaling curve (one task: --envs ID, default WallSweep-v0)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 8, 64, 256, 1024, 4096],
                        help="--batched: vehicles per batched env (default 1 8 64 256 1024 4096)")
    parser.add_argument("--batched-steps", type=int, default=400_000,
                        help="--batched: env steps per figure, at least 20 calls (default 400000)")
    parser.add_argument("--two-core-n", type=int, default=1024,
                        help="--batched: vehicles per process for the two-process figure, 0 = skip (default 1024)")
    parser.add_argument("--memory-resets", type=int, default=1000,
                        help="--batched: resets of a 1,024-env batch for the memory check, 0 = skip (default 1000)")
    parser.add_argument("--plot", metavar="FILE", help="--batched: write the scaling curve as a picture (PNG)")
    parser.add_argument("--geometry-n", type=int, default=256,
                        help="--batched: vehicles of the structure tasks (Facade, Pier: suction and contact from "
                             "PyBullet's geometry) measured beside the plane-only task at the same N, 0 = skip "
                             "(default 256)")


def run(args: argparse.Namespace) -> int:
    if args.steps < 100:
        raise SystemExit("--steps must be at least 100")
    unknown = [env_id for env_id in args.envs if env_id not in wall_env.ENV_IDS]
    if unknown:
        raise SystemExit(f"unknown environment id(s) {unknown}; known: {list(wall_env.ENV_IDS)}")
    for flag in ("json", "markdown", "plot"):  # output paths are checked before minutes of measuring
        value = getattr(args, flag, None)
        if value:
            if os.path.isdir(value):
                raise SystemExit(f"--{flag} {value}: is a folder; give a file name")
            try:
                check_output_folder(os.path.dirname(os.path.abspath(value)), f"--{flag}")
            except ValueError as exc:
                raise SystemExit(str(exc)) from None
    if args.plot and not args.batched:
        raise SystemExit("--plot draws the batched env's scaling curve: use it with --batched")
    if args.batched:
        if any(n < 1 for n in args.sizes) or args.batched_steps < 1 or args.two_core_n < 0 or args.memory_resets < 0 \
                or args.geometry_n < 0:
            raise SystemExit("--sizes and --batched-steps must be positive, --two-core-n, --memory-resets and "
                             "--geometry-n >= 0")
        from wall_inspector.bench_env_batched import run_batched

        return run_batched(args)
    results = {}
    header = f"{'environment':32s} {'steps/s':>10s} {'reset ms':>9s} {f'{args.n_envs}-proc steps/s':>16s}"
    print(header)
    print("-" * len(header))
    for env_id in args.envs:
        single = measure_single(env_id, args.steps)
        vector = measure_vector(env_id, args.steps, args.n_envs)
        results[env_id] = {**single, "vector_steps_per_s": vector, "vector_processes": args.n_envs}
        print(f"{env_id:32s} {single['steps_per_s']:10.0f} {single['reset_median_ms']:9.3f} {vector:16.0f}")
    worst_speed = min(r["steps_per_s"] for r in results.values())
    worst_reset = max(r["reset_median_ms"] for r in results.values())
    ok = worst_speed >= TARGET_STEPS_PER_S and worst_reset < TARGET_RESET_MS
    print(f"\ntargets: >= {TARGET_STEPS_PER_S:.0f} steps/s in one process, median reset < {TARGET_RESET_MS} ms: "
          f"{'met' if ok else 'NOT met'} (slowest {worst_speed:.0f} steps/s, slowest reset {worst_reset:.3f} ms)")
    if args.markdown:
        lines = [
            f"| environment | steps/s (1 process) | median reset (ms) | steps/s ({args.n_envs} processes) |",
            "|---|---:|---:|---:|",
            *[f"| `{env_id}` | {r['steps_per_s']:,.0f} | {r['reset_median_ms']:.3f} | {r['vector_steps_per_s']:,.0f} |"
              for env_id, r in results.items()],
            "",
            f"Random actions, resets included, {args.steps:,} steps per figure, measured by "
            f"`wall-inspector bench-env` on {os.cpu_count()} cores (Python {platform.python_version()}).",
        ]
        with open(args.markdown, "w") as fh:
            fh.write("\n".join(lines) + "\n")
        print(f"wrote {args.markdown}")
    if args.json:
        payload = {
            "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
            "steps": args.steps,
            "targets": {"steps_per_s": TARGET_STEPS_PER_S, "reset_median_ms": TARGET_RESET_MS},
            "targets_met": ok,
            "results": results,
        }
        with open(args.json, "w") as fh:
            json.dump(payload, fh, indent=2)
        print(f"wrote {args.json}")
    return 0
