"""The JSON report of a discovery run.

Keys:

``effects``
    one record per named effect, in the order they were added:
    ``{"name", "params", "param_std", "where", "explained_fraction"}`` with the
    parameters and standard errors in the library's units, where the effect acts
    (:func:`discovery.regressors.describe_force`) and the share of the nominal model's
    held-out force-residual energy it explains. Empty when the data agree with the
    nominal model within noise.
``motor_lag``
    ``null`` when no lag was looked for (the vehicle block gives ``motor_time_constant``,
    or one effect was fitted alone), else the lag fitted next to the chosen effects
    (:mod:`discovery.motor_lag`): ``{"time_constant_s", "std_s", "interval_95_share", "to_narrow",
    "explained", "force_rms_N", "kept", "reason", "determined", "moves", "effect_std"}`` (``interval_95_share``:
    the largest error the 95 % interval allows, as a share of the true time constant; ``to_narrow``: the manoeuvre
    that determines it better when that share is above 10 %, else ``null``; ``moves``: the chosen
    parameter the lag would change most, when by more than 5 % and two standard errors; ``effect_std``: each chosen
    effect's standard errors fitted beside the lag). A kept lag is the model file's vehicle ``motor_time_constant``,
    and the effects above were chosen with it; their ``param_std`` are at least those of ``effect_std``, which carry
    the lag's own uncertainty.
``gap_before``, ``gap_after``
    ``{"force_rms_N", "prediction_rms_m"}`` on held-out data for the nominal and the
    discovered model: RMS of the force residual (vector norm, N) and of the open-loop
    position error at the prediction horizon (m).
``model``
    path of the updated model file (``null`` if not written).
``noise``
    the log's noise floor (:func:`discovery.noise.noise_floor`): ``floor_N``, the held-out rms
    force residual measurement noise and unlogged disturbances leave (a perfect model's), per
    axis, ``floor_upper_N``, its one-sided 95 % upper bound, the fitted noise levels, ``band_top_share`` and
    ``filtered`` (the log's states look filtered), and ``transient_share``, the share of its spectrum segments left
    out of the floor as transients.
``unexplained``
    ``null`` when the held-out residual is within :data:`~discovery.noise.FLOOR_FACTOR` times the
    noise floor's upper bound (or exceeds it by less than 0.2 % of the weight) and no regressor
    localises it;
    else ``{"force_rms_N", "noise_floor_N", "times_noise_floor", "excess_rms_N", "share_of_weight",
    "lives_in", "where", "shape", "position", "position_cells", "time", "direction_world"}``: how much
    is left beyond the noise and where it lives (:mod:`discovery.unexplained`): ``lives_in`` is
    ``states`` (``where``: the regressor, range, direction and times; ``shape``: piecewise linear in
    it), ``position`` (``position``: a region of the flight over height and position along the
    wall; ``position_cells``: the map), ``time (periodic)`` or ``time (slow)`` (``time``: the peak of
    its spectrum's excess over the noise, its amplitude, the share below 0.5 Hz).
``stand_ins``
    effects the selection kept that only stood in for the unexplained residual
    (:mod:`discovery.standins`): ``{"effect", "params", "with_structure", "reason"}``; not written.
``cancelling``
    sets of effects whose forces cancelled each other (look-alikes near hover): their forces, what was
    kept (the simplest account within a parameter's price of the best held-out score) and the manoeuvre
    that separates them (:mod:`discovery.cancelling`).
``wall_edge``
    ``null``, or where wall 0 seems to end (:mod:`discovery.wall_extent`): the axis, the side the wall is on,
    the edge and the share of the fitted suction the data show on either side.
``form_range``
    ``null``, or, when a ground or ceiling effect was kept and the flight came nearer the surface than its
    form is trusted (:mod:`discovery.form_range`): the share and seconds of samples set aside, the parameters
    fitted on everything and (when ``applied``) without them, or why the fit on everything was kept; ``added``
    names such an effect that the fit on every sample had left out and that was taken in within that range;
    ``changed`` the sets it went through (``immaterial``: an effect left out as explaining nothing material
    there); ``set_aside_misfit`` how much worse the fit on everything predicts the samples set aside than the rest
    (``ratio`` of their vertical mean squares, the ``limit`` sampling allows, and ``forms_kept``: within it the
    ground or ceiling effect keeps the form chosen on every sample); ``leakage_shift`` how far each parameter moves
    when what the form leaves on the samples set aside, carried into the rows fitted on by the smoothing, is taken
    out (counted in the standard errors).
``loose``
    the written parameters the flight pins only loosely (:func:`discovery.determination.loose_parameters`): each
    entry whose 95 % interval allows an error of more than 10 % of the parameter's true value, as ``{"effect",
    "parameter", "value", "std", "interval_95_share", "manoeuvre"}``, the manoeuvre being the one that narrows it
    (``interval_95_share`` null where the interval reaches zero: a standard error widened after the parameter was
    found determined, by a motor lag found beside it or by the smoothing's leak of ``form_range.leakage_shift``).
``vehicle_fields``
    where each field of the model file's vehicle came from: given in the vehicle block, derived from it,
    found (a motor lag), or defaulted (the paper vehicle's value; the log says nothing about it).
``left_out``
    the stretches of each log left out and why (held up, ground contact, held at the ceiling).
``withheld``
    ``null``, or the effects a model held that were not written because its held-out force gap was
    not smaller than the nominal model's.
``flights``
    with several logs: ``conditions``, each flight's own wind with its standard error (the model
    file is for still air), and ``held_out``, each flight's force error predicted by the model fitted
    on the other flights.
``closed_loop``
    ``null``, or the closed-loop check (:mod:`discovery.closed_loop`).
``undetermined``
    parameters the flight did not determine (:mod:`discovery.determination`): value,
    standard error, why, what was done (nulled or the effect left out of the model
    file) and the manoeuvre that would determine it.
``alike``
    candidates the flight could not tell apart, with the manoeuvre that would (and ``why_chosen``
    when the one chosen did not score best).
``notes``
    what was left out of the logs and why (e.g. time resting on the ground).
``limits``
    effects the flight could not determine, each ``{"effects", "reason", "manoeuvre"}``
    with the manoeuvre that would determine them (:mod:`discovery.coverage`).
``details``
    what the run saw and did: logs, settings, where the nominal residual was, the
    selection rounds, runtime.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from discovery.determination import MANOEUVRES, loose_parameters, separating_manoeuvre
from discovery.motor_lag import LAG_KEY
from discovery.selection import MIN_SHARE, MIN_WEIGHT_SHARE

__all__ = ["build_report", "write_report", "format_summary"]


def _clean(value: Any) -> Any:
    """JSON-ready copy: numpy scalars and arrays to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        number = float(value)
        return number if math.isfinite(number) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    return value


