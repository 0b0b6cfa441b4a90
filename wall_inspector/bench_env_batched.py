"""``wall-inspector bench-env --batched``: how the batched env scales with the number of vehicles.

The measurements and their targets are :mod:`wall_env.benchmark_batched`'s (its docstring says
what is measured); this module prints the table and the targets met, and writes the figures to
``--markdown``, ``--json`` and the scaling curve to ``--plot``. :mod:`wall_inspector.bench_env`
reads the options and checks them.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from typing import Any

from wall_env.benchmark_batched import (
    TARGET_BATCHED,
    check_targets,
    measure_batched,
    measure_geometry,
    measure_memory,
    measure_single,
    measure_two_processes,
)


def _load() -> str:
    try:
        one, five, fifteen = os.getloadavg()
        return f"{one:.2f}, {five:.2f}, {fifteen:.2f}"
    except OSError:  # pragma: no cover - not on Linux
        return "unknown"


def run_batched(args: argparse.Namespace) -> int:
    env_id = args.envs[0] if args.envs and len(args.envs) == 1 else "WallInspector/WallSweep-v0"
    if args.envs and len(args.envs) > 1:
        print(f"--batched measures one task; using {env_id}")
    sizes = tuple(args.sizes)
    load_start = _load()
    print(f"batched env scaling, {env_id}, one process, random actions, resets included "
          f"(load average at start: {load_start})")
    single = measure_single(env_id, args.steps)
    rows: list[dict[str, Any]] = []
    header = (f"{'N':>6s} {'env steps/s':>12s} {'x single':>9s} {'reset all (ms)':>15s} {'ms / 1000 envs':>15s} "
              f"{'steps/CPU-s':>12s} {'CPU ms/1000':>12s}")
    print(header)
    print("-" * len(header))
    print(f"{'single':>6s} {single:12,.0f} {1.0:9.1f} {'':>15s} {'':>15s}")
    for n in sizes:
        row = measure_batched(env_id, n, args.batched_steps)
        row["ratio_to_single"] = row["steps_per_s"] / single
        rows.append(row)
        print(f"{n:6d} {row['steps_per_s']:12,.0f} {row['ratio_to_single']:9.1f} {row['reset_all_ms']:15.3f} "
              f"{row['reset_ms_per_1000_envs']:15.3f} {row['steps_per_cpu_s']:12,.0f} "
              f"{row['reset_cpu_ms_per_1000_envs']:12.3f}")
    two = measure_two_processes(env_id, args.two_core_n, args.batched_steps) if args.two_core_n else None
    if two:
        print(f"\ntwo processes, one batched env of {two['n_per_process']} each: {two['steps_per_s']:,.0f} env steps/s")
    memory = measure_memory(env_id, 1024, args.memory_resets) if args.memory_resets else None
    if memory:
        print(f"memory over {memory['resets']} resets of a 1,024-env batch: {memory['rss_before_mb']:.1f} MB -> "
              f"{memory['rss_after_mb']:.1f} MB ({memory['growth_mb']:+.1f} MB)")
    geometry = measure_geometry(env_id, args.geometry_n, min(args.batched_steps, 100_000)) if args.geometry_n else []
    if geometry:
        print(f"\nstructures (PyBullet's geometry) beside planes, N = {args.geometry_n}:")
        for row in geometry:
            print(f"  {row['env_id']:28s} {row['steps_per_s']:10,.0f} env steps/s {row['steps_per_cpu_s']:10,.0f} "
                  f"per CPU-second")
    load_end = _load()
    print(f"load average at end: {load_end}")

    checks = check_targets(rows, two, geometry)
    print()
    for name, (value, ok) in checks.items():
        print(f"{'met    ' if ok else 'NOT met'}  {name}: {value:,.3f}")

    if args.markdown:
        lines = ["| vehicles N | env steps/s (1 process) | x single env | reset all N (ms) | ms per 1,000 envs | "
                 "env steps per CPU-second |",
                 "|---:|---:|---:|---:|---:|---:|",
                 f"| single env | {single:,.0f} | 1.0 | | | |",
                 *[f"| {r['n']:,} | {r['steps_per_s']:,.0f} | {r['ratio_to_single']:.1f} | {r['reset_all_ms']:.3f} | "
                   f"{r['reset_ms_per_1000_envs']:.3f} | {r['steps_per_cpu_s']:,.0f} |" for r in rows]]
        if two:
            lines += ["", f"Two processes, one batched env of {two['n_per_process']:,} each: "
                          f"{two['steps_per_s']:,.0f} env steps/s."]
        lines += ["", f"`{env_id}`, random actions, resets included, measured by `wall-inspector bench-env --batched` "
                      f"on {os.cpu_count()} cores (load average {load_start} at start)."]
        if geometry:
            lines += ["", f"| structure, N = {args.geometry_n:,} | env steps/s (1 process) | env steps per CPU-second |",
                      "|---|---:|---:|",
                      *[f"| `{r['env_id']}`{' (planes only)' if r['env_id'] == env_id else ''} | "
                        f"{r['steps_per_s']:,.0f} | {r['steps_per_cpu_s']:,.0f} |" for r in geometry],
                      "", "Measured in turn twice in the same run, the better of each; the structures' suction and "
                      "contact come from PyBullet's closest-point queries on their bodies."]
        with open(args.markdown, "w") as fh:
            fh.write("\n".join(lines) + "\n")
        print(f"wrote {args.markdown}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        ax.loglog([r["n"] for r in rows], [r["steps_per_s"] for r in rows], "o-", label="batched env, 1 process")
        ax.loglog([r["n"] for r in rows], [r["steps_per_cpu_s"] for r in rows], "o--", color="tab:blue", alpha=0.5,
                  label="batched env, per CPU-second")
        ax.axhline(single, color="grey", linestyle="--", label="single env (gym.make)")
        if two:
            ax.plot([two["n_per_process"]], [two["steps_per_s"]], "s", label="2 processes")
        ax.axhline(TARGET_BATCHED, color="tab:red", linestyle=":", label="target at N = 1024")
        ax.set_xlabel("vehicles per batched env N")
        ax.set_ylabel("env steps per second")
        ax.set_title(f"{env_id.split('/')[-1]}: random actions, resets included")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        plt.close(fig)
        print(f"wrote {args.plot}")
    if args.json:
        payload = {
            "env_id": env_id,
            "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform(),
                        "load_average_start": load_start, "load_average_end": load_end},
            "single_steps_per_s": single,
            "batched": rows,
            "two_processes": two,
            "memory": memory,
            "geometry": geometry,
            "checks": {name: {"value": value, "met": ok} for name, (value, ok) in checks.items()},
        }
        with open(args.json, "w") as fh:
            json.dump(payload, fh, indent=2)
        print(f"wrote {args.json}")
    return 0
