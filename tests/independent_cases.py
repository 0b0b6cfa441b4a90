"""Classes of logs from the second simulator (:mod:`tests.independent_sim`) and what discovery should say of each.

Run as a user would: each log is written as CSV and sidecar, then ``wall-inspector discover`` reads it::

    python -m tests.independent_cases --seeds 201,202 --json indep.json      # every class, three rates
    python -m tests.independent_cases --seeds 201 --cases gust,finite_wall   # some of them
    python -m tests.independent_cases --seeds 201 --long                     # with the 360 s offset logs
    python -m tests.independent_cases --seeds 201 --turn 35 --shift 1.5,-2   # logged in a turned, shifted frame
    python -m tests.independent_cases --seeds 201 --rotor-radius 0.17 --plus # another vehicle's rotor layout

Each case says which effects are flown (in the library's terms where the library has them), whether a
residual the library cannot describe is left (and where it lives), and what else the report must say (a
sidecar error, ground contact left out). :func:`judge` compares a report with that: named right with nothing
spurious, every parameter within 10 %, no held-out gap above the nominal model's, an unexplained residual of
more than 3 % of the weight reported with where it lives. Seeds 101-110 were used to develop discovery's
checks; evaluate on others.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tests import independent_sim
from tests.independent_sim import CEILING_Z, GRAVITY, MASS, NEAR_WALL, fly, turbulence, write

WALL = {"centre": (0.25, 0.0, 1.0), "amplitude": (0.09, 0.5, 0.25), "period": (7.0, 9.0, 3.0), "gains": NEAR_WALL}
OPEN = {"centre": (1.5, 0.0, 1.0), "amplitude": (1.0, 1.0, 0.4), "period": (5.0, 6.0, 3.0)}
FAST = {"centre": (1.5, 0.0, 1.0), "amplitude": (2.0, 2.0, 0.4), "period": (5.0, 6.0, 3.0)}
GROUND = {"centre": (1.5, 0.0, 0.12), "amplitude": (0.6, 0.6, 0.06), "period": (7.0, 9.0, 4.0)}
GROUND_CLOSE = {"centre": (1.5, 0.0, 0.09), "amplitude": (0.6, 0.6, 0.05), "period": (7.0, 9.0, 5.0)}
_UNDER_CEILING = {"kp": [6.0, 6.0, 40.0], "kd": [4.0, 4.0, 12.0], "ki": [1.0, 1.0, 20.0]}  # beats the ceiling's pull
CEILING = {"centre": (1.5, 0.0, CEILING_Z - 0.13), "amplitude": (0.6, 0.6, 0.05), "period": (7.0, 9.0, 4.0),
           "gains": _UNDER_CEILING}
# close under a ceiling its pull beats the loop above: a seed-207 flight planned down to 5.5 cm came to 2.9 cm, where
# this simulator's gain saturates (at 0.6 of the radius) and the library's does not yet (at half of it)
_CLOSE_UNDER_CEILING = {"kp": [6.0, 6.0, 100.0], "kd": [4.0, 4.0, 20.0], "ki": [1.0, 1.0, 100.0]}
CEILING_CLOSE = {"centre": (1.5, 0.0, CEILING_Z - 0.105), "amplitude": (0.6, 0.6, 0.045), "period": (7.0, 9.0, 5.0),
                 "gains": _CLOSE_UNDER_CEILING}
TALL_WALL = {"centre": (0.25, 0.0, 1.2), "amplitude": (0.09, 0.5, 0.45), "period": (7.0, 9.0, 5.0), "gains": NEAR_WALL}
TALL = {"centre": (1.5, 0.0, 1.2), "amplitude": (1.0, 1.0, 0.5), "period": (5.0, 6.0, 6.0)}
RATES = (100.0, 50.0, 200.0)
#: where the finite wall ends: 1.2 m up (the survey spans 0.75-1.65 m), or with ``--wall-end side`` 0.15 m along the
#: wall (y; the survey spans -0.5 to 0.5 m)
WALL_ENDS = {"top": {"wall_top": 1.2}, "side": {"wall_side": 0.15}}
WALL_END = WALL_ENDS["top"]
_REACH = independent_sim.reach_toward_wall()  # m: the default layout's
WEIGHT = MASS * GRAVITY
#: parameters in the world's frame: turned back from the log's frame to be judged (the drags' coefficients are in
#: body axes)
WORLD_FRAME_PARAMETERS = {("constant_force", "F"), ("quadratic_drag", "w")}
#: draw each case's parameters from the wide ranges (``--wide``)
WIDE = False
UNEXPLAINED_SHARE = 0.03  # of the weight: a log leaving more must say so, with where it lives


@dataclass
class Case:
    """One class of log: what is flown, and what discovery should name."""

    name: str
    effects: dict[str, Any]
    flight: dict[str, Any]
    expected: dict[str, dict[str, Any]] = field(default_factory=dict)  # effect name -> true library parameters
    write: dict[str, Any] = field(default_factory=dict)  # keywords of independent_sim.write
    duration: float = 60.0
    motor_lag: float = 0.0
    takeoff: bool = False
    unexplained: str | None = None  # where a residual the library cannot describe lives: "time", "height", ...
    says: tuple[str, ...] = ()  # phrases the report's notes or limits must hold
    long: bool = False  # a 360 s log, run with --long only
    rate: float | None = None  # a fixed rate (else the rates cycle)
    unseen_wall: float | None = None  # a wall at x = 0 the scene does not have stops guards of this radius (m)


def cases(seed: int) -> list[Case]:
    """Every class, with parameters drawn from ``seed`` (in the second simulator's and the library's terms); with
    :data:`WIDE`, from ranges two to four times as wide (and a motor lag drawn too)."""
    if WIDE:
        return _cases_wide(seed)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x1D]))
    u = lambda low, high: float(rng.uniform(low, high))  # noqa: E731
    k_s, d_thr = u(4.5, 7.0), u(0.115, 0.14)
    wind = [u(0.2, 0.4) * s for s in (1, -1)] + [u(-0.3, -0.15)]
    D = [u(0.15, 0.3), u(0.15, 0.3), u(0.3, 0.45)]
    C, w_air = [u(0.08, 0.14), u(0.07, 0.12), u(0.05, 0.09)], [u(1.2, 2.0), -u(0.8, 1.5), 0.0]
    radius, ceiling_radius = u(0.07, 0.09), u(0.07, 0.09)
    scale, offset = u(0.88, 0.93), u(-1.6, -0.9)
    gust_f = u(0.2, 0.3)
    return _cases(rng, k_s, d_thr, wind, D, C, w_air, radius, ceiling_radius, scale, offset, gust_f, 0.03)


def _cases_wide(seed: int) -> list[Case]:
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x1D, 0x3E]))
    u = lambda low, high: float(rng.uniform(low, high))  # noqa: E731
    sign = lambda: float(rng.choice([-1.0, 1.0]))  # noqa: E731
    k_s, d_thr = u(2.5, 10.0), u(0.09, 0.19)
    wind = [u(0.1, 0.8) * sign(), u(0.1, 0.8) * sign(), u(0.1, 0.5) * sign()]
    D = [u(0.06, 0.5), u(0.06, 0.5), u(0.1, 0.7)]
    C, w_air = [u(0.04, 0.22), u(0.04, 0.22), u(0.03, 0.15)], [u(0.5, 3.0) * sign(), u(0.5, 3.0) * sign(), 0.0]
    radius, ceiling_radius = u(0.05, 0.11), u(0.05, 0.11)
    # a scale within 3 % of 1 and an offset within 0.3 N of 0 act as no effect: moved to those edges (seed 7944 drew
    # 1.0004 and -0.007 N, a clean log that was counted as a thrust scale missed)
    scale, offset = _away_from(u(0.8, 1.15), 1.0, 0.03), _away_from(u(-2.0, 1.5), 0.0, 0.3)
    gust_f = u(0.1, 0.6)
    return _cases(rng, k_s, d_thr, wind, D, C, w_air, radius, ceiling_radius, scale, offset, gust_f, u(0.015, 0.06))


def _away_from(value: float, null: float, margin: float) -> float:
    """``value`` moved out of ``null +- margin`` to the nearer edge."""
    if abs(value - null) >= margin:
        return value
    return null + math.copysign(margin, value - null)


def _cases(rng: np.random.Generator, k_s: float, d_thr: float, wind: list[float], D: list[float], C: list[float],
           w_air: list[float], radius: float, ceiling_radius: float, scale: float, offset: float, gust_f: float,
           lag: float) -> list[Case]:
    u = lambda low, high: float(rng.uniform(low, high))  # noqa: E731
    out = [
        Case("clean", {}, OPEN),
        Case("suction", {"suction": (k_s, d_thr)}, WALL, {"wall_suction": {"k_s": k_s, "d_thr": d_thr}}),
        Case("suction_wind", {"suction": (k_s, d_thr), "wind_force": wind}, WALL,
             {"wall_suction": {"k_s": k_s, "d_thr": d_thr}, "constant_force": {"F": wind}}),
        Case("ground", {"ground": (radius, 0.0)}, GROUND, {"ground_effect": {"radius": radius}}, {"wall": False}),
        Case("ceiling", {"ceiling": (ceiling_radius, 0.0)}, CEILING, {"ceiling_effect": {"radius": ceiling_radius}},
             {"wall": False, "ceiling": True}),
        Case("wind", {"wind_force": wind}, OPEN, {"constant_force": {"F": wind}}, {"wall": False}),
        Case("linear_drag", {"linear_drag": D}, OPEN, {"linear_drag": {"D": D}}, {"wall": False}),
        Case("thrust_scale", {"thrust_scale": scale}, OPEN, {"thrust_scale": {"scale": scale}}, {"wall": False}),
        Case("quadratic_drag_wind", {"quadratic_drag": (C, w_air)}, FAST, {"quadratic_drag": {"C": C, "w": w_air}},
             {"wall": False}),
        Case("motor_lag", {"linear_drag": D}, OPEN, {"linear_drag": {"D": D}}, {"wall": False}, motor_lag=lag),
        # ---- beyond the library, and a sidecar that is wrong
        Case("reversed_normal", {"suction": (k_s, d_thr)}, WALL, {"wall_suction": {"k_s": k_s, "d_thr": d_thr}},
             {"wall_normal": -1.0}, says=("flip the sign of scene.walls[0].normal",)),
        Case("gust", {"gust": ([u(0.4, 0.6), -u(0.3, 0.5), u(0.2, 0.4)], gust_f)}, OPEN, {}, {"wall": False},
             unexplained="time"),
        Case("gust_wind", {"wind_force": wind, "gust": ([u(0.25, 0.35), u(0.2, 0.3), 0.0], gust_f)}, OPEN,
             {"constant_force": {"F": wind}}, {"wall": False}, unexplained="time"),
        Case("turbulence", {"turbulence": ([u(0.35, 0.5), u(0.35, 0.5), u(0.25, 0.35)], 2.0)}, OPEN, {},
             {"wall": False}, unexplained="time"),
        Case("finite_wall", {"suction": (k_s, d_thr), **WALL_END}, TALL_WALL,
             {"wall_suction": {"k_s": k_s, "d_thr": d_thr}}, says=("wall 0 seems to end",)),
        Case("height_force", {"height_force": u(0.6, 0.9)}, TALL, {}, {"wall": False}, unexplained="height"),
        Case("ground_contact", {"linear_drag": D}, OPEN, {"linear_drag": {"D": D}}, {"wall": False}, takeoff=True,
             says=("ground",)),
        Case("thrust_map", {"thrust_scale": scale, "thrust_offset": offset}, OPEN,
             {"thrust_scale": {"scale": scale, "offset": offset}}, {"wall": False}),
        Case("unseen_wall", {"quadratic_drag": (C, w_air)}, FAST, {"quadratic_drag": {"C": C, "w": w_air}},
             {"wall": False}, unseen_wall=0.04, says=("struck a surface the scene does not have",)),
        # ---- long logs (a distance offset needs slow, close passes)
        Case("ground_offset", {"ground": (radius, 0.012)}, GROUND_CLOSE,
             {"ground_effect": {"radius": radius, "offset": 0.012}}, {"wall": False}, duration=360.0, long=True),
        Case("ceiling_offset", {"ceiling": (ceiling_radius, 0.012)}, CEILING_CLOSE,
             {"ceiling_effect": {"radius": ceiling_radius, "offset": 0.012}}, {"wall": False, "ceiling": True},
             duration=360.0, long=True),
    ]
    return out


def _effects_for_flight(case: Case, seed: int) -> dict[str, Any]:
    effects = dict(case.effects)
    if "turbulence" in effects:
        std, time_constant = effects["turbulence"]
        total = case.duration + 30.0
        effects["turbulence"] = turbulence(std, time_constant, total, seed + 7)
    return effects


@contextlib.contextmanager
def _wall_guard(radius: float | None) -> Iterator[None]:
    """The second simulator's wall at x = 0 stops guards of ``radius`` (None: it lets the vehicle through) while
    flying."""
    guard = independent_sim.WALL_GUARD_RADIUS
    independent_sim.WALL_GUARD_RADIUS = radius
    try:
        yield
    finally:
        independent_sim.WALL_GUARD_RADIUS = guard


def fly_case(case: Case, seed: int, rate: float, folder: Path, waypoints: float = 0.0) -> Path:
    """Fly ``case`` and write its log into ``folder``; returns the CSV path. ``waypoints``: see
    :func:`tests.independent_sim.fly` (0: the sinusoidal survey)."""
    # --wall-guard acts in worlds whose scene has a wall (a world without one has nothing to strike), and a case's
    # unseen wall in its own world
    walled = case.write.get("wall", True)
    guard = independent_sim.WALL_GUARD_RADIUS if walled else case.unseen_wall
    flight = dict(case.flight)
    if walled:  # the same distances from the wall for the rotor nearest it, whatever the rotor layout
        flight["centre"] = (flight["centre"][0] + independent_sim.reach_toward_wall() - _REACH, *flight["centre"][1:])
    with _wall_guard(guard):
        rows = fly(_effects_for_flight(case, seed), duration=case.duration, rate_hz=rate, seed=seed,
                   motor_lag=case.motor_lag, takeoff=case.takeoff, waypoints=waypoints, **flight)
    return write(rows, folder / f"{case.name}_{seed}.csv", seed=seed, **case.write)


def discover(paths: list[Path], out: Path, extra: tuple[str, ...] = ()) -> dict:
    """``wall-inspector discover`` on ``paths`` (in this process); returns the report."""
    from wall_inspector.cli import main

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer), contextlib.redirect_stderr(io.StringIO()):
        code = main(["discover", *map(str, paths), "--out", str(out), "--no-plots", "--quiet", *extra])
    if code != 0:
        raise RuntimeError(f"discover failed on {paths}")
    report = json.loads((out / "report.json").read_text())
    report["_summary"] = buffer.getvalue()
    return report


def relative_error(fitted: Any, truth: Any) -> float:
    f, v = np.atleast_1d(np.asarray(fitted, float)), np.atleast_1d(np.asarray(truth, float))
    if f.shape != v.shape:
        return math.inf
    nonzero = np.abs(v) > 1e-9
    errors = np.abs(f - v)[nonzero] / np.abs(v)[nonzero]
    return float(errors.max()) if errors.size else 0.0


def _report_name(effect: dict) -> str:
    return effect["name"]


def judge(case: Case, report: dict) -> dict:
    """What ``report`` said of ``case`` against what was flown."""
    named = {_report_name(e): e for e in report["effects"]}
    expected = set(case.expected)
    errors: dict[str, float | None] = {}
    for name, truth in case.expected.items():
        effect = named.get(name)
        for key, value in truth.items():
            fitted = None if effect is None else effect["params"].get(key)
            if fitted is not None and (name, key) in WORLD_FRAME_PARAMETERS:
                fitted = independent_sim.from_log_world(fitted)
            errors[f"{name}.{key}"] = None if fitted is None else relative_error(fitted, value)
    lag = report.get("motor_lag") or {}
    if case.motor_lag:
        tau = lag.get("time_constant_s") if lag.get("kept") else None
        errors["motor_lag.time_constant"] = None if tau is None else abs(tau - case.motor_lag) / case.motor_lag
    before, after = report["gap_before"]["force_rms_N"], report["gap_after"]["force_rms_N"]
    unexplained = report.get("unexplained")
    floor = (report.get("noise") or {}).get("floor_N")
    excess = math.sqrt(max(after**2 - (floor or 0.0) ** 2, 0.0)) if after is not None else None
    text = " ".join(report.get("notes") or []) + " " + " ".join(x["reason"] for x in report.get("limits") or [])
    text += " " + report.get("_summary", "")
    must_say = excess is not None and excess > UNEXPLAINED_SHARE * WEIGHT
    said_where = bool(unexplained and unexplained.get("where"))
    where_text = json.dumps(unexplained or {})
    # the report says a parameter is uncertain when it calls it loose, undetermined (nulled), or names it in a limit
    # (a lag it cannot tell from it)
    said = {f"{x['effect']}.{x['parameter']}".split("[")[0] for x in (report.get("loose") or []) +
            (report.get("undetermined") or [])}
    said |= {f"{effect}.{key}" for limit in report.get("limits") or [] for effect in limit["effects"]
             for name, truth in case.expected.items() if name == effect for key in truth
             if f"{effect} {key}" in limit["reason"]}
    if lag.get("to_narrow"):
        said.add("motor_lag.time_constant")
    off = sorted(k for k, e in errors.items() if e is not None and e > 0.10)
    return {
        "case": case.name,
        "named": sorted(named),
        "named_right": set(named) == expected,
        "spurious": sorted(set(named) - expected),
        "missing": sorted(expected - set(named)),
        "param_errors": errors,
        "params_within_10_percent": all(e is not None and e <= 0.10 for e in errors.values()),
        "off_said_uncertain": {k: k in said for k in off},  # parameters more than 10 % off: did the report say so?
        "gap_before_N": before,
        "gap_after_N": after,
        "gap_not_worse": after is None or before is None or after <= before,
        "noise_floor_N": floor,
        "unexplained_N": None if unexplained is None else unexplained.get("force_rms_N"),
        "unexplained_excess_share_of_weight": None if excess is None else excess / WEIGHT,
        "unexplained_said_where": said_where,
        "unexplained_ok": (said_where if must_say else True) and
                          (case.unexplained is None or (said_where and case.unexplained in where_text)),
        "says": {phrase: phrase in text for phrase in case.says},
        "motor_lag_kept": bool(lag.get("kept")),
        "runtime_s": (report.get("details") or {}).get("runtime_s"),
    }


def winds_case(seed: int) -> tuple[dict, list[dict]]:
    """Flights at three steady winds with air-relative quadratic drag: the shared C and each flight's wind."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x3D]))
    C = [float(rng.uniform(0.08, 0.13)), float(rng.uniform(0.07, 0.12)), float(rng.uniform(0.05, 0.09))]
    winds = []
    for speed in (2.0, 4.0, 6.0):
        heading = float(rng.uniform(-0.6, 0.6))
        winds.append([speed * math.cos(heading), speed * math.sin(heading), 0.0])
    return {"C": C}, [{"w": w} for w in winds]


