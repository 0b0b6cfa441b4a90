"""Hidden-effect logs for checking discovery: effects (and the literature's fuller forms) flown, then found.

:func:`draw` picks parameters in realistic ranges for one *form* of :data:`FORMS` and a
flight that excites it; :func:`draw_pair` two forms flown together. :func:`check`
flies such logs with ``discovery.fly`` (PID, simulator command noise, default
measurement noise), runs :class:`~discovery.workflow.Discovery` on them, told nothing,
and compares what it found with what was flown. ``wall-inspector bench-discover
--acceptance`` prints the figures.

Ranges: wall suction k_s 3.5-8 N/m, d_thr 0.11-0.15 m (paper: 4.1 N/m, 0.132 m);
ground and ceiling effective radius 6-10 cm and 5-8 cm (6-9 cm with the distance offset
of 1-4 cm, flown for at least 360 s, 3.5 to 20 cm above the ground or 5 to 22 cm under the ceiling;
paired with a steady force or a thrust scale, also 120 s of that effect's own flight away from the surface);
under a ceiling the vertical loop is stiffer than the ceiling survey's (Kp 100 against 30), and the plain
effect is flown 5.5 to 14.5 cm from it; a steady force paired with wall suction
points away from the wall;
thrust error 5-15 % either way; steady force 0.15-0.5 N per axis; extra linear drag
0.1-0.4 N s/m per axis; quadratic drag 0.05-0.15 N s^2/m^2 per axis, with a steady
horizontal wind of 1-3 m/s in the ``_wind`` form.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

__all__ = ["FORMS", "PAIRS", "draw", "draw_pair", "spec", "fly_and_discover"]

ARM = 0.1 / math.sqrt(2.0)  # the default vehicle's rotor offset along body x (m)
FORMS = ("wall_suction", "wall_suction_scaled", "ground_effect", "ground_effect_offset", "ceiling_effect",
         "ceiling_effect_offset", "thrust_scale", "constant_force", "linear_drag", "quadratic_drag",
         "quadratic_drag_wind")
PAIRS = (("wall_suction", "constant_force"), ("wall_suction_scaled", "constant_force"),
         ("ground_effect_offset", "constant_force"), ("ceiling_effect_offset", "thrust_scale"),
         ("ground_effect", "thrust_scale"), ("linear_drag", "constant_force"), ("quadratic_drag_wind", "thrust_scale"),
         ("thrust_scale", "constant_force"), ("quadratic_drag", "constant_force"))
_NEAR_WIDE = {"amplitude": (0.6, 0.6, 0.085), "period": (7.0, 9.0, 3.5)}  # 0.05 to 0.22 m from the surface
# The offset k2 shows where the distance is comparable to it. Planned down to 3.5 cm (the ground's push keeps the
# vehicle at about 4.2 cm), the spread of k2 over noise seeds fell from 16 % to 10 % against 5 cm (ground alone,
# r 7.5 cm, k2 2.5 cm, 100 Hz, 30 s); planned down to 3 cm, one flight in 15 touched the ground. Under a ceiling the
# pull carried the vehicle into it from 4.5 cm, so that survey keeps 5 cm. The spread is set by the thrust noise
# the log does not record (smoothing windows of 0.4 to 1.5 s give the same estimates), so the other lever is time.
_GROUND_CLOSE = {"amplitude": (0.6, 0.6, 0.0825), "period": (7.0, 9.0, 5.0), "centre": (1.5, 0.0, 0.1175)}
# 5 cm under a ceiling its pull (negative stiffness growing as 1 / d^3) beat the ceiling survey's vertical loop
# (Kp 30, Kv 11, Ki 30): with strong effects drawn (r 7-9 cm, k2 1-2 cm, five settings of thrust error and rate,
# three seeds each) 15 of 15 flights hit the ceiling on their first approach; twice as stiff, 3 of 15 did (r 9 cm,
# k2 1 cm, thrust 14 % short, 50 Hz). A thrust short of the command weakens the loop by the same share, and at 50 Hz
# Kp 60 still hit the ceiling in 6 of 6 40 s flights with that effect and in 8 of 8 with r 8.5 cm, k2 1.5 cm and the
# thrust 10 % short (a draw of seed 27); Kp 100 with Kv 20 and Ki 100 hit it in none of those 14 flights, keeping
# 2.5 cm and 3.3 cm
_CEILING_CLOSE_GAINS = {"kp": [8.0, 8.0, 100.0], "kv": [4.0, 4.0, 20.0], "ki": [0.0, 0.0, 100.0]}
# A weak ceiling effect's held-out gap is bounded by the thrust noise the log does not record (on one log of
# seed 12 the true effect itself removed only 80.4 %): at 50 Hz the ceiling survey (8 to 20 cm, Kp 30) left 5 of
# the 12 plain ceiling logs of seeds 1-12 and 6 of 12 of seeds 13-24 below an 80 % reduction, the worst at 65 %.
# Flown 5.5 to 14.5 cm from the ceiling with the stiffer loop, the worst of seeds 1-24 at 50 Hz was 83 % (84 % with
# Kp 60); the strongest plain effect drawn (r 8 cm) pulled that flight to 3.7-4.0 cm in 18 flights at 50 and
# 100 Hz (2.5-2.8 cm with Kp 60; the ducts touch at 1.75 cm)
_CEILING_NEAR = {"amplitude": (0.6, 0.6, 0.045), "period": (7.0, 9.0, 3.5), "centre": (1.5, 0.0, 1.90)}
#: a distance offset and its radius are two parameters of one curve: their flights last at least this long (s).
#: Over seeds 13-24 at 50 and 100 Hz (72 offset logs, singly and paired with a steady force or a thrust scale),
#: 30 missed 10 % at 90 s, 23 at 180 s and 15 at 360 s (ceiling flights with Kp 60); the ground offset alone
#: missed 5 of 24 at 90 s, none at 360 s
OFFSET_MIN_DURATION = 360.0
#: a distance offset paired with a steady force or a thrust scale: the second effect's own flight (s), a second log.
#: Over seeds 13-24 at 50 and 100 Hz (48 pair logs, 360 s near the surface) the offset missed 10 % in 16 without it
#: and in 3 with it; on seeds 36-43, in 4 of 32 with it (10.2 to 15.7 %, 1.4 to 2.4 standard errors)
AWAY_DURATION = 120.0
_AWAY_SEED = 1 << 30  # the away flight's seed is the pair's plus this


def _suction_survey(k_s: float, d_thr: float) -> dict[str, Any]:
    d_min = max(0.075, d_thr - min(0.06, 0.5 / (2 * k_s)))  # pull at most ~0.5 N, never nearer than 7.5 cm
    d_max = d_thr + 0.03
    # climbing and descending briskly (0.3 m at 3 s: +-1.3 m/s^2, the thrust +-13 %) tells suction
    # scaled by rotor thrust from the plain form (27 of 27 logs of seeds 1-7); at a 5 s period
    # (+-5 %) neither was told (the plain form kept in 8 of 8 scaled logs); at 2.5 s one flight hit the wall
    return {"amplitude": ((d_max - d_min) / 2, 0.6, 0.3), "period": (6.0, 9.0, 3.0),
            "centre": ((d_max + d_min) / 2 + ARM, 0.0, 1.0)}


def draw(form: str, rng: np.random.Generator) -> tuple[dict[str, Any], dict[str, Any]]:
    """``({"name", "params"}, fly keywords)`` for one form of :data:`FORMS`."""
    params: dict[str, Any]
    if form.startswith("wall_suction"):
        k_s, d_thr = rng.uniform(3.5, 8.0), rng.uniform(0.11, 0.15)
        params = {"k_s": k_s, "d_thr": d_thr}
        if form == "wall_suction_scaled":
            params["thrust_scaling"] = True
        return {"name": "wall_suction", "params": params}, {"scenario": "wall-survey",
                                                             "survey": _suction_survey(k_s, d_thr)}
    if form.startswith("ground_effect"):
        params = {"radius": rng.uniform(0.06, 0.10)}
        if form == "ground_effect_offset":  # two parameters of one curve: passes close to the ground tell them apart
            params = {"radius": rng.uniform(0.06, 0.09), "offset": rng.uniform(0.01, 0.04)}
            return {"name": "ground_effect", "params": params}, {
                "scenario": "ground-survey", "survey": _GROUND_CLOSE, "min_duration": OFFSET_MIN_DURATION}
        return {"name": "ground_effect", "params": params}, {"scenario": "ground-survey"}
    if form.startswith("ceiling_effect"):
        params = {"radius": rng.uniform(0.05, 0.08)}
        if form == "ceiling_effect_offset":
            params = {"radius": rng.uniform(0.06, 0.09), "offset": rng.uniform(0.01, 0.04)}
            return {"name": "ceiling_effect", "params": params}, {
                "scenario": "ceiling-survey", "survey": {**_NEAR_WIDE, "centre": (1.5, 0.0, 1.865)},
                "policy_kwargs": _CEILING_CLOSE_GAINS, "min_duration": OFFSET_MIN_DURATION}
        return {"name": "ceiling_effect", "params": params}, {
            "scenario": "ceiling-survey", "survey": _CEILING_NEAR, "policy_kwargs": _CEILING_CLOSE_GAINS}
    if form == "thrust_scale":
        return {"name": form, "params": {"scale": 1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.05, 0.15)}}, \
            {"scenario": "survey"}
    if form == "constant_force":
        return {"name": form, "params": {"F": list(rng.choice([-1.0, 1.0], 3) * rng.uniform(0.15, 0.5, 3))}}, \
            {"scenario": "survey"}
    if form == "linear_drag":
        return {"name": form, "params": {"D": list(rng.uniform(0.1, 0.4, 3))}}, {"scenario": "survey"}
    if form.startswith("quadratic_drag"):
        params = {"C": list(rng.uniform(0.05, 0.15, 3))}
        if form == "quadratic_drag_wind":
            heading = rng.uniform(0, 2 * math.pi)
            speed = rng.uniform(1.0, 3.0)
            params["w"] = [speed * math.cos(heading), speed * math.sin(heading), 0.0]
        return {"name": "quadratic_drag", "params": params}, {"scenario": "survey"}
    raise ValueError(f"unknown form {form!r}; known: {FORMS}")


def draw_pair(forms: tuple[str, str], rng: np.random.Generator) -> tuple[list[dict], dict[str, Any]]:
    """Two forms flown together, in the flight of the first (the second acts everywhere).

    A form with the distance offset is paired with a second vertical effect (a steady force,
    a thrust scale) whose far-field look-alike is the offset curve's tail; such a pair also
    flies the second form's own flight, away from the surface, for :data:`AWAY_DURATION`
    (the fly keyword ``away``), and discovery reads both logs, as a user would fly both.

    The near-ground and near-ceiling surveys fly a PID with integral action
    (:data:`discovery.scenarios.SCENARIOS`), so a second effect's steady vertical force (a
    thrust scale of 0.85 to 1.15, a steady force of up to 0.5 N) does not shift them off the
    planned distances.
    """
    first, fly_kwargs = draw(forms[0], rng)
    second, second_kwargs = draw(forms[1], rng)
    if first["name"] == "wall_suction" and second["name"] == "constant_force":
        second["params"]["F"][0] = abs(second["params"]["F"][0])  # a breeze off the wall (x = 0, normal +x)
    if forms[0].endswith("_offset"):  # the second effect's own flight, away from the surface, as a second log
        fly_kwargs = {**fly_kwargs, "away": {**second_kwargs, "duration": AWAY_DURATION}}
    return [first, second], fly_kwargs


def spec(effects: list[dict]) -> str:
    """The command-line form of effects, e.g. ``wall_suction:k_s=4.1,d_thr=0.132;constant_force:F=0.2/0/0``."""
    def value(v):
        if isinstance(v, bool):
            return str(v).lower()
        return "/".join(f"{x:.9g}" for x in v) if isinstance(v, (list, tuple, np.ndarray)) else f"{v:.9g}"

    return ";".join(e["name"] + ":" + ",".join(f"{k}={value(v)}" for k, v in e["params"].items()) for e in effects)


def fly_and_discover(effects: list[dict], fly_kwargs: dict[str, Any], seed: int, rate_hz: float = 100.0,
                     duration: float = 30.0) -> dict[str, Any]:
    """Fly ``effects`` hidden, discover, and compare: named right, parameter errors, held-out gap reduction.

    ``fly_kwargs`` are :func:`discovery.fly.fly`'s keywords plus, from :func:`draw` and :func:`draw_pair`,
    ``min_duration`` (s, stretching ``duration``) and ``away`` (a second flight's keywords, flown with the
    same effects and rate and read together with the first log).
    """
    from discovery.fly import fly
    from discovery.workflow import Discovery

    fly_kwargs = dict(fly_kwargs)
    duration = max(duration, fly_kwargs.pop("min_duration", 0.0))
    away = fly_kwargs.pop("away", None)
    flights = [(seed, {**fly_kwargs, "duration": duration})]
    if away is not None:
        flights.append((seed + _AWAY_SEED, dict(away)))
    logs, collisions = [], 0
    for flight_seed, kwargs in flights:
        log, summary = fly(None, "pid", spec(effects), flight_seed, None, rate_hz=rate_hz, **kwargs)
        collisions += summary["collisions"]
        if summary["terminated"]:  # the PID hit a surface: no log to judge discovery by
            return {"flown": effects, "ended_early": True, "collisions": collisions,
                    "duration_s": summary["duration_s"], "rate_hz": rate_hz, "seed": seed}
        logs.append(log)
    started = time.perf_counter()
    found = Discovery().fit(logs)
    runtime = time.perf_counter() - started
    flown = sorted(e["name"] for e in effects)
    named = sorted(found.names_)
    errors: dict[str, float | None] = {}
    sigmas: dict[str, float | None] = {}  # the error in the fit's own standard errors (largest entry)
    for e in effects:
        fitted = next((f for f in found.effects_ if f.name == e["name"]), None)
        stds = next((std for f, std in zip(found.effects_, found.param_std_) if f.name == e["name"]), {})
        for key, true in e["params"].items():
            if isinstance(true, bool):
                continue
            truth = np.atleast_1d(np.asarray(true, dtype=float))
            if fitted is None or key not in fitted.values:
                errors[f"{e['name']}.{key}"] = None
                continue
            got = np.atleast_1d(fitted.values[key])
            std = np.atleast_1d(np.asarray(stds.get(key, np.nan), dtype=float))
            with np.errstate(divide="ignore", invalid="ignore"):
                sigma = np.abs(got - truth) / std
            finite = np.isfinite(sigma)  # entries left at their null value have no standard error
            sigmas[f"{e['name']}.{key}"] = float(np.max(sigma[finite])) if finite.any() else None
            big = np.abs(truth) > 1e-9
            if key == "w":  # a wind vector: error relative to the wind speed
                errors[f"{e['name']}.{key}"] = float(np.linalg.norm(got - truth) / np.linalg.norm(truth))
            else:
                errors[f"{e['name']}.{key}"] = float(np.max(np.abs(got[big] - truth[big]) / np.abs(truth[big])))
    forms_right = all(
        any(f.name == e["name"] and all(f.option_values.get(k) == v for k, v in _options(e).items())
            for f in found.effects_) for e in effects)
    before, after = found.gap_before_["force_rms_N"], found.gap_after_["force_rms_N"]
    return {"flown": effects, "ended_early": False, "named": named, "named_right": named == flown, "form_right": forms_right,
            "spurious": sorted(set(named) - set(flown)), "missed": sorted(set(flown) - set(named)),
            "param_errors": errors, "param_errors_in_std": sigmas, "gap_reduction": 1.0 - after / before if before else None,
            "gap_before_N": before, "gap_after_N": after, "rate_hz": rate_hz, "seed": seed,
            "samples": sum(log.n_samples for log in logs), "collisions": collisions, "runtime_s": runtime,
            "undetermined": [f"{c['effect']}.{c['parameter']}" for c in found.undetermined_],
            "forms_left_open": [limit["effects"][0] for limit in found.limits_ if "[" in limit["effects"][0]],
            "alike": [f"{a['chosen']}~{a['alike']}" for a in found.selection_.alike] if found.selection_ else []}


def _options(effect: dict) -> dict[str, bool]:
    from wall_env.effects import make_effect

    return make_effect(effect["name"], **effect["params"]).option_values
