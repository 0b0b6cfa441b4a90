"""``wall-inspector fly``: record a flight log (CSV + JSON) from the simulator, with measurement noise.

What is flown and written is :func:`discovery.fly.fly`'s (its module's docstring says it all);
this module reads the options, checks them and the output files before flying, and prints what
was flown.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from discovery.flight_log import csv_output_problem, scenario_path
from discovery.fly import MeasurementNoise, fly
from discovery.scenarios import SCENARIOS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default=None, help="environment id (default WallInspector/WallSweep-v0, or the "
                        "scenario's)")
    parser.add_argument("--scenario", choices=sorted(SCENARIOS), default=None,
                        help="a ready-made flight that excites effects: " +
                        "; ".join(f"{s.name}: {s.description}" for s in SCENARIOS.values()))
    parser.add_argument("--policy", default="pid",
                        help="pid, mpc, scmpc or the path of a saved Stable-Baselines3 agent")
    parser.add_argument("--policy-model", default=None, help="model file for --policy scmpc")
    parser.add_argument("--policy-kwargs", default="{}", help='controller keyword arguments as JSON, e.g. '
                        '\'{"kp": [30, 30, 10], "kv": [11, 11, 6]}\' for a PID stiff enough to fly inside the '
                        'suction zone')
    parser.add_argument("--effects", default="", help='effects flown, e.g. "wall_suction:k_s=4.1,d_thr=0.132;'
                        'linear_drag:D=0.2/0.2/0.1" (default: none, only the nominal vehicle)')
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True, help="CSV file to write (the JSON sidecar goes beside it)")
    parser.add_argument("--env-kwargs", default="{}", help='env keyword arguments as JSON, e.g. \'{"altitude": 1.2, '
                        '"ceiling_z": 2.4, "standoff": 0.3}\'')
    parser.add_argument("--survey", default=None, help='fly a Lissajous survey instead of the task\'s reference, '
                        'as JSON: {"amplitude": [ax, ay, az] (m), "period": [Tx, Ty, Tz] (s), "centre": [x, y, z] (m)}')
    parser.add_argument("--duration", type=float, default=None, help="flight length (s; default the task's)")
    parser.add_argument("--rate", type=float, default=100.0, help="log (and env) rate in Hz, 50 to 1000")
    parser.add_argument("--control-rate", type=float, default=None, help="policy rate in Hz (default min(rate, 100))")
    parser.add_argument("--noise-scale", type=float, default=1.0, help="multiplies every measurement noise level "
                        "(0 for noiseless measurements)")
    parser.add_argument("--with-acceleration", action="store_true", help="also write measured acceleration ax, ay, az")
    parser.add_argument("--with-rotor-thrusts", action="store_true", help="also write rotor_0..rotor_3")
    parser.add_argument("--overwrite", action="store_true", help="replace existing output files")


def run(args: argparse.Namespace) -> int:
    parsed: dict[str, Any] = {}
    for option in ("env_kwargs", "policy_kwargs", "survey"):
        text = getattr(args, option)
        if text is None:
            parsed[option] = None
            continue
        try:
            parsed[option] = json.loads(text)
        except json.JSONDecodeError as exc:
            print(f"fly: --{option.replace('_', '-')} is not valid JSON: {exc}", file=sys.stderr)
            return 2
        if not isinstance(parsed[option], dict):
            print(f"fly: --{option.replace('_', '-')} must be a JSON object", file=sys.stderr)
            return 2
    problem = csv_output_problem(args.out, args.overwrite, (scenario_path(args.out),))
    if problem:
        print(f"fly: {problem}", file=sys.stderr)
        return 2
    env_kwargs, policy_kwargs, survey = parsed["env_kwargs"], parsed["policy_kwargs"], parsed["survey"]
    noise = MeasurementNoise().scaled(args.noise_scale) if args.noise_scale > 0 else None
    try:
        log, summary = fly(args.env, args.policy, args.effects, args.seed, args.out, scenario=args.scenario,
                           env_kwargs=env_kwargs, survey=survey, duration=args.duration, rate_hz=args.rate,
                           control_rate_hz=args.control_rate, noise=noise, policy_model=args.policy_model,
                           policy_kwargs=policy_kwargs or None, with_acceleration=args.with_acceleration,
                           with_rotor_thrusts=args.with_rotor_thrusts, overwrite=args.overwrite, progress=True)
    except (ValueError, FileNotFoundError, FileExistsError) as exc:
        print(f"fly: {exc}", file=sys.stderr)
        return 2
    ending = ("ended early: collision" if summary["terminated"] and summary["collisions"]
              else "ended early: strayed from the reference" if summary["terminated"] else "full length")
    print(f"flew {summary['scenario']['env_id']} with {args.policy}: {summary['steps']} samples, "
          f"{summary['duration_s']:.2f} s ({ending}; {summary['collisions']} collision(s))")
    flown = ", ".join(f"{e['name']}({', '.join(f'{k}={v}' for k, v in e['params'].items())})"
                      for e in summary["scenario"]["effects"]) or "none"
    print(f"effects flown (kept out of the log): {flown}")
    for path in summary["files"]:
        print(f"wrote {path}")
    if not math.isfinite(log.t[-1]):
        return 1
    return 0
