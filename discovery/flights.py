"""Many flights, one model: each flight's own conditions, each flight held out, and a fitted model on a new flight.

Several logs of one vehicle are fitted together (:class:`~discovery.layout.ParameterLayout`): the vehicle's
and the aerodynamics' parameters are shared, and each flight has its own conditions (:data:`~discovery.layout.
CONDITIONS`: a steady wind). Here:

- :func:`still_air`: the effects for the model file, the winds being the flights' conditions (the report
  gives them), so the model file is for still air;
- :func:`conditions`: each flight's own wind with its standard error;
- :func:`held_out_flights`: each flight predicted by the model fitted on the others (its own wind fitted on
  it alone), its force error against the full fit's error on it;
- :func:`model_on`: a fitted model's residual on other logs, each flight's wind given or fitted on it with
  everything else held (what :meth:`discovery.workflow.Discovery.predict` and ``score`` use).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from discovery.determination import entry, null_value
from discovery.fitting import Candidate, EffectFit
from discovery.layout import CONDITIONS
from discovery.residuals import FlightData
from wall_env.effects import Effect
from wall_env.model_file import FlightModel

__all__ = ["still_air", "conditions", "held_out_flights", "model_on"]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(x**2, axis=1)))) if len(x) else float("nan")


def still_air(effects: list[Effect], n_flights: int) -> list[Effect]:
    """``effects`` with their winds at zero when several flights were fitted (each flight's wind is its own)."""
    if n_flights <= 1:
        return list(effects)
    out = []
    for effect in effects:
        if CONDITIONS & set(effect.values):
            values = {**effect.params_dict(), **{k: [0.0] * len(effect.values[k]) for k in CONDITIONS
                                                 if k in effect.values}}
            effect = type(effect)(**values, **effect.option_values)
        out.append(effect)
    return out


def conditions(data: FlightData, final: Candidate) -> dict:
    """``{"conditions", "held_out"}`` when several flights were fitted: each flight's own wind with its standard
    error, and :func:`held_out_flights`; empty lists for one flight."""
    layout = final.fit.layout
    if layout is None or data.n_flights <= 1:
        return {"conditions": [], "held_out": []}
    sources = [next(seg.source for seg in data.segments if seg.flight == f) for f in range(data.n_flights)]
    records = []
    for f in range(data.n_flights):
        record: dict[str, Any] = {"log": sources[f]}
        for effect, std in zip(final.fit.flight_effects(f), final.fit.std_dicts(f)):
            if "w" in effect.values:
                record[effect.name] = {"w": [float(x) for x in effect.values["w"]], "w_std": std.get("w")}
        records.append(record)
    return {"conditions": records, "held_out": held_out_flights(data, final, sources)}


def held_out_flights(data: FlightData, final: Candidate, sources: list[str]) -> list[dict]:
    """Each flight predicted by the model fitted on the others: the shared parameters from the other flights,
    the held-out flight's own conditions fitted on it alone. Its force error (rms at the fit rows) against the
    full fit's error on it: ``[{"log", "force_rms_N", "in_sample_force_rms_N", "ratio_to_in_sample",
    "conditions_fitted_on_it", "on_no_other_flight"}]``.

    An effect that acts on no other flight (a wall's suction when only this flight came near a wall) is not
    determined by them: the flight is predicted without it, and ``on_no_other_flight`` names it. Its fitted values
    hold what this flight showed, so keeping them would not be a prediction."""
    problem, fit = final.problem, final.fit
    if problem is None or not final.names or fit.layout is None:
        return []
    layout = fit.layout
    held = fit.held if fit.held is not None else np.zeros(problem.size, dtype=bool)
    inside = problem.residuals(fit.theta)
    out = []
    for f in range(data.n_flights):
        others = [np.full(len(rows), seg.flight != f) for seg, rows in zip(data.segments, problem.rows)]
        mine = [~m for m in others]
        if not any(m.any() for m in others):
            continue
        informed = problem.informed(fit.theta, [m & u for m, u in zip(others, problem.usable)])
        start, held_here, absent = fit.theta.copy(), held.copy(), []
        for e, effect in enumerate(fit.effects):
            entries = layout.entries_of(e)
            if informed[entries & ~layout.flight_entries(f)].any():
                continue
            absent.append(effect.name)
            main = effect.parameters[0]  # no force at its null value (no suction, no drag, no gain)
            null, first = null_value(effect.name, main.name), entry(effect, main.name, None)
            for rows in layout.index[e]:
                start[rows[first:first + main.size]] = 0.0 if null is None else null
            held_here |= entries
        shared = problem.fit(masks=others, theta0=start, held=held_here).theta
        own = layout.flight_entries(f) & ~held_here
        theta = problem.fit(masks=mine, theta0=shared, held=~own).theta if own.any() else shared
        predicted = problem.residuals(theta)
        held_out = _rms(np.concatenate([r[m] for r, m in zip(predicted, mine)]))
        in_sample = _rms(np.concatenate([r[m] for r, m in zip(inside, mine)]))
        out.append({"log": sources[f], "force_rms_N": held_out, "in_sample_force_rms_N": in_sample,
                    "ratio_to_in_sample": held_out / in_sample if in_sample > 0 else None,
                    "conditions_fitted_on_it": int(own.sum()), "on_no_other_flight": absent})
    return out


def model_on(data: FlightData, final: Candidate, templates: list[Effect],
             given: dict[str, dict[str, Any]] | None) -> tuple[list[np.ndarray], list[np.ndarray], list[dict]]:
    """The fitted model ``final`` (its candidate keys' ``templates``) on other logs ``data``: per segment the nominal
    residual and the model's residual, and each flight's conditions, ``given`` (``{"quadratic_drag": {"w": [...]}}``)
    or fitted on the flight with every shared parameter held."""
    nominal = FlightModel(data.vehicle.to_vehicle_params(), []).aero_model()
    r_nom = data.residuals(nominal)
    if not final.names:
        return r_nom, r_nom, [{} for _ in range(data.n_flights)]
    problem = EffectFit(data, templates, r_nom, None, list(final.names))
    layout, fitted = problem.layout, final.fit
    theta = layout.pack({k: e.param_vector() for k, e in zip(final.names, fitted.effects)})
    free = np.zeros(layout.size, dtype=bool)
    for e, effect in enumerate(layout.templates):
        names = [p.name for p in effect.parameters for _ in range(p.size)]
        wind = [i for i, n in enumerate(names) if n in CONDITIONS]
        value = (given or {}).get(effect.name, {}).get("w")
        held_before = _all_held(fitted, e, wind)
        for f in range(layout.n_flights):
            rows = layout.index[e][f]
            for component, i in enumerate(wind):
                if value is not None:
                    theta[rows[i]] = float(np.asarray(value, dtype=float)[component])
                elif not held_before:
                    free[rows[i]] = True
    if free.any():
        theta = problem.fit(theta0=theta, held=~free).theta
    residual = problem.out_of_fold([theta] * data.n_folds, r_nom)
    used = [{e.name: e.params_dict() for e in layout.effects(theta, f) if "w" in e.values}
            for f in range(data.n_flights)]
    return r_nom, residual, used


def _all_held(fit, effect: int, entries: list[int]) -> bool:
    """Whether ``fit`` held every one of effect ``effect``'s own ``entries`` (undetermined: left at zero)."""
    if not entries or fit.held is None or fit.layout is None or not fit.held.size:
        return False
    rows = fit.layout.index[effect][0]
    return bool(np.all(fit.held[rows[entries]]))
