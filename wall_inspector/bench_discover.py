"""``wall-inspector bench-discover``: how long discovery takes, and (``--acceptance``) how well it does.

Timing: flies a 60 s, 100 Hz wall survey with two hidden effects (wall suction and
extra linear drag), then times ``wall-inspector discover`` on it twice: as a fresh
process (what a user waits for: interpreter start, imports, compile-cache lookups,
fitting, report and plots) and inside this process (the same command without the
interpreter's start and imports). The target is at most 5 s per minute of 100 Hz log as
a command; both figures are checked against it and printed with the load average, since
on a shared machine the figures follow the load. Then (``--flights``, default 5) it flies
that many one-minute surveys of one vehicle, each in its own steady wind with the same
quadratic drag, and times ``discover`` on all of them at once as a command (one model, a
wind per flight): target at most 20 s for five, with the shared drag coefficient, each
flight's wind and each held-out flight's force error printed beside it.

``--acceptance``: flies hidden-effect logs (:mod:`discovery.hidden_effects`): every
form of :data:`~discovery.hidden_effects.FORMS` (the library's effects and the
literature's fuller forms) singly and the pairs of
:data:`~discovery.hidden_effects.PAIRS`, plus clean logs of every scenario, at log
rates cycling through 50, 100, 200, 500 and 1000 Hz, with the seeds of ``--seeds``;
then prints the share named right with no spurious effect (target >= 95 %), the
parameters within 10 %, the held-out force-gap reductions (target >= 80 %) and
whether clean logs name nothing. ``--json`` writes every log's record.

The cases, targets and figures are :mod:`discovery.benchmark`'s; this module reads the
options, times the command, and prints and writes the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from discovery.benchmark import (
    EFFECTS,
    FLIGHT_WINDS,
    FLIGHTS_DRAG,
    TARGET_S_FLIGHTS,
    TARGET_S_PER_MINUTE,
    acceptance_records,
    format_summary,
    summarise,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, default=60.0, help="log length in seconds (default 60; "
                        "30 with --acceptance)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs of each kind (default 3)")
    parser.add_argument("--json", metavar="FILE", help="write the figures to this JSON file")
    parser.add_argument("--acceptance", action="store_true", help="measure naming, parameter and gap figures on "
                        "hidden-effect logs instead of the runtime")
    parser.add_argument("--seeds", default="0", help="comma-separated seeds for --acceptance (default 0)")
    parser.add_argument("--flights", type=int, default=5, help="also time discover on this many one-minute flights "
                        f"in different winds, fitted together (default 5, at most {len(FLIGHT_WINDS)}; 0 skips it)")


def _check_args(args: argparse.Namespace) -> str | None:
    if not (args.duration > 0 and args.duration <= 3600):
        return f"--duration must be in (0, 3600] s, got {args.duration}"
    if args.repeats < 1:
        return f"--repeats must be at least 1, got {args.repeats}"
    if not 0 <= args.flights <= len(FLIGHT_WINDS):
        return f"--flights must be in [0, {len(FLIGHT_WINDS)}], got {args.flights}"
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    except ValueError:
        return f"--seeds must be comma-separated integers, got {args.seeds!r}"
    if not seeds:
        return "--seeds needs at least one seed"
    return None


def run(args: argparse.Namespace) -> int:
    problem = _check_args(args)
    if problem:
        print(f"bench-discover: {problem}", file=sys.stderr)
        return 2
    if args.acceptance:
        return _acceptance(args)
    return _timing(args)


def _acceptance(args: argparse.Namespace) -> int:
    duration = 30.0 if args.duration == 60.0 else args.duration
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    records = []
    for record in acceptance_records(seeds, duration):
        records.append(record)
        label, rate = record["case"], record["rate_hz"]
        if record["flown"]:  # a log with hidden effects
            if record["ended_early"]:
                print(f"{label:42s} {rate:6.0f} Hz  flight ended early after {record['duration_s']:.1f} s "
                      f"({record['collisions']} collision(s)): not counted", flush=True)
                continue
            errs = list(record["param_errors"].values())
            worst = "missing" if any(e is None for e in errs) else f"{100 * max(errs, default=0):.1f} %"
            print(f"{label:42s} {rate:6.0f} Hz  found {','.join(record['named']) or '-':40s} "
                  f"{'ok ' if record['named_right'] else 'BAD'} worst param {worst:>8s}  gap "
                  f"-{100 * record['gap_reduction']:.0f} %  ({record['runtime_s']:.1f} s)", flush=True)
        elif record["ended_early"]:
            print(f"{label:42s} flight ended early: not counted", flush=True)
        else:
            print(f"{label:42s} {rate:6.0f} Hz  found {','.join(record['named']) or '-':40s} "
                  f"{'ok ' if record['named_right'] else 'BAD'}", flush=True)
    summary = summarise(records, seeds, duration)
    print(format_summary(summary))
    if args.json:
        Path(args.json).write_text(json.dumps({"summary": summary, "logs": records}, indent=2, default=str))
        print(f"wrote {args.json}")
    return 0


def _timing(args: argparse.Namespace) -> int:
    from discovery.fly import fly
    from wall_inspector.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "survey.csv"
        fly(None, "pid", EFFECTS, 51, log, scenario="wall-survey", duration=args.duration)
        command = [sys.executable, "-m", "wall_inspector.cli", "discover", str(log), "--out", str(Path(tmp) / "cmd"),
                   "--quiet"]
        process_times, inprocess_times = [], []
        # the in-process figure is the work alone: the modules discover loads are imported first
        for module in ("wall_inspector.discover", "discovery.workflow", "discovery.report", "discovery.plots", "matplotlib.figure"):
            importlib.import_module(module)
        load_start = os.getloadavg()
        for i in range(args.repeats):
            start = time.perf_counter()
            subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
            process_times.append(time.perf_counter() - start)
            start = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()):
                main(["discover", str(log), "--out", str(Path(tmp) / f"run{i}"), "--quiet"])
            inprocess_times.append(time.perf_counter() - start)
        found = sorted(e["name"] for e in json.loads((Path(tmp) / "run0" / "report.json").read_text())["effects"])

        flights = _time_flights(args, Path(tmp)) if args.flights else None

    worst, worst_inprocess = max(process_times), max(inprocess_times)
    target = TARGET_S_PER_MINUTE * args.duration / 60.0
    load_end = os.getloadavg()
    print(f"discover on a {args.duration:g} s, 100 Hz log ({len(found)} effects found: {', '.join(found)})")
    print(f"  as a command:    {', '.join(f'{t:.2f}' for t in process_times)} s")
    print(f"  in one process:  {', '.join(f'{t:.2f}' for t in inprocess_times)} s")
    print(f"load average (1 min) {load_start[0]:.2f} at the start, {load_end[0]:.2f} at the end, on {os.cpu_count()} CPUs")
    for label, slowest in (("as a command", worst), ("in one process", worst_inprocess)):
        print(f"per minute of log {label}: {60.0 * slowest / args.duration:.2f} s (slowest run); target <= "
              f"{TARGET_S_PER_MINUTE:g} s: {'met' if slowest <= target else 'NOT met'}")
    if flights is not None:
        limit = TARGET_S_FLIGHTS * args.flights / 5.0
        print(f"{args.flights} flights of {args.duration:g} s at 100 Hz in {args.flights} winds, fitted together as a "
              f"command: {', '.join(f'{t:.2f}' for t in flights['command_s'])} s; slowest {max(flights['command_s']):.2f} s;"
              f" target <= {limit:g} s: {'met' if max(flights['command_s']) <= limit else 'NOT met'}")
        print(f"  found {', '.join(flights['found']) or 'nothing'}; shared C {flights['C']} (flown {list(FLIGHTS_DRAG)});"
              f" winds {flights['winds']} (flown {[list(w) for w in FLIGHT_WINDS[:args.flights]]}); held-out flight "
              f"force error / in-sample: {flights['held_out_ratio']}")
    if args.json:
        Path(args.json).write_text(json.dumps({
            "log_duration_s": args.duration, "rate_hz": 100.0, "effects_found": found,
            "command_s": process_times, "in_process_s": inprocess_times,
            "target_s_per_minute": TARGET_S_PER_MINUTE, "target_met": worst <= target,
            "in_process_target_met": worst_inprocess <= target,
            "flights": flights, "flights_target_s": TARGET_S_FLIGHTS * args.flights / 5.0 if flights else None,
            "flights_target_met": (max(flights["command_s"]) <= TARGET_S_FLIGHTS * args.flights / 5.0)
            if flights else None,
            "load_average_start": list(load_start), "load_average_end": list(load_end), "cpus": os.cpu_count(),
        }, indent=2))
        print(f"wrote {args.json}")
    return 0


def _time_flights(args: argparse.Namespace, folder: Path) -> dict:
    """Fly ``args.flights`` one-minute surveys, each in its own steady wind with the same quadratic drag, and time
    ``wall-inspector discover`` on all of them at once as a fresh process (``args.repeats`` times)."""
    from discovery.fly import fly

    paths = []
    for i, (wx, wy) in enumerate(FLIGHT_WINDS[:args.flights]):
        path = folder / f"wind{i}.csv"
        coefficients = "/".join(f"{c:g}" for c in FLIGHTS_DRAG)
        fly(None, "pid", f"quadratic_drag:C={coefficients},w={wx:g}/{wy:g}/0", 60 + i, path, scenario="survey",
            duration=args.duration)
        paths.append(str(path))
    times = []
    for i in range(args.repeats):
        out = folder / f"flights{i}"
        command = [sys.executable, "-m", "wall_inspector.cli", "discover", *paths, "--out", str(out), "--quiet",
                   "--no-plots"]
        start = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        times.append(time.perf_counter() - start)
    report = json.loads((folder / "flights0" / "report.json").read_text())
    drag = next((e for e in report["effects"] if e["name"] == "quadratic_drag"), None)
    flights = report.get("flights") or {}
    return {"n": args.flights, "command_s": times, "found": sorted(e["name"] for e in report["effects"]),
            "C": None if drag is None else [round(c, 4) for c in drag["params"]["C"]],
            "winds": [[round(x, 3) for x in (c.get("quadratic_drag") or {}).get("w", [])]
                      for c in flights.get("conditions", [])],
            "held_out_ratio": [None if h.get("ratio_to_in_sample") is None else round(h["ratio_to_in_sample"], 3)
                               for h in flights.get("held_out", [])]}