def build_report(found, model_path: str | None = None, closed_loop: dict | None = None) -> dict[str, Any]:
    """The report of a fitted :class:`~discovery.workflow.Discovery`."""
    effects = []
    for effect, std in zip(found.effects_, found.param_std_):
        effects.append({
            "name": effect.name,
            "params": effect.params_dict(),
            "param_std": std,
            "where": found.where_[effect.name],
            "explained_fraction": round(float(found.explained_fraction_.get(effect.name, 0.0)), 4),
        })
    selection = found.selection_
    if selection is None:  # nothing to fit
        report = {"effects": [], "motor_lag": None, "gap_before": found.gap_before_, "gap_after": found.gap_after_,
                  "model": None if model_path is None else str(model_path), "noise": found.noise_,
                  "unexplained": None, "withheld": None, "loose": [], "left_out": found.left_out_,
                  "flights": found.flights_, "closed_loop": closed_loop, "notes": list(found.notes_), "limits": list(found.limits_),
                  "details": {"logs": _logs(found), "runtime_s": round(found.runtime_s_, 3)}}
        return _clean(report)
    details = {
        "logs": _logs(found),
        "settings": {"candidates": found.candidates, "effect": found.effect, "window_s": found.window_s,
                     "block_s": found.block_s, "n_folds": found.n_folds, "horizon_s": found.horizon_s,
                     "motor_lag": found.motor_lag, "effective_samples_per_axis": round(selection.n_eff, 1)},
        "residual_where": dict(found.where_before_),
        "selection": [{"chosen": step.chosen, "cv_mse_before_N2": step.mse_before, "cv_mse_after_N2": step.mse_after,
                       "tried": step.tried} for step in selection.steps],
        "removed_by_backward_check": selection.removed,
        "forms_chosen": selection.forms,
        "prediction_windows": int(len(found.prediction_errors_before_)),
        "runtime_s": round(found.runtime_s_, 3),
    }
    report = {
        "effects": effects,
        "motor_lag": found.motor_lag_,
        "gap_before": found.gap_before_,
        "gap_after": found.gap_after_,
        "model": None if model_path is None else str(model_path),
        "noise": found.noise_,
        "unexplained": found.unexplained_,
        "withheld": found.withheld_,
        "stand_ins": [{k: v for k, v in item.items() if k != "key"} for item in found.stand_ins_],
        "cancelling": found.cancelling_,
        "vehicle_fields": found.model_.vehicle_fields,
        "wall_edge": found.wall_edge_,
        "form_range": found.form_range_,
        "loose": _loose(found),
        "left_out": found.left_out_,
        "flights": found.flights_,
        "closed_loop": closed_loop,
        "notes": list(found.notes_),
        "limits": list(found.limits_),
        "undetermined": [{k: v for k, v in case.items() if k not in ("name", "index")}
                         for case in found.undetermined_],
        "alike": [{**a, "manoeuvre": separating_manoeuvre(a["chosen"], a["alike"])} for a in selection.alike],
        "details": details,
    }
    return _clean(report)


