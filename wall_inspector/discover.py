"""``wall-inspector discover``: find what the nominal model misses in flight logs, fix the model, prove it.

::

    wall-inspector discover flight.csv [more.csv ...] --out results/ [--json report.json]
                            [--effect wall_suction] [--closed-loop]
    wall-inspector discover flight.ulg --vehicle vehicle.yaml --scene scene.yaml --out results/

Several logs of one vehicle are fitted together: one model for the vehicle and its
aerodynamics, each flight with its own conditions (a steady wind) and scene; each flight is
then held out in turn and predicted by the model fitted on the others.

Writes into ``--out``: ``model.json`` (the nominal vehicle plus the named effects with
fitted parameters and standard errors; ``gym.make(..., model="model.json")`` and
``SCMPC.from_env(env, model="model.json")`` load it), ``report.json`` (see
:mod:`discovery.report`; also copied to ``--json``) and the figures of
:mod:`discovery.plots`. The logs are only read. ``--effect NAME`` fits only that effect
(the paper's identification of Sec. 3.4 for ``wall_suction``). ``--closed-loop`` also
flies nominal MPC and SC-MPC from the discovered model in the log's world
(:mod:`discovery.closed_loop`); the world comes from ``--scenario`` or the
``<log>.scenario.json`` that ``wall-inspector fly`` writes.

A PX4 ULog or a ROS 2 bag is imported first (:mod:`discovery.importers`, as
``wall-inspector import-log`` does) with the vehicle and scene files of ``--vehicle``
and ``--scene``. Outputs and options are checked before any work.

Exit status 0 on success, 2 when a log or an argument is unusable (one line naming
the file, column or key, and row, or the option and its allowed range). The work is
:class:`discovery.Discovery`'s; this module reads the options, checks them and the outputs,
and writes and prints the results.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from discovery.flight_log import LogFormatError, read_log, scenario_path, sidecar_path
from wall_env.effects import EFFECTS

__all__ = ["add_arguments", "run", "OUTPUT_FILES"]

OUTPUT_FILES = ("model.json", "report.json", "residual_vs_regressor.png", "residual_time.png", "prediction.png",
                "unexplained_shape.png", "unexplained_where.png")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="+", metavar="LOG",
                        help="flight logs: CSV (each with its .json sidecar), PX4 ULog (.ulg) or ROS 2 bags "
                             "(the latter two with --vehicle and --scene)")
    parser.add_argument("--out", required=True, help="folder for model.json, report.json and the figures")
    parser.add_argument("--json", default=None, help="also write the report to this file")
    parser.add_argument("--vehicle", default=None, help="vehicle file (YAML) for .ulg logs and bags")
    parser.add_argument("--scene", default=None, help="scene file (YAML) for .ulg logs and bags")
    parser.add_argument("--topics", default=None, help="ROS 2 topic map (YAML) for bags")
    parser.add_argument("--effect", choices=sorted(EFFECTS), default=None,
                        help="fit only this effect (the paper's identification for wall_suction)")
    parser.add_argument("--candidates", default=None,
                        help=f"comma-separated effects to consider (default all: {','.join(EFFECTS)})")
    parser.add_argument("--window", type=float, default=None, help="smoothing window of the differentiator (s)")
    parser.add_argument("--horizon", type=float, default=None, help="open-loop prediction horizon (s, default 0.5)")
    parser.add_argument("--no-plots", action="store_true", help="skip the figures")
    parser.add_argument("--no-motor-lag", action="store_true",
                        help="do not look for a motor lag (the vehicle's motor_time_constant stays as given, 0 if not)")
    parser.add_argument("--closed-loop", action="store_true",
                        help="also fly nominal MPC and SC-MPC from the discovered model in the log's world")
    parser.add_argument("--scenario", default=None,
                        help="scenario file for --closed-loop (default: <first log>.scenario.json written by fly)")
    parser.add_argument("--closed-loop-seeds", type=int, default=1, help="episodes per controller (seeds 0..N-1)")
    parser.add_argument("--closed-loop-duration", type=float, default=None, help="closed-loop flight length (s)")
    parser.add_argument("--quiet", action="store_true", help="print only the summary")


def _fail(message: str) -> int:
    print(f"discover: {message}", file=sys.stderr)
    return 2


def _output_problem(out: Path, json_path: Path | None) -> str | None:
    """Why the outputs cannot be written (checked before any work), or None."""
    if out.exists() and not out.is_dir():
        return f"--out {out} exists and is not a folder; --out names a folder for model.json, report.json and figures"
    parent = out
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        return f"--out {out}: cannot create or write into {parent}"
    if json_path is not None:
        if json_path.is_dir():
            return f"--json {json_path} is a folder; give a file path"
        if json_path.suffix.lower() != ".json":
            return f"--json must be a .json path, got {json_path}"
    return None


def _read_logs(args: argparse.Namespace) -> list:
    from discovery.importers import import_log, is_importable

    logs = []
    for name in args.logs:
        if is_importable(name):
            if not (args.vehicle and args.scene):
                raise ValueError(f"{name} is a PX4 ULog or ROS 2 bag: give the nominal vehicle and the scene with "
                                 "--vehicle VEHICLE.yaml --scene SCENE.yaml")
            log, _ = import_log(name, args.vehicle, args.scene, topics=args.topics)
            logs.append(log)
        else:
            logs.append(read_log(name))
    return logs


def run(args: argparse.Namespace) -> int:
    from discovery.report import build_report, format_summary, write_report
    from discovery.workflow import Discovery

    started = time.perf_counter()
    out = Path(args.out)
    problem = _output_problem(out, Path(args.json) if args.json else None)
    if problem:
        return _fail(problem)
    if args.closed_loop_seeds < 1:
        return _fail(f"--closed-loop-seeds must be at least 1, got {args.closed_loop_seeds}")
    inputs = []
    for name in args.logs:
        path = Path(name)
        inputs += [path, sidecar_path(path), scenario_path(path)]
    outputs = [out / f for f in OUTPUT_FILES] + ([Path(args.json)] if args.json else [])
    resolved_inputs = {p.resolve() for p in inputs if p.exists()}
    clashes = [str(p) for p in outputs if p.resolve() in resolved_inputs]
    if clashes:
        return _fail(f"output file(s) {clashes} would overwrite an input; choose another --out or --json")
    settings: dict = {"motor_lag": not args.no_motor_lag}
    if args.window is not None:
        settings["window_s"] = args.window
    if args.horizon is not None:
        settings["horizon_s"] = args.horizon
    candidates = None
    if args.candidates:
        candidates = [c.strip() for c in args.candidates.split(",") if c.strip()]
    say = None if args.quiet else (lambda text: print(f"  {text}", file=sys.stderr))
    try:
        workflow = Discovery(candidates, args.effect, progress=say, **settings)
    except ValueError as exc:
        option = str(exc).replace("window_s", "--window").replace("horizon_s", "--horizon")
        return _fail(option)
    try:
        logs = _read_logs(args)
    except (LogFormatError, FileNotFoundError, ValueError) as exc:
        return _fail(str(exc))
    try:
        found = workflow.fit(logs)
    except ValueError as exc:
        return _fail(str(exc).replace("window_s", "--window").replace("horizon_s", "--horizon"))
    out.mkdir(parents=True, exist_ok=True)
    model_path = out / "model.json"
    found.model_.save(model_path)
    closed_loop = None
    if args.closed_loop:
        from discovery.closed_loop import closed_loop_check, load_scenario, scenario_match

        scenario_file = Path(args.scenario) if args.scenario else scenario_path(args.logs[0])
        if not scenario_file.exists():
            return _fail(f"--closed-loop needs the log's world: {scenario_file} does not exist "
                         "(fly writes it beside the log; or pass --scenario)")
        try:
            scenario = load_scenario(scenario_file)
            problems, own = scenario_match(scenario, logs[0], args.logs[0])
        except ValueError as exc:
            return _fail(f"--scenario {scenario_file}: {exc}")
        if problems:
            return _fail(f"--scenario {scenario_file} is not the world of {args.logs[0]}: {'; '.join(problems)}")
        if say:
            say(f"closed-loop check in {scenario_file}")
        closed_loop = closed_loop_check(model_path, scenario, seeds=range(args.closed_loop_seeds),
                                        duration=args.closed_loop_duration, ground_truth=own)
    if not args.no_plots and found.usable_:
        from discovery.plots import plot_all

        plot_all(found, out)
    report = build_report(found, str(model_path), closed_loop)
    report["details"]["command_runtime_s"] = round(time.perf_counter() - started, 3)
    write_report(report, out / "report.json")
    if args.json:
        write_report(report, args.json)
    print(format_summary(report))
    print(f"wrote {out / 'report.json'}" + (f" and {args.json}" if args.json else ""))
    return 0
