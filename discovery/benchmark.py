"""``wall-inspector bench-discover``: how long discovery takes on a 60 s log at 100 Hz.

Flies a 60 s, 100 Hz wall survey with two hidden effects (wall suction and extra
linear drag), then times ``wall-inspector discover`` on it twice: as a fresh process
(what a user waits for: interpreter start, imports, compile-cache lookups, fitting,
report and plots) and inside this process (the workflow alone). The target is at most
10 s. ``--json`` writes the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 10.0
EFFECTS = "wall_suction:k_s=4.1,d_thr=0.132;linear_drag:D=0.2/0.2/0.2"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, default=60.0, help="log length in seconds (default 60)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs of each kind (default 3)")
    parser.add_argument("--json", metavar="FILE", help="write the figures to this JSON file")


def run(args: argparse.Namespace) -> int:
    from discovery.fly import fly
    from wall_inspector.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "survey.csv"
        fly(None, "pid", EFFECTS, 51, log, scenario="wall-survey", duration=args.duration)
        command = [sys.executable, "-m", "wall_inspector.cli", "discover", str(log), "--out", str(Path(tmp) / "cmd"),
                   "--quiet"]
        process_times, inprocess_times = [], []
        for i in range(args.repeats):
            start = time.perf_counter()
            subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
            process_times.append(time.perf_counter() - start)
            start = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()):
                main(["discover", str(log), "--out", str(Path(tmp) / f"run{i}"), "--quiet"])
            inprocess_times.append(time.perf_counter() - start)
        found = sorted(e["name"] for e in json.loads((Path(tmp) / "run0" / "report.json").read_text())["effects"])

    worst = max(process_times)
    print(f"discover on a {args.duration:g} s, 100 Hz log ({len(found)} effects found: {', '.join(found)})")
    print(f"  as a command:    {', '.join(f'{t:.2f}' for t in process_times)} s")
    print(f"  in one process:  {', '.join(f'{t:.2f}' for t in inprocess_times)} s")
    print(f"target <= {TARGET_S:g} s as a command: {'met' if worst <= TARGET_S else 'NOT met'} (slowest {worst:.2f} s)")
    if args.json:
        Path(args.json).write_text(json.dumps({
            "log_duration_s": args.duration, "rate_hz": 100.0, "effects_found": found,
            "command_s": process_times, "in_process_s": inprocess_times, "target_s": TARGET_S,
            "target_met": worst <= TARGET_S,
        }, indent=2))
        print(f"wrote {args.json}")
    return 0
