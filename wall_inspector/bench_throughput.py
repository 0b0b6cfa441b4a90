"""``wall-inspector bench-throughput``: training env steps per second for several vector-env layouts.

Trains the task's configured learner for ``--timesteps`` env steps with each ``--layouts`` entry
(:mod:`agents.throughput`) and prints env steps per second of wall time, updates included;
``--json FILE`` writes them with the load average.
"""

from __future__ import annotations

import argparse
import json
import os


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default="WallSweep-v0", help="task (default WallSweep-v0)")
    parser.add_argument("--timesteps", type=int, default=100_000, help="env steps per layout (default 100,000)")
    parser.add_argument("--layouts", nargs="*", default=["batched-32", "multi-16/2", "sb3-8"],
                        help="batched-N, sb3-N or multi-N/W (default: batched-32 multi-16/2 sb3-8)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a configuration entry, as train's --set")
    parser.add_argument("--json", metavar="FILE", help="write the figures to FILE")


def run(args: argparse.Namespace) -> int:
    from agents.config import apply_overrides, default_config
    from agents.throughput import measure, parse_layout
    from wall_env.validation import check_output_folder

    try:
        default = default_config(args.env)
        apply_overrides(default, list(args.set))
        if not 1000 <= args.timesteps <= 10**9:
            raise ValueError(f"--timesteps must be in [1000, 1e9], got {args.timesteps}")
        if not args.layouts:
            raise ValueError("--layouts needs at least one layout")
        for layout in args.layouts:
            parse_layout(layout)
        if args.json:
            from pathlib import Path

            check_output_folder(Path(args.json).parent or Path("."), "--json")
    except (ValueError, FileNotFoundError) as exc:
        raise SystemExit(f"{exc}") from None
    load_before = os.getloadavg()[0]
    figures = {}
    print(f"{'layout':14s} {'env steps/s':>12s}")
    for layout in args.layouts:
        rate = measure(args.env, layout, args.timesteps, args.set)
        figures[layout] = rate
        print(f"{layout:14s} {rate:12,.0f}", flush=True)
    load = [load_before, os.getloadavg()[0]]
    print(f"load average {load[0]:.1f} -> {load[1]:.1f} on {os.cpu_count()} CPUs")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"env": args.env, "timesteps": args.timesteps, "env_steps_per_s": figures,
                       "load_average_1min": load}, fh, indent=2)
    return 0
