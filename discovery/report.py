"""The JSON report of a discovery run.

Keys:

``effects``
    one record per named effect, in the order they were added:
    ``{"name", "params", "param_std", "where", "explained_fraction"}`` with the
    parameters and standard errors in the library's units, where the effect acts
    (:func:`discovery.regressors.describe_force`) and the share of the nominal model's
    held-out force-residual energy it explains. Empty when the data agree with the
    nominal model within noise.
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
    details = {
        "logs": [{"file": log.source, "samples": log.n_samples, "duration_s": round(log.duration, 3),
                  "rate_hz": round(log.rate_hz, 2)} for log in found.logs_],
        "settings": {"candidates": found.candidates, "effect": found.effect, "window_s": found.window_s,
                     "block_s": found.block_s, "n_folds": found.n_folds, "horizon_s": found.horizon_s,
                     "effective_samples_per_axis": round(selection.n_eff, 1)},
        "residual_where": dict(found.where_before_),
        "selection": [{"chosen": step.chosen, "cv_mse_before_N2": step.mse_before, "cv_mse_after_N2": step.mse_after,
                       "tried": step.tried} for step in selection.steps],
        "removed_by_backward_check": selection.removed,
        "prediction_windows": int(len(found.prediction_errors_before_)),
        "runtime_s": round(found.runtime_s_, 3),
    }
    report = {
        "effects": effects,
        "gap_before": found.gap_before_,
        "gap_after": found.gap_after_,
        "model": None if model_path is None else str(model_path),
        "unexplained": found.unexplained_,
        "closed_loop": closed_loop,
        "details": details,
    }
    return _clean(report)


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
    lines = []
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
    else:
        lines.append("found nothing: the logs agree with the nominal model within noise")
    b, a = report["gap_before"], report["gap_after"]
    lines.append(f"held-out force residual RMS: {b['force_rms_N']:.4f} N -> {a['force_rms_N']:.4f} N "
                 f"({_reduction(b['force_rms_N'], a['force_rms_N'])} smaller)")
    lines.append(f"held-out open-loop prediction RMS: {b['prediction_rms_m']:.4f} m -> {a['prediction_rms_m']:.4f} m "
                 f"({_reduction(b['prediction_rms_m'], a['prediction_rms_m'])} smaller)")
    if report.get("unexplained"):
        w = report["unexplained"]["where"]
        lines.append(f"UNEXPLAINED residual ({report['unexplained']['force_rms_N']:.4f} N RMS) depends on "
                     f"{w.get('regressor')} in {w.get('range')} {w.get('unit') or ''}")
    cl = report.get("closed_loop")
    if cl:
        lines.append(cl.get("summary", ""))
    if report.get("model"):
        lines.append(f"model file: {report['model']}")
    return "\n".join(lines)


def _fmt(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:.4g}" for v in value) + "]"
    return f"{value:.4g}"
