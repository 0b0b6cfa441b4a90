"""Which fitted parameters the flight determined, and what to do with those it did not.

A parameter is *determined* when its 95 % confidence interval (value +- 1.96 standard
errors) is finite, excludes the value at which it has no effect (:data:`NULL_VALUES`:
zero drag, zero force, zero wind, no suction, a thrust scale of one) and stays away
from the bounds of its range. The horizontal components of a vector along the world axes (a
steady force, a wind) are judged together, by their 95 % region, so that a log written in a frame
turned about the vertical determines the same. Nothing undetermined goes into the model file:

- an undetermined entry of a vector parameter (drag along one body axis, one
  component of a steady force or of the wind) is set to its null value: that axis
  gets nothing from this effect;
- an effect whose main scalar parameter (``k_s``, ``d_thr``, ``radius``, ``scale``) is
  undetermined is left out altogether.

Each such case is reported with the manoeuvre that would determine it
(:data:`MANOEUVRES`). :func:`refit_determined` fits what is left again, so the model file holds
the values of the model that was scored, not those of a joint fit with what was dropped.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import numpy as np

from wall_env.effects import Effect, Parameter

if TYPE_CHECKING:
    from discovery.fitting import Candidate, Fitter

__all__ = ["Z_95", "CHI2_2_95", "NARROW_INTERVAL_SHARE", "interval_share", "NULL_VALUES", "NULL_BY_EFFECT",
           "null_value", "MANOEUVRES", "Undetermined", "undetermined_cases", "restrict", "determined", "entry",
           "nothing_left", "open_cases", "refit_determined", "determining_manoeuvre", "separating_manoeuvre",
           "loose_parameters"]

Z_95 = 1.96
CHI2_2_95 = 5.991  # the chi-square distribution's 95 % point with two degrees of freedom (-2 ln 0.05)
#: a written parameter whose 95 % interval allows an error of more than this share of its true value
#: (:func:`interval_share`) is reported with the manoeuvre that narrows it (the acceptance figures ask parameters
#: within 10 %)
NARROW_INTERVAL_SHARE = 0.10
NULL_VALUES = {"k_s": 0.0, "d_thr": 0.0, "D": 0.0, "C": 0.0, "F": 0.0, "w": 0.0, "scale": 1.0, "radius": 0.0,
               "time_constant": 0.0}
#: null values of parameters whose name means something else in another effect (an affine thrust map's offset, N,
#: has none at 0; a ground or ceiling effect's distance offset has no null value)
NULL_BY_EFFECT = {("thrust_scale", "offset"): 0.0}
_AXES = "xyz"
MANOEUVRES = {
    ("wall_suction", "k_s"): "fly with the rotors within 0.15 m of the wall, at several distances",
    ("wall_suction", "d_thr"): "fly from 0.3 m in to 0.07 m from the wall and back, slowly",
    ("wall_suction", "thrust_scaling"): "fly within 0.15 m of the wall while climbing and descending briskly "
                                        "(thrust varying by 20 % or more)",
    ("ground_effect", "radius"): "hover at several heights from 0.1 m to 0.5 m above the ground",
    ("ground_effect", "offset"): "fly slowly from 0.3 m down to within 0.03 m of the ground and back, several "
                                 "times (the offset shows where the height is comparable to it)",
    ("ceiling_effect", "radius"): "hover at several distances from 0.1 m to 0.5 m under the ceiling",
    ("ceiling_effect", "offset"): "fly slowly from 0.3 m in to within 0.03 m of the ceiling and back, several "
                                  "times (the offset shows where the distance is comparable to it)",
    ("thrust_scale", "scale"): "climb and descend briskly (thrust varying by 20 % or more)",
    ("thrust_scale", "offset"): "climb and descend briskly over a wide range of thrust (from 70 % to 130 % of the "
                                "weight): the offset is the thrust at zero command, the scale its slope",
    ("constant_force", "F"): "a longer flight (the force is within its noise)",
    ("motor_lag", "time_constant"): "climb and descend in steps of different lengths (0.3 s to 3 s), so that the "
                                    "thrust changes at several rates",
}


def interval_share(size: float, std: float) -> float:
    """The largest error, as a share of the true value, that a 95 % interval of half-width ``Z_95 std`` around an
    estimate of size ``size`` allows: ``Z_95 std / (size - Z_95 std)``, the truth at the interval's near end (inf
    when the interval reaches zero). Taken against the estimate, ``Z_95 std / size``, it understates the error of
    an estimate that came out high: a motor lag of 33.0 +- 1.66 ms was "+-9.8 %" and 10.1 % off the true 30 ms."""
    half = Z_95 * std
    return half / (size - half) if size > half else math.inf


def loose_parameters(effects: list[Effect], stds: list[dict]) -> list[dict]:
    """Determined parameters the flight pins only loosely: each entry whose 95 % interval allows an error of more than
    :data:`NARROW_INTERVAL_SHARE` of the parameter's true size (:func:`interval_share`), as ``{"effect",
    "parameter", "value", "std", "interval_95_share", "manoeuvre"}``. The size is the value; a vector's length for a
    vector along the world axes (a force, a wind: its direction is the frame's); each entry's own value for one
    coefficient per body axis (:attr:`~wall_env.effects.base.Parameter.frame` ``"body"``: a drag along body z is its
    own quantity, and measured against the drag vector's length a vertical drag of 0.44 +- 0.026 N s/m, +-12 %,
    had passed as +-10 %). A hold at one height, for instance, pins a ground effect's gain there and only loosely how it
    splits between the radius and the distance offset."""
    out = []
    for effect, p, value, error in _entries(effects, stds):
        sizes = np.abs(value) if p.frame == "body" else np.full(value.size, float(np.linalg.norm(value)))
        for i in range(value.size):
            if sizes[i] <= 0.0:
                continue
            share = interval_share(float(sizes[i]), float(error[i]))
            if np.isfinite(error[i]) and share > NARROW_INTERVAL_SHARE:  # inf share: the interval reaches zero
                index = i if p.size > 1 else None
                out.append({"effect": effect.name, "parameter": p.entry_name(i),
                            "value": float(value[i]), "std": float(error[i]), "interval_95_share": share,
                            "manoeuvre": determining_manoeuvre(effect.name, p.name, index)})
    return out


def _entries(effects: list[Effect], stds: list[dict]) -> Iterator[tuple[Effect, Parameter, np.ndarray, np.ndarray]]:
    """Each parameter of ``effects`` with its values and standard errors as arrays (NaN errors where ``stds`` has
    none of the parameter's size)."""
    for effect, std in zip(effects, stds):
        values = effect.params_dict()
        for p in effect.parameters:
            value = np.atleast_1d(np.asarray(values[p.name], dtype=float))
            error = np.atleast_1d(np.asarray(std.get(p.name, np.nan), dtype=float))
            yield effect, p, value, error if error.size == value.size else np.full(value.size, np.nan)


class Undetermined(dict):
    """``{"effect", "parameter", "name", "index", "value", "std", "reason", "action", "manoeuvre"}``."""


def null_value(effect: str, name: str) -> float | None:
    """The value at which parameter ``name`` of ``effect`` has no effect (None if it has none)."""
    return NULL_BY_EFFECT.get((effect, name), NULL_VALUES.get(name))


def determining_manoeuvre(effect: str, name: str, index: int | None = None) -> str:
    """The flight that would determine parameter ``name`` (entry ``index`` of a vector) of ``effect``."""
    if name in ("D", "C") and index is not None:
        return f"fly back and forth along body {_AXES[index]} at 1 m/s or more"
    if name == "w" and index is not None:
        return f"fly back and forth along world {_AXES[index]} at 1 m/s or more, at several speeds"
    return MANOEUVRES.get((effect, name), "fly where this effect acts, over a wider range")


def _reason(value: float, std: float, low: float, high: float, null: float | None) -> str | None:
    if not np.isfinite(std):
        return "its standard error is not finite (the flight does not constrain it)"
    lo, hi = value - Z_95 * std, value + Z_95 * std
    if null is not None and lo <= null <= hi:
        return f"its 95 % interval [{lo:.4g}, {hi:.4g}] contains {null:g}, where it has no effect"
    span = high - low
    if lo <= low + 1e-6 * span or hi >= high - 1e-6 * span:
        return f"its 95 % interval [{lo:.4g}, {hi:.4g}] reaches a bound of its range [{low:g}, {high:g}]"
    return None


def _horizontal_reason(value: np.ndarray, error: np.ndarray, null: float) -> str | None:
    """Why a world vector's horizontal part (``value`` and ``error``: its x and y entries) is not determined: both
    components together within their 95 % region about ``null`` (``sum ((v - null) / std)^2`` at most
    :data:`CHI2_2_95`, the components' correlation left out); None when it is determined."""
    chi2 = float(np.sum(((value - null) / error) ** 2))
    if chi2 > CHI2_2_95:
        return None
    return (f"its horizontal part ({value[0]:.4g}, {value[1]:.4g}) lies within its 95 % region about {null:g}, where "
            f"it has no effect (x and y together: {chi2:.2f} <= {CHI2_2_95:.2f})")


def undetermined_cases(effects: list[Effect], stds: list[dict]) -> list[Undetermined]:
    """Every parameter entry the flight did not determine (see the module text).

    A vector along the world axes (:attr:`~wall_env.effects.base.Parameter.frame` ``"world"``: a steady force, a
    wind) has its horizontal components judged together, so that what is determined does not depend on how the log's
    frame is turned about the vertical: 0.47 N along a turned frame's y and 0.04 N along its x, the x alone within
    noise, is one determined horizontal force. Its vertical component, along gravity in any frame, is judged alone."""
    cases = []
    for effect, p, value, error in _entries(effects, stds):
        null = null_value(effect.name, p.name)
        together = p.frame == "world" and p.size == 3 and null is not None and bool(np.all(error[:2] > 0))
        horizontal = _horizontal_reason(value[:2], error[:2], float(null)) if together and null is not None else None
        for i in range(value.size):
            if together and i < 2:
                reason = horizontal or _reason(float(value[i]), float(error[i]), p.low, p.high, None)
            else:
                reason = _reason(float(value[i]), float(error[i]), p.low, p.high, null)
            if reason is None:
                continue
            index = i if p.size > 1 else None
            nullable = p.size > 1 or p.name == "offset"
            cases.append(Undetermined(
                effect=effect.name, parameter=p.entry_name(i), name=p.name,
                index=index, value=float(value[i]), std=float(error[i]), reason=reason,
                action=f"set to {null or 0.0:g} in the model file" if nullable else "effect left out of the model file",
                manoeuvre=determining_manoeuvre(effect.name, p.name, index)))
    return cases


def restrict(effects: list[Effect], cases: list[Undetermined]) -> list[Effect]:
    """``effects`` with the undetermined entries of ``cases`` nulled and the effects they rule out left out."""
    out = []
    for effect in effects:
        mine = [c for c in cases if c["effect"] == effect.name]
        if any(c["action"].startswith("effect left out") for c in mine):
            continue
        values = effect.params_dict()
        for c in mine:
            null = null_value(effect.name, c["name"])
            null = 0.0 if null is None else null
            if c["index"] is None:
                values[c["name"]] = null
            else:
                entries = list(np.atleast_1d(np.asarray(values[c["name"]], dtype=float)))
                entries[c["index"]] = null
                values[c["name"]] = entries
        if mine and len(mine) >= sum(p.size for p in effect.parameters if null_value(effect.name, p.name) is not None):
            continue  # every entry nulled: nothing left of this effect
        out.append(type(effect)(**values, **effect.option_values))
    return out


def determined(effects: list[Effect], stds: list[dict]) -> tuple[list[Effect], list[dict], list[Undetermined]]:
    """The determined part of ``effects``, their standard errors (NaN where nulled) and the undetermined cases."""
    cases = undetermined_cases(effects, stds)
    kept = restrict(effects, cases)
    names = {e.name for e in kept}
    kept_std = []
    for effect, std in zip(effects, stds):
        if effect.name not in names:
            continue
        std = {k: (list(v) if isinstance(v, list) else v) for k, v in std.items()}
        for c in cases:
            if c["effect"] == effect.name:
                if c["index"] is None:
                    std[c["name"]] = float("nan")
                else:
                    std[c["name"]][c["index"]] = float("nan")
        kept_std.append(std)
    return kept, kept_std, cases


SEPARATING = {
    frozenset({"thrust_scale", "constant_force"}): "climb and descend briskly (thrust varying by 20 % or more): "
                                                   "a thrust scale grows with the thrust, a steady force does not",
    frozenset({"linear_drag", "quadratic_drag"}): "fly at several speeds, from 0.3 m/s to 3 m/s: linear and "
                                                  "quadratic drag part at high speed",
    frozenset({"ground_effect", "thrust_scale"}): "hover at several heights above the ground and far from it",
    frozenset({"ceiling_effect", "thrust_scale"}): "hover at several distances under the ceiling and far from it",
    frozenset({"constant_force", "linear_drag"}): "fly back and forth at several speeds in each direction",
    frozenset({"constant_force", "quadratic_drag"}): "fly back and forth at several speeds in each direction",
}


def separating_manoeuvre(a: str, b: str) -> str:
    """The flight that tells effect ``a`` from effect ``b``."""
    return SEPARATING.get(frozenset({a, b}), f"fly where {a} acts and {b} does not (and the other way round)")


def entry(effect: Effect, name: str, index: int | None) -> int:
    """Position of parameter ``name`` (entry ``index`` of a vector) in ``effect``'s own parameter vector."""
    position = 0
    for p in effect.parameters:
        if p.name == name:
            return position + (index or 0)
        position += p.size
    raise KeyError(f"{effect.name} has no parameter {name}")


def nothing_left(effect: Effect, held: dict[int, float]) -> bool:
    """Whether every entry of ``effect``'s first parameter is held at its null value: then the effect puts no force
    on the vehicle whatever its other parameters (a drag with every coefficient at zero has no use for a wind)."""
    first = effect.parameters[0]
    null = null_value(effect.name, first.name)
    return null is not None and all(held.get(i) == null for i in range(first.size))


def open_cases(candidate: Candidate, hold: dict[str, dict[int, float]]) -> list[Undetermined]:
    """The undetermined entries of a fitted candidate set not already held (:func:`undetermined_cases`); with several
    flights, a flight's own entry (its wind) counts when it is undetermined in every flight."""
    fit = candidate.fit
    if not candidate.names:
        return []
    held = {(e.name, i) for k, e in zip(candidate.names, fit.effects) for i in hold.get(k, {})}
    out = []
    for case in undetermined_cases(fit.effects, fit.std_dicts()):
        effect = next(e for e in fit.effects if e.name == case["effect"])
        if (effect.name, entry(effect, case["name"], case["index"])) in held:
            continue
        layout = fit.layout
        if layout is not None and layout.n_flights > 1 and case["name"] == "w":
            others = [undetermined_cases(fit.flight_effects(f), fit.std_dicts(f)) for f in range(1, layout.n_flights)]
            if not all(any(c["effect"] == case["effect"] and c["parameter"] == case["parameter"] for c in other)
                       for other in others):
                continue  # determined in another flight
        out.append(case)
    return out


def refit_determined(fitter: Fitter | None, chosen: Candidate, say: Callable[[str], None] | None = None,
                     hold: dict[str, dict[int, float]] | None = None
                     ) -> tuple[Candidate, dict[str, dict[int, float]], list[Undetermined]]:
    """Only what the flight determined, fitted again: undetermined entries held at their null value and effects
    whose main parameter is undetermined dropped, the rest refitted and scored again by ``fitter``
    (:class:`~discovery.fitting.Fitter`), until nothing more is undetermined. ``hold``: entries ``chosen`` was
    fitted with held already (kept held). Returns the final candidate set, the entries held
    (``{key: {entry: value}}``) and every case found on the way."""
    current, found = chosen, []
    hold = {k: dict(v) for k, v in (hold or {}).items()}
    for _ in range(len(chosen.names) + 2):
        cases = open_cases(current, hold)
        if not cases or fitter is None:
            break
        found += cases
        dropped = {c["effect"] for c in cases if c["action"].startswith("effect left out")}
        keys = [k for k, e in zip(current.names, current.fit.effects) if e.name not in dropped]
        for c in cases:
            if c["effect"] in dropped:
                continue
            key, effect = next((k, e) for k, e in zip(current.names, current.fit.effects) if e.name == c["effect"])
            null = null_value(effect.name, c["name"])
            hold.setdefault(key, {})[entry(effect, c["name"], c["index"])] = 0.0 if null is None else null
        hold = {k: v for k, v in hold.items() if k in keys}
        keys = [k for k in keys if not nothing_left(fitter.templates[k], hold.get(k, {}))]
        if say is not None:
            say(f"fitting again without what the flight did not determine: {', '.join(keys) or 'nothing'}")
        current = fitter.candidate(keys, previous=current.previous(), hold=hold)
    return current, hold, found