def _loose(found) -> list[dict[str, Any]]:
    """The written parameters pinned only loosely; one whose error a found motor lag widened
    (``found.widened_by_lag_``) moves with the lag, so the manoeuvre given is the one that pins the lag."""
    loose = loose_parameters(found.effects_, found.param_std_)
    for entry in loose:
        if (entry["effect"], entry["parameter"]) in found.widened_by_lag_:
            entry["manoeuvre"] = (f"{MANOEUVRES[(LAG_KEY, 'time_constant')]} (it moves with the motor lag found, "
                                  "which that pins)")
    return loose


def _logs(found) -> list[dict[str, Any]]:
    out = []
    for log in found.logs_:
        record = {"file": log.source, "samples": log.n_samples, "duration_s": round(log.duration, 3),
                  "rate_hz": round(log.rate_hz, 2)}
        if log.vehicle.thrust_map is not None:
            record["nominal_thrust_map"] = log.vehicle.thrust_map.to_dict()
        out.append(record)
    return out


def write_report(report: dict[str, Any], path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_clean(report), indent=2) + "\n")
    return path


def _change(before: float | None, after: float | None) -> str:
    """``x % smaller`` or ``x % larger`` (a gap that grew is never said to be a negative share smaller)."""
    if before is None or after is None or not before:
        return "n/a"
    share = 1 - after / before
    return f"{100 * share:.0f} % smaller" if share >= 0 else f"{-100 * share:.0f} % larger"


