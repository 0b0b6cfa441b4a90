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
    (:mod:`discovery.motor_lag`): ``{"time_constant_s", "std_s", "explained", "force_rms_N",
    "kept", "reason", "determined", "moves"}`` (``moves``: the chosen parameter the lag would
    change most, when by more than 5 % and two standard errors). A kept lag is the model
    file's vehicle ``motor_time_constant``, and the effects above were chosen with it.
``gap_before``, ``gap_after``
    ``{"force_rms_N", "prediction_rms_m"}`` on held-out data for the nominal and the
    discovered model: RMS of the force residual (vector norm, N) and of the open-loop
    position error at the prediction horizon (m).
``model``
    path of the updated model file (``null`` if not written).
``unexplained``
    ``null``, or ``{"force_rms_N", "where"}`` when a significant residual is left that no
    candidate explains, with where it is (regressor, range, direction, times).
``closed_loop``
    ``null``, or the closed-loop check (:mod:`discovery.closed_loop`).
``undetermined``
    parameters the flight did not determine (:mod:`discovery.determination`): value,
    standard error, why, what was done (nulled or the effect left out of the model
    file) and the manoeuvre that would determine it.
``alike``
    candidates the flight could not tell apart, with the manoeuvre that would.
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

from discovery.determination import separating_manoeuvre
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
                  "model": None if model_path is None else str(model_path), "unexplained": None,
                  "closed_loop": closed_loop, "notes": list(found.notes_), "limits": list(found.limits_),
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
        "unexplained": found.unexplained_,
        "closed_loop": closed_loop,
        "notes": list(found.notes_),
        "limits": list(found.limits_),
        "undetermined": [{k: v for k, v in case.items() if k not in ("name", "index")}
                         for case in found.undetermined_],
        "alike": [{**a, "manoeuvre": separating_manoeuvre(a["chosen"], a["alike"])} for a in selection.alike],
        "details": details,
    }
    return _clean(report)


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


def _reduction(before: float | None, after: float | None) -> str:
    if before is None or after is None or not before:
        return "n/a"
    return f"{100 * (1 - after / before):.0f} %"


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
    lag = report.get("motor_lag")
    if lag and lag["kept"]:
        lines.append(f"found a motor lag: time_constant={_fmt(lag['time_constant_s'])} +- {_fmt(lag['std_s'])} s (the "
                     f"rotors produce the logged thrust late); explains {100 * lag['explained']:.0f} % of the held-out "
                     "residual; written as the model's vehicle motor_time_constant")
    if not report["effects"] and not (lag and lag["kept"]):
        if "selection" not in report["details"]:
            lines.append("found nothing: the logs hold no airborne flight to fit (see the notes below)")
        elif report.get("unexplained"):
            lines.append("found no effect of the library that explains the residual (see UNEXPLAINED below)")
        else:
            lines.append("found nothing: the logs agree with the nominal model within noise (no candidate explains "
                         f"{100 * MIN_SHARE:g} % of the held-out residual energy and a force of "
                         f"{100 * MIN_WEIGHT_SHARE:g} % of the weight)")
    b, a = report["gap_before"], report["gap_after"]
    if b.get("force_rms_N") is not None:
        lines.append(f"held-out force residual RMS: {_number(b['force_rms_N'])} N -> {_number(a['force_rms_N'])} N "
                     f"({_reduction(b['force_rms_N'], a['force_rms_N'])} smaller)")
        if b.get("prediction_rms_m") is None:
            lines.append("held-out open-loop prediction RMS: n/a (no prediction window fits inside one "
                         "cross-validation block; a longer log or a shorter --horizon gives one)")
        else:
            lines.append(f"held-out open-loop prediction RMS: {_number(b['prediction_rms_m'])} m -> "
                         f"{_number(a['prediction_rms_m'])} m "
                         f"({_reduction(b['prediction_rms_m'], a['prediction_rms_m'])} smaller)")
    for case in report.get("undetermined") or []:
        lines.append(f"undetermined {case['effect']}.{case['parameter']} = {_fmt(case['value'])} +- "
                     f"{_fmt(case['std'])}: {case['reason']}; {case['action']}; to determine: {case['manoeuvre']}")
    for pair in report.get("alike") or []:
        lines.append(f"cannot tell {pair['chosen']} from {pair['alike']} in this flight (scores within one "
                     f"parameter's price); to tell them apart: {pair['manoeuvre']}")
    for note in report.get("notes") or []:
        if not note.startswith("likely sidecar error"):
            lines.append(f"note: {note}")
    for limit in report.get("limits") or []:
        lines.append(f"cannot determine {' / '.join(limit['effects'])}: {limit['reason']}; to determine: "
                     f"{limit['manoeuvre']}")
    if report.get("unexplained"):
        w = report["unexplained"]["where"]
        lines.append(f"UNEXPLAINED residual ({report['unexplained']['force_rms_N']:.4f} N RMS) depends on "
                     f"{w.get('regressor')} in {w.get('range')} {w.get('unit') or ''}"
                     + (" (beyond the surface: likely a sidecar error, see the warning)"
                        if w.get("unit") == "m" and w.get("range") and w["range"][1] <= 0 else ""))
        shape = report["unexplained"].get("shape")
        if shape:
            points = ", ".join(f"{f:.3g} N at {k:.3g}" for k, f in zip(shape["knots"], shape["force_N_at_knots"]))
            lines.append(f"  its shape along {shape['direction_world']} (piecewise linear in {shape['regressor']}, "
                         f"{shape['unit']}): {points}")
    cl = report.get("closed_loop")
    if cl:
        lines.append(cl.get("summary", ""))
    if report.get("model"):
        lines.append(f"model file: {report['model']}")
    return "\n".join(lines)


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.4f}"


def _fmt(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return "n/a" if value is None else f"{value:.4g}"