def run_winds(seed: int, rate: float, folder: Path, n_flights: int = 3, waypoints: float = 0.0) -> dict:
    """Fly the winds case, discover across its flights, and judge the shared drag and each wind."""
    shared, flights = winds_case(seed)
    paths = []
    for i, flight in enumerate(flights[:n_flights]):
        with _wall_guard(None):
            rows = fly({"quadratic_drag": (shared["C"], flight["w"])}, duration=60.0, rate_hz=rate,
                       seed=seed * 10 + i, waypoints=waypoints, **FAST)
        paths.append(write(rows, folder / f"winds_{seed}_{i}.csv", seed=seed * 10 + i, wall=False))
    report = discover(paths, folder / f"winds_{seed}")
    effect = next((e for e in report["effects"] if e["name"] == "quadratic_drag"), None)
    out: dict[str, Any] = {"case": "winds", "named": sorted(e["name"] for e in report["effects"])}
    out["named_right"] = out["named"] == ["quadratic_drag"]
    if effect is not None:
        out["C_error"] = relative_error(effect["params"]["C"], shared["C"])
        per_flight = (report.get("flights") or {}).get("conditions") or []
        wind_errors = []
        for flight, record in zip(flights, per_flight):
            fitted = (record.get("quadratic_drag") or {}).get("w")
            true = np.asarray(flight["w"])
            off = None if fitted is None else independent_sim.from_log_world(fitted) - true
            wind_errors.append(None if off is None else float(np.linalg.norm(off) / np.linalg.norm(true)))
        out["wind_errors"] = wind_errors
    held = (report.get("flights") or {}).get("held_out") or []
    out["held_out_ratio"] = [h.get("ratio_to_in_sample") for h in held]
    out["gap_before_N"], out["gap_after_N"] = report["gap_before"]["force_rms_N"], report["gap_after"]["force_rms_N"]
    out["runtime_s"] = (report.get("details") or {}).get("runtime_s")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", default="201")
    parser.add_argument("--cases", default=None, help="comma-separated case names (default all; 'winds' included)")
    parser.add_argument("--long", action="store_true", help="also the 360 s distance-offset logs")
    parser.add_argument("--json", default=None)
    parser.add_argument("--keep", default=None, help="folder to keep the logs and reports in")
    parser.add_argument("--waypoints", type=float, default=0.0,
                        help="fly every survey between waypoints (tanh sharpness, 2 is brisk; 0: sinusoids)")
    parser.add_argument("--gain-floor", type=float, default=independent_sim.GAIN_FLOOR_RADII,
                        help="radii at which the image-rotor gain levels off (default %(default)s; the library's: 0.5)")
    parser.add_argument("--mass", type=float, default=independent_sim.MASS,
                        help="the vehicle's mass, kg (default %(default)s); the loop's gains are accelerations, so a "
                             "light vehicle resists wall suction's pull (N/m) less")
    parser.add_argument("--wall-guard", type=float, default=None,
                        help="the wall stops each rotor's guard of this radius, m, in worlds whose scene has a wall "
                             "(default: the vehicle passes through)")
    parser.add_argument("--ceiling-guard", type=float, default=None,
                        help="the ceiling stops each rotor's guard of this radius, m (default: the vehicle passes "
                             "through)")
    parser.add_argument("--turn", type=float, default=0.0,
                        help="write each log in a frame turned by this many degrees about z (the flight is the same)")
    parser.add_argument("--shift", default="0,0", help="and shifted by this x,y (m)")
    parser.add_argument("--rotor-radius", type=float, default=None,
                        help=f"the rotors' distance from the centre, m (default {independent_sim.ROTOR_RADIUS})")
    parser.add_argument("--plus", action="store_true", help="rotors on the body axes (default: on the diagonals)")
    parser.add_argument("--corridor", type=float, default=None,
                        help="in worlds whose scene has a wall, a second wall this far (m) from it, facing it, with the "
                             "same suction")
    parser.add_argument("--accelerometer", action="store_true", help="the logs have ax, ay, az too")
    parser.add_argument("--wall-end", choices=sorted(WALL_ENDS), default="top",
                        help="where the finite wall ends: at its top (default) or at its side")
    parser.add_argument("--noise", type=float, default=1.0, help="measurement noise times this (default 1)")
    parser.add_argument("--wide", action="store_true",
                        help="draw the parameters from ranges two to four times as wide (a thrust scale above 1, a "
                             "positive offset, weak and strong suction, winds of either sign, a motor lag of 15-60 ms)")
    parser.add_argument("--yaw-swing", default="0,0",
                        help="the heading swings by this amplitude (deg) with this period (s) instead of holding 0")
    args = parser.parse_args(argv)
    if not 0.25 < args.gain_floor < 5.0:  # at a quarter of the radius the image-rotor gain is infinite
        parser.error(f"--gain-floor must be in (0.25, 5) radii, got {args.gain_floor}")
    if not 0.1 <= args.mass <= 20.0:
        parser.error(f"--mass must be in [0.1, 20] kg, got {args.mass}")
    if args.wall_guard is not None and not 0.0 < args.wall_guard < 0.3:
        parser.error(f"--wall-guard must be in (0, 0.3) m, got {args.wall_guard}")
    if args.ceiling_guard is not None and not 0.0 < args.ceiling_guard < 0.3:
        parser.error(f"--ceiling-guard must be in (0, 0.3) m, got {args.ceiling_guard}")
    if args.rotor_radius is not None and not 0.05 <= args.rotor_radius <= 0.5:
        parser.error(f"--rotor-radius must be in [0.05, 0.5] m, got {args.rotor_radius}")
    if not 0.0 <= args.noise <= 20.0:
        parser.error(f"--noise must be in [0, 20], got {args.noise}")
    if args.corridor is not None and not 0.3 <= args.corridor <= 10.0:
        parser.error(f"--corridor must be in [0.3, 10] m, got {args.corridor}")
    shift = tuple(float(x) for x in args.shift.split(","))
    if len(shift) != 2:
        parser.error(f"--shift must be two numbers x,y, got {args.shift!r}")
    swing = tuple(float(x) for x in args.yaw_swing.split(","))
    if len(swing) != 2 or not 0.0 <= swing[0] <= 90.0 or (swing[0] and not 1.0 <= swing[1] <= 600.0):
        parser.error(f"--yaw-swing must be amplitude,period with amplitude in [0, 90] deg and period in [1, 600] s, "
                     f"got {args.yaw_swing!r}")
    independent_sim.YAW_SWING = (math.radians(swing[0]), swing[1])
    global WEIGHT, WALL_END, WIDE
    WIDE = args.wide
    WALL_END = WALL_ENDS[args.wall_end]
    independent_sim.WORLD_TURN, independent_sim.WORLD_SHIFT = math.radians(args.turn), shift
    independent_sim.NOISE_SCALE, independent_sim.ACCELEROMETER = args.noise, args.accelerometer
    independent_sim.SECOND_WALL_X = args.corridor
    if args.rotor_radius is not None or args.plus:
        radius = args.rotor_radius if args.rotor_radius is not None else independent_sim.ROTOR_RADIUS
        independent_sim.ROTORS_BODY = independent_sim.rotor_layout(radius, args.plus)
    independent_sim.GAIN_FLOOR_RADII = args.gain_floor
    independent_sim.MASS, WEIGHT = args.mass, args.mass * GRAVITY
    independent_sim.WALL_GUARD_RADIUS = args.wall_guard
    independent_sim.CEILING_GUARD_RADIUS = args.ceiling_guard
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    wanted = None if args.cases is None else {c.strip() for c in args.cases.split(",")}
    records = []
    folder_context = tempfile.TemporaryDirectory() if args.keep is None else contextlib.nullcontext(args.keep)
    with folder_context as folder_name:
        folder = Path(folder_name)
        folder.mkdir(parents=True, exist_ok=True)
        index = 0
        for seed in seeds:
            for case in cases(seed):
                if (wanted is not None and case.name not in wanted) or (case.long and not args.long):
                    continue
                rate = case.rate or RATES[index % len(RATES)]
                index += 1
                started = time.perf_counter()
                path = fly_case(case, seed, rate, folder, args.waypoints)
                report = discover([path], folder / f"{case.name}_{seed}")
                record = {"seed": seed, "rate_hz": rate, **judge(case, report),
                          "wall_s": round(time.perf_counter() - started, 1)}
                records.append(record)
                errs = list(record["param_errors"].values())
                worst = "missing" if any(e is None for e in errs) else f"{100 * max(errs, default=0.0):.1f} %"
                print(f"{case.name:20s} seed {seed} {rate:5.0f} Hz found {','.join(record['named']) or '-':32s} "
                      f"{'ok ' if record['named_right'] else 'BAD'} params {worst:>8s} gap "
                      f"{record['gap_before_N']:.3f}->{record['gap_after_N']:.3f} N floor "
                      f"{record['noise_floor_N'] or float('nan'):.3f} unexpl "
                      f"{'ok ' if record['unexplained_ok'] else 'BAD'} says {record['says']}", flush=True)
            if wanted is None or "winds" in wanted:
                rate = RATES[index % len(RATES)]
                index += 1
                record = {"seed": seed, "rate_hz": rate, **run_winds(seed, rate, folder, waypoints=args.waypoints)}
                records.append(record)
                shown = {k: v for k, v in record.items() if k not in ("seed", "rate_hz")}
                print(f"{'winds':20s} seed {seed} {rate:5.0f} Hz {json.dumps(shown)}", flush=True)
    singles = [r for r in records if r["case"] != "winds"]
    print(f"named right with nothing spurious: {sum(r['named_right'] for r in singles)}/{len(singles)}; "
          f"all parameters within 10 %: {sum(r['named_right'] and r['params_within_10_percent'] for r in singles)}; "
          f"gap never above the nominal's: {sum(r['gap_not_worse'] for r in singles)}/{len(singles)}; "
          f"unexplained said right: {sum(r['unexplained_ok'] for r in singles)}/{len(singles)}; "
          f"parameters more than 10 % off said uncertain: {sum(sum(r['off_said_uncertain'].values()) for r in singles)}/"
          f"{sum(len(r['off_said_uncertain']) for r in singles)}")
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