def format_summary(report: dict[str, Any]) -> str:
    """A few lines for the terminal."""
    lines = [f"WARNING {note}" for note in report.get("notes") or [] if note.startswith("likely sidecar error")]
    if report["effects"]:
        for e in report["effects"]:
            params = ", ".join(
                f"{k}={_fmt(v)} +- {_fmt(report_std)}" for (k, v), report_std in zip(e["params"].items(),
                                                                                      e["param_std"].values()))
            where = e["where"] or {}
            place = where.get("regressor")
            if place not in (None, "everywhere") and where.get("range"):
                place = f"{place} in [{where['range'][0]:.3g}, {where['range'][1]:.3g}] {where.get('unit') or ''}"
            lines.append(f"found {e['name']}: {params}; acts {place or 'nowhere'}; explains "
                         f"{100 * e['explained_fraction']:.0f} % of the held-out residual")
            for loose in (x for x in report.get("loose") or [] if x["effect"] == e["name"]):
                share = loose["interval_95_share"]  # None (not finite) where the interval reaches zero
                extent = "not even to its sign (its 95 % interval reaches zero)" if share is None else \
                    f"only to +-{100 * share:.0f} % (95 % interval)"
                lines.append(f"  the flight determines {loose['parameter']} {extent}; to narrow it: "
                             f"{loose['manoeuvre']}")
    lag = report.get("motor_lag")
    if lag and lag["kept"]:
        lines.append(f"found a motor lag: time_constant={_fmt(lag['time_constant_s'])} +- {_fmt(lag['std_s'])} s (the "
                     f"rotors produce the logged thrust late); explains {100 * lag['explained']:.0f} % of the held-out "
                     "residual; written as the model's vehicle motor_time_constant")
        if lag.get("to_narrow"):
            lines.append(f"  the flight determines the motor lag only to +-{100 * lag['interval_95_share']:.0f} % (95 % "
                         f"interval); to narrow it: {lag['to_narrow']}")
    noise = (report.get("noise") or {}).get("floor_N")
    after = (report.get("gap_after") or {}).get("force_rms_N")
    if not report["effects"] and not (lag and lag["kept"]):
        if "selection" not in report["details"]:
            lines.append("found nothing: the logs hold no airborne flight to fit (see the notes below)")
        elif report.get("unexplained"):
            lines.append("found no effect of the library that explains the residual (see UNEXPLAINED below)")
        elif noise and after is not None:
            upper = report["noise"].get("floor_upper_N")
            bound = f", at most {upper:.4f} N at 95 %" if upper is not None and upper > noise else ""
            lines.append(f"found nothing: the held-out force residual, {after:.4f} N rms, is "
                         f"{after / noise:.2g} times the log's noise floor ({noise:.4f} N{bound}, measured from the "
                         "log): the logs agree with the nominal model within noise (no candidate explains "
                         f"{100 * MIN_SHARE:g} % of the held-out residual energy and a force of "
                         f"{100 * MIN_WEIGHT_SHARE:g} % of the weight)")
        else:
            lines.append("found nothing: no candidate explains "
                         f"{100 * MIN_SHARE:g} % of the held-out residual energy and a force of "
                         f"{100 * MIN_WEIGHT_SHARE:g} % of the weight (the log has no band to measure its noise in)")
    elif not report.get("unexplained") and noise and after is not None:
        lines.append(f"what is left is noise: the held-out force residual, {after:.4f} N rms, is {after / noise:.2g} "
                     f"times the log's noise floor ({noise:.4f} N)")
    for item in report.get("stand_ins") or []:
        params = ", ".join(f"{k}={_fmt(v)}" for k, v in item["params"].items())
        lines.append(f"NOT WRITTEN as physics: {item['effect']} ({params}) stood in for the unexplained residual: "
                     f"{item['reason']}")
    if report.get("withheld"):
        w = report["withheld"]
        lines.append(f"NOT WRITTEN: the model with {', '.join(w['effects'])} leaves a held-out force gap of "
                     f"{w['force_rms_N']:.4f} N, not smaller than the nominal model's {w['nominal_force_rms_N']:.4f} N")
    b, a = report["gap_before"], report["gap_after"]
    if b.get("force_rms_N") is not None:
        lines.append(f"held-out force residual RMS: {_number(b['force_rms_N'])} N -> {_number(a['force_rms_N'])} N "
                     f"({_change(b['force_rms_N'], a['force_rms_N'])})")
        if b.get("prediction_rms_m") is None:
            lines.append("held-out open-loop prediction RMS: n/a (no prediction window fits inside one "
                         "cross-validation block; a longer log or a shorter --horizon gives one)")
        else:
            lines.append(f"held-out open-loop prediction RMS: {_number(b['prediction_rms_m'])} m -> "
                         f"{_number(a['prediction_rms_m'])} m "
                         f"({_change(b['prediction_rms_m'], a['prediction_rms_m'])})")
    flights = report.get("flights") or {}
    for record in flights.get("conditions") or []:
        winds = "; ".join(f"{name} wind {_fmt(v['w'])} +- {_fmt(v.get('w_std'))} m/s" for name, v in record.items()
                          if name != "log" and isinstance(v, dict))
        if winds:
            lines.append(f"flight {record['log']}: {winds} (its own condition; the model file is for still air)")
    for record in flights.get("held_out") or []:
        lines.append(f"held-out flight {record['log']}: force error {record['force_rms_N']:.4f} N rms with the model "
                     f"fitted on the other flights ({_fmt(record.get('ratio_to_in_sample'))} times its in-sample "
                     f"{record['in_sample_force_rms_N']:.4f} N"
                     + (f"; its own {record['conditions_fitted_on_it']} condition entries fitted on it"
                        if record.get("conditions_fitted_on_it") else "")
                     + (f"; {', '.join(record['on_no_other_flight'])} acts on no other flight: predicted without "
                        "it" if record.get("on_no_other_flight") else "") + ")")
    for case in report.get("undetermined") or []:
        lines.append(f"undetermined {case['effect']}.{case['parameter']} = {_fmt(case['value'])} +- "
                     f"{_fmt(case['std'])}: {case['reason']}; {case['action']}; to determine: {case['manoeuvre']}")
    for pair in report.get("alike") or []:
        lines.append(f"cannot tell {pair['chosen']} from {pair['alike']} in this flight (scores within one "
                     f"parameter's price)" + (f"; {pair['chosen']} was chosen: {pair['why_chosen']}"
                                              if pair.get("why_chosen") else "")
                     + f"; to tell them apart: {pair['manoeuvre']}")
    for note in report.get("notes") or []:
        if not note.startswith("likely sidecar error"):
            lines.append(f"note: {note}")
    for limit in report.get("limits") or []:
        lines.append(f"cannot determine {' / '.join(limit['effects'])}: {limit['reason']}; to determine: "
                     f"{limit['manoeuvre']}")
    if report.get("unexplained"):
        lines += _unexplained_lines(report["unexplained"])
        shape = report["unexplained"].get("shape")
        if shape:
            points = ", ".join(f"{f:.3g} N at {k:.3g}" for k, f in zip(shape["knots"], shape["force_N_at_knots"]))
            lines.append(f"  its shape along {shape['direction_world']} over every flown {shape['regressor']} "
                         f"(piecewise linear, {shape['unit']}): {points}")
    cl = report.get("closed_loop")
    if cl:
        lines.append(cl.get("summary", ""))
    if report.get("model"):
        lines.append(f"model file: {report['model']}")
        fields = report.get("vehicle_fields") or {}
        defaulted = sorted(k for k, v in fields.items() if v.startswith("defaulted"))
        if defaulted:
            lines.append(f"  its vehicle's {', '.join(defaulted)} are defaults (the paper's vehicle, or 0), not "
                         "yours: the model file's vehicle_fields says where each came from")
    return "\n".join(lines)


