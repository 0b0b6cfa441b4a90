"""``wall-inspector bench-mpc``: SC-MPC's solve times in closed loop, against CasADi + IPOPT on the same problems.

The measurement is :mod:`controllers.benchmark`'s; this module reads the options, prints the figures and
the checks against their targets, and writes JSON and Markdown (``wall-inspector readme --set bench-mpc=FILE``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

from controllers.benchmark import ENV_ID, check_targets, markdown, measure, measure_batched, measure_predict, pin_to_one_core


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--steps", type=int, default=2000, help="control steps to fly (at least 2000 for the targets)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    parser.add_argument("--k-s", type=float, default=4.1, help="suction scale of the env and SC-MPC (N/m)")
    parser.add_argument("--d-thr", type=float, default=0.132, help="suction threshold of the env and SC-MPC (m)")
    parser.add_argument("--no-ipopt", action="store_true", help="skip the IPOPT comparison")
    parser.add_argument("--batch", type=int, default=64, help="vehicles of the batched predict measurement")
    parser.add_argument("--batched-steps", type=int, default=1000,
                        help="control steps of the batched predict measurement (0 skips it)")
    parser.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU core")
    parser.add_argument("--high-priority", action="store_true",
                        help="run the SC-MPC solves with real-time FIFO scheduling (needs the permission) so that "
                             "other processes on a shared machine do not preempt them, as on a flight computer")
    parser.add_argument("--markdown", metavar="FILE", help="write the figures as a Markdown table to FILE")
    parser.add_argument("--json", metavar="FILE", help="write the figures to FILE")


def _row(name: str, stats: dict) -> str:
    return (f"  {name:<16} median {stats['median']:7.3f}  p99 {stats['p99']:7.3f}  p99.8 {stats['p99_8']:7.3f}  "
            f"max {stats['max']:7.3f}  ms  ({stats['count']} solves)")


def run(args: argparse.Namespace) -> int:
    core = None if args.no_pin else pin_to_one_core()
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    t0 = time.perf_counter()
    figures = measure(args.steps, args.seed, args.k_s, args.d_thr, with_ipopt=not args.no_ipopt,
                      high_priority=args.high_priority)
    figures["single"] = measure_predict(args.steps, args.seed, args.k_s, args.d_thr)
    if args.batched_steps > 0:
        figures["batched"] = measure_batched(args.batch, args.batched_steps, args.seed, args.k_s, args.d_thr)
    figures["wall_seconds"] = time.perf_counter() - t0
    load_after = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    figures["machine"] = {"python": platform.python_version(), "processor": platform.processor() or platform.machine(),
                          "cpus": os.cpu_count(), "pinned_core": core,
                          "load_average_1min": [load_before, load_after]}
    print(f"SC-MPC on {ENV_ID} (k_s {args.k_s} N/m, d_thr {args.d_thr} m, noise on): {figures['steps']} control "
          f"steps, {figures['episodes']} episode(s), {figures['collisions']} collision step(s), "
          f"{figures['lm_iterations_mean']:.2f} LM iterations per solve"
          + (f", pinned to core {core}" if core is not None else "")
          + f", {figures['priority']}"
          + f"; load average {load_before:.1f} -> {load_after:.1f} on {os.cpu_count()} CPUs")
    print(_row("LM solve", figures["lm_solve_ms"]))
    print(_row("LM solve (CPU)", figures["lm_solve_cpu_ms"]))
    print(_row("controller step", figures["controller_step_ms"]))
    print(f"  one env, a flight of its own ({figures['single']['steps']} steps, no IPOPT between them), "
          "whole predict, CPU time:")
    print(_row("predict (CPU)", figures["single"]["predict_cpu_ms"]))
    if "batched" in figures:
        b = figures["batched"]
        print(f"  batched env, {b['vehicles']} vehicles, {b['steps']} steps, one predict per step "
              f"({b['lm_iterations_mean']:.2f} LM iterations per solve), CPU time per vehicle:")
        print(_row("predict (CPU)", b["predict_cpu_ms"]))
    if "ipopt_solve_ms" in figures:
        print(_row("IPOPT solve", figures["ipopt_solve_ms"]))
        gap = figures["cost_gap"]
        print(f"  IPOPT / LM median time: {figures['speedup_median']:.1f}x;  cost gap (F_LM - F_IPOPT) / F_IPOPT: "
              f"median {gap['median']:.2e}, max {gap['max']:.2e}, min {gap['min']:.2e}, "
              f"within 1 % on {100 * gap['share_within_1pct']:.1f} % of steps"
              + (f"; IPOPT did not converge on {figures['ipopt_failures']} step(s)" if figures["ipopt_failures"] else ""))
    checks = check_targets(figures)
    figures["targets"] = checks
    for name, ok in checks.items():
        print(f"  [{'PASS' if ok else 'FAIL'}] {name}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(figures, fh, indent=2)
        print(f"wrote {args.json}")
    if args.markdown:
        with open(args.markdown, "w") as fh:
            fh.write(markdown(figures))
        print(f"wrote {args.markdown}")
    return 0 if all(checks.values()) else 1


