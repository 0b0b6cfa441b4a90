"""``wall-inspector bench-export``: how fast the exported controllers step, beside the Python ones.

On the paper's Table II flight (``WallSweep-v0``, k_s = 4.1 N/m, d_thr = 0.132 m, command
noise on, contacts do not end it; seed ``--seed``):

- the C controller (``--method``, default SC-MPC): exported and built into ``OUT/<method>``,
  the Python controller flies the flight once and every step it solved is run again through
  ``wi_step`` by a C timing loop (``wi_bench``: one untimed pass, then ``--passes`` timed ones),
  wall clock and CPU time of each call (:mod:`controllers.export.timing`); beside it the
  Python ``predict`` of the same flight;
- the ONNX policy (``--agent``, default the shipped WallSweep agent): exported to
  ``OUT/ppo/policy.onnx``, the Python agent flies the flight once, and each of its
  observations goes through one onnxruntime call (one thread); beside it the Python
  ``predict`` (:func:`agents.export.measure_onnx_policy`).

Both also report the largest difference between the exported and the Python actions.
Targets (printed with the figures): the C step's median <= 0.1 ms and p99.8 <= 0.3 ms, the
ONNX step's median <= 0.05 ms (wall clock). The process is pinned to one CPU core
(``--no-pin`` leaves it free); ``--high-priority`` runs the C timing loop with real-time FIFO
scheduling where permitted, as a flight computer runs its control thread. The load average
is printed beside the figures; ``--json FILE`` writes them all, ``--markdown FILE`` a table for the
README (``wall-inspector readme --set bench-export=FILE``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path
from typing import Any

from wall_env.validation import check_output_folder


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", choices=("scmpc", "mpc"), default="scmpc", help="the C controller to time")
    parser.add_argument("--agent", default="WallSweep-v0", metavar="SOURCE",
                        help="the agent to time as ONNX: checkpoint folder or task name (default WallSweep-v0's)")
    parser.add_argument("--no-onnx", action="store_true", help="time the C controller only")
    parser.add_argument("--seed", type=int, default=0, help="seed of the flight (default 0)")
    parser.add_argument("--passes", type=int, default=5, help="timed passes of the C loop over the flight (default 5)")
    parser.add_argument("--out", default="out/bench-export", help="folder for the exported files")
    parser.add_argument("--json", default=None, metavar="FILE", help="write every figure to FILE")
    parser.add_argument("--markdown", default=None, metavar="FILE",
                        help="write the figures as a Markdown table to FILE (for wall-inspector readme)")
    parser.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU core")
    parser.add_argument("--high-priority", action="store_true",
                        help="run the C timing loop with real-time FIFO scheduling (needs the permission)")


def _check(args: argparse.Namespace) -> Path:
    if args.passes < 1:
        raise SystemExit(f"--passes must be a positive integer, got {args.passes}")
    if args.seed < 0:
        raise SystemExit(f"--seed must be non-negative, got {args.seed}")
    try:
        out = check_output_folder(args.out, "--out")
        for flag, value in (("--json", args.json), ("--markdown", args.markdown)):
            if value is not None:
                if Path(value).is_dir():
                    raise ValueError(f"{flag} {value}: is a folder")
                check_output_folder(Path(value).parent, flag)
    except ValueError as exc:
        raise SystemExit(str(exc)) from None
    if not args.no_onnx:
        import importlib.util

        import agents

        missing = [name for name in ("onnx", "onnxscript", "onnxruntime") if importlib.util.find_spec(name) is None]
        if missing:
            raise SystemExit(f"the ONNX step needs {', '.join(missing)}: pip install 'wall-inspector[export]', "
                             "or pass --no-onnx")

        if not Path(args.agent).exists():
            try:
                folder = agents.pretrained_path(args.agent)
            except ValueError:
                raise SystemExit(f"--agent {args.agent}: no such folder, and not a task name") from None
            if not folder.is_dir():
                raise SystemExit(f"--agent {args.agent}: no shipped agent for this task ({folder} does not exist)")
            args.agent = str(folder)
    return out


def _line(name: str, stats: dict[str, float]) -> str:
    return f"  {name:38s} {stats['median']:8.4f} {stats['p99_8']:8.4f} {stats['max']:8.4f}"


def markdown(results: dict[str, Any]) -> str:
    """The figures of :func:`run` as a Markdown table with a note of how they were measured."""
    c, onnx = results["c_controller"], results.get("onnx_policy")
    name = c["controller"]
    rows = [(f"{name}, exported C: `wi_step` in a C timing loop (wall clock)", c["c_step_ms"]),
            (f"{name}, exported C: `wi_step` in a C timing loop (CPU time)", c["c_step_cpu_ms"]),
            (f"{name}, Python `predict` (wall clock)", c["python_predict_ms"])]
    if onnx is not None:
        rows += [("PPO, exported ONNX: one onnxruntime call (wall clock)", onnx["onnx_step_ms"]),
                 ("PPO, Python `predict` (wall clock)", onnx["python_predict_ms"])]
    lines = ["| step | median (ms) | p99 (ms) | p99.8 (ms) | max (ms) |", "|---|---:|---:|---:|---:|"]
    lines += [f"| {label} | {s['median']:.3f} | {s['p99']:.3f} | {s['p99_8']:.3f} | {s['max']:.3f} |" for label, s in rows]
    load = ", ".join(f"{x:.2f}" for x in results["load_average"])
    note = (f"One flight of `{c['env']}` (k_s 4.1 N/m, d_thr 0.132 m, command noise, seed {c['seed']}), "
            f"{c['steps']:,} control steps; the C loop runs them {c['passes']} times after one untimed pass, "
            f"{c['lm_iterations_mean']:.2f} LM iterations per step. The C controller's actions equal the Python "
            f"controller's (largest difference {c['max_action_difference']:.2g})")
    if onnx is not None:
        note += f", the ONNX policy's the Python agent's within {onnx['max_action_difference']:.2g}"
    note += (f". {'Pinned to one core' if results['pinned_core'] is not None else 'Not pinned'}, "
             f"{results['priority']}, load average {load} after the run; measured by `wall-inspector bench-export`.")
    return "\n".join(lines) + "\n\n" + note + "\n"


def _verdict(value: float, target: float) -> str:
    return "met" if value <= target else "NOT met"


def run(args: argparse.Namespace) -> int:
    from controllers.export.timing import measure_exported_controller, realtime_permitted

    out = _check(args)
    core = None
    if not args.no_pin and hasattr(os, "sched_setaffinity"):
        core = sorted(os.sched_getaffinity(0))[-1]
        os.sched_setaffinity(0, {core})
    realtime = bool(args.high_priority and realtime_permitted())
    priority = ("C loop under real-time FIFO scheduling" if realtime else
                "normal priority" + (" (no permission for FIFO scheduling)" if args.high_priority else ""))
    results: dict[str, Any] = {"machine": platform.machine(), "processor": platform.processor(),
                               "pinned_core": core, "priority": priority}
    c = measure_exported_controller(out / args.method, args.method, args.seed, args.passes, realtime=realtime)
    results["c_controller"] = c
    onnx = None
    if not args.no_onnx:
        from agents.export import measure_onnx_policy

        onnx = measure_onnx_policy(args.agent, out / "ppo", args.seed)
        results["onnx_policy"] = onnx
    results["load_average"] = list(os.getloadavg())

    load = " ".join(f"{x:.2f}" for x in results["load_average"])
    print(f"{c['env']} (k_s 4.1 N/m, d_thr 0.132 m, noise on), seed {args.seed}: {c['steps']} control steps; "
          f"load average {load}; {'pinned to core ' + str(core) if core is not None else 'not pinned'}; {priority}")
    print(f"  {'ms per step':38s} {'median':>8s} {'p99.8':>8s} {'max':>8s}")
    print(_line(f"{c['controller']} exported C, wi_step (wall)", c["c_step_ms"]))
    print(_line(f"{c['controller']} exported C, wi_step (CPU)", c["c_step_cpu_ms"]))
    print(_line(f"{c['controller']} Python predict (wall)", c["python_predict_ms"]))
    print(_line(f"{c['controller']} Python predict (CPU)", c["python_predict_cpu_ms"]))
    if onnx is not None:
        print(_line("PPO ONNX, onnxruntime run (wall)", onnx["onnx_step_ms"]))
        print(_line("PPO Python predict (wall)", onnx["python_predict_ms"]))
    targets = c["targets"]
    print(f"C step ({c['passes']} passes x {c['steps']} steps, {c['lm_iterations_mean']:.2f} LM iterations per step): "
          f"median <= {targets['median_ms']} ms {_verdict(c['c_step_ms']['median'], targets['median_ms'])}, "
          f"p99.8 <= {targets['p99_8_ms']} ms {_verdict(c['c_step_ms']['p99_8'], targets['p99_8_ms'])} (wall clock); "
          f"C actions - Python actions: largest {c['max_action_difference']:.3g}, failures C {c['c_failures']} / "
          f"Python {c['python_failures']}")
    if onnx is not None:
        target = onnx["targets"]["median_ms"]
        print(f"ONNX step: median <= {target} ms {_verdict(onnx['onnx_step_ms']['median'], target)}; "
              f"ONNX actions - Python actions: largest {onnx['max_action_difference']:.3g} ({onnx['agent']})")
    if args.json is not None:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(results, indent=1) + "\n")
        print(f"wrote {path}")
    if args.markdown is not None:
        path = Path(args.markdown)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(markdown(results))
        print(f"wrote {path}")
    return 0