def _unexplained_lines(left: dict) -> list[str]:
    """The UNEXPLAINED lines of the summary: how much is left beyond the noise, and where it lives."""
    floor = left.get("noise_floor_N")
    head = f"UNEXPLAINED residual ({left['force_rms_N']:.4f} N RMS"
    if floor is not None and left.get("times_noise_floor") is not None:
        head += (f", {left['times_noise_floor']:.2g} times the noise floor of {floor:.4f} N; "
                 f"{100 * left['share_of_weight']:.2g} % of the weight beyond the noise")
    head += ")"
    lives = left.get("lives_in")
    w = left.get("where") or {}
    direction = left.get("direction_world")
    if lives == "time (periodic)":
        t = left["time"]
        head += (f" varies in time: periodic at {t['peak_hz']:.3g} Hz, {t['peak_amplitude_N']:.3g} N amplitude along "
                 f"{direction} ({100 * t['periodic_explained_fraction']:.0f} % of it predicted by a sinusoid at that "
                 "frequency fitted on the other folds): a periodic gust or another force the flight's state does not "
                 "explain")
    elif lives == "time (slow)":
        t = left["time"]
        head += (f" varies in time with nothing in the flight's state or position predicting it: "
                 f"{100 * t['slow_share']:.0f} % of its excess over the noise is below {0.5:g} Hz, along {direction} "
                 "(a changing wind, gusts)")
    elif lives == "position":
        region = left["position"]["region"]
        head += (f" lives in a region of the flight: {left['position']['along']} in {region['along_m']} m, height in "
                 f"{region['height_m']} m" + (" (the top of the flight: a surface may end there)"
                                              if region.get("top_of_flight") else "")
                 + (" (the bottom of the flight)" if region.get("bottom_of_flight") else ""))
    elif lives == "everywhere":
        head += (f" is steady: a force of {left.get('level_N')} N (world) everywhere, what varies is within the noise; "
                 "no candidate the flight could determine describes it")
    elif lives == "nowhere in particular":
        head += " is spread over the flight: no state, place or time period predicts it"
    else:
        head += (f" depends on {w.get('regressor')}: it stands out in {w.get('range')} {w.get('unit') or ''}"
                 + (" (beyond the surface: likely a sidecar error, see the warning)"
                    if w.get("unit") == "m" and w.get("range") and w["range"][1] <= 0 else ""))
    return [head]


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.4f}"


def _fmt(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return "n/a" if value is None else f"{value:.4g}"
