"""Where a library form is trusted: a ground or ceiling effect fitted away from its surface.

The image-rotor gain of the ground and ceiling effects (:func:`wall_env.effects.ground.image_rotor_gain`) grows
without bound as a rotor nears the surface, so every model of it stops the growth somewhere. The library clamps
the distance at half the effective radius (a gain of 4/3); a real rotor and its frame level off where their own
shape says, and a simulator written apart may clamp elsewhere. That end of the form is a guess a log need not
share. From :data:`~wall_env.effects.ground.FORM_TRUSTED_FROM_RADII` effective radii out the forms agree.

A flight that spends time nearer lets those samples, where the gain is largest, set the parameters: flown down to
2 cm under a ceiling whose gain levels off at 0.6 of the radius, the radius came out 7-13 % large with a spurious
distance offset. So the parameters written come from a refit without the samples that had a rotor nearer than
that to the surface (:func:`fit_within_form`). The range depends on the radius being fitted, so the refit is
repeated until the samples it leaves out stop changing. The samples left out are still held out and scored: what
the form leaves there is part of the gap after, and the report says where it lives. When the whole set's range
leaves too little of the flight, the range is taken again from the surface effects fitted alone, and each other
effect comes back only where it pays within it: a stand-in beside the surface effect can widen the radius, and with
it the range. A ground or ceiling effect the fit on every sample left out is asked the same way once more
(:func:`_left_out_surface`): a gain that levels off farther out than the form's can make a thrust scale the better
account of every sample, and the surface effect beside it run to a bound. Within the range every other effect
must still explain what selection asks of any effect, a material share of the gap and force
(:func:`_material`); one that only bends the surface effect goes. The surface effect keeps the form chosen on every
sample (with or without a distance offset) when that fit predicts the samples set aside as well as the rest
(:func:`_set_aside_misfit`): the gain levels off there as the form says, the form was not chosen for their sake,
and within the range alone an offset may not be worth its price. The rows fitted on still carry, through the
smoothing of their force, some of what the form leaves on the samples set aside; how far that moves the parameters
(:func:`leakage_shift`) is counted in their standard errors.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from discovery.determination import open_cases
from discovery.selection import MIN_SHARE, MIN_WEIGHT_SHARE, effect_name, score
from wall_env.effects import Effect
from wall_env.effects.ground import FORM_TRUSTED_FROM_RADII

if TYPE_CHECKING:
    from discovery.fitting import Candidate, Fitter
    from discovery.regressors import Regressor
    from discovery.residuals import FlightData

__all__ = ["SURFACE_DISTANCE", "MIN_FITTED_SHARE", "near_rows", "leakage_shift", "fit_within_form"]

#: the regressor (the nearest rotor's distance, m) of the surface each image-rotor effect acts near
SURFACE_DISTANCE = {"ground_effect": "height above ground", "ceiling_effect": "distance to ceiling"}
SURFACE_NAME = {"ground_effect": "the ground", "ceiling_effect": "the ceiling"}
#: the share of the fit rows that must stay for the refit: below it the flight lived near the surface, and the fit
#: on all of it is kept (the report says so). Fewer rows are still asked whether they determine every parameter
#: (:func:`~discovery.determination.open_cases`). A ground flight 2.5-14 cm up kept 21 % of its 360 s within the
#: ground effect's range, where the radius and offset came out 0.1 % and 1.5 % off; at 30 % asked, the fit on all of
#: it was written, with a thrust scale of 0.93 beside a radius 2.7 times the true one.
MIN_FITTED_SHARE = 0.15
ITERATIONS = 5  # refits at most: the range follows the radius, the radius the range
LEAKAGE_BINS = 10  # bins of distance in which what the form leaves nearer than its range is averaged
LEAKAGE_ROUNDS = 3  # rounds of estimating that and refitting without it
#: standard errors of the log ratio of two mean squares by which the held-out vertical residual of the samples set
#: aside may exceed that of the rows within the range before the form fitted on all of them counts as not
#: describing them (one-sided, about 2 % by chance)
DESCRIBED_SIGMAS = 2.0


def _inside(data: FlightData, regressors: list[Regressor], effect: Effect) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per segment, per sample: the nearest rotor's distance to ``effect``'s surface (m; inf where unknown) and
    whether it is nearer than the form is trusted (distance plus the effect's offset below
    :data:`FORM_TRUSTED_FROM_RADII` times its radius); empty when the log has no such distance."""
    values = {r.name: r.values for r in regressors}
    name = SURFACE_DISTANCE.get(effect.name)
    if name not in values:
        return []
    params = effect.params_dict()
    reach = FORM_TRUSTED_FROM_RADII * float(params["radius"]) - float(params.get("offset", 0.0))  # type: ignore[arg-type]
    starts = np.cumsum([0] + [seg.n for seg in data.segments])
    out = []
    for s in range(len(data.segments)):
        distance = np.nan_to_num(values[name][starts[s]:starts[s + 1]], nan=np.inf)
        out.append((distance, distance < reach))
    return out


def near_rows(data: FlightData, regressors: list[Regressor], effects: list[Effect]) -> list[np.ndarray]:
    """Per segment, over its fit rows: the samples with a rotor nearer to a surface than its effect's form is
    trusted (:func:`_inside`)."""
    out = [np.zeros(len(seg.fit_rows), dtype=bool) for seg in data.segments]
    for effect in effects:
        for s, (_, inside) in enumerate(_inside(data, regressors, effect)):
            out[s] |= inside[data.segments[s].fit_rows]
    return out


def _share(near: list[np.ndarray]) -> float:
    total = sum(len(n) for n in near)
    return float(sum(int(n.sum()) for n in near) / total) if total else 0.0


def _held_out_axes(candidate: Candidate, near: list[np.ndarray]) -> np.ndarray:
    """Held-out mean squared force residual per world axis (N^2) on the rows fitted on (those not ``near``)."""
    rows = np.concatenate([r[~n] for r, n in zip(candidate.cv_residual, near)])
    return np.mean(rows**2, axis=0) if rows.size else np.zeros(3)


def _score(candidate: Candidate, near: list[np.ndarray], n_eff: float) -> float:
    """:func:`~discovery.selection.score` on the held-out residual of the rows fitted on, with the effective sample
    count scaled to their share."""
    return score(_held_out_axes(candidate, near), candidate.n_params, n_eff * (1.0 - _share(near)))


def _fixed_point(fitter: Fitter, keys: list[str], start: Candidate, near: list[np.ndarray],
                 hold: dict[str, dict[int, float]], data: FlightData, regressors: list[Regressor],
                 say: Callable[[str], None] | None) -> tuple[Candidate | None, list[np.ndarray]]:
    """``keys`` fitted without the rows nearer a surface than the form is trusted (``near``: those of ``start``'s
    fit), the rows set by the fit itself; ``None`` when too few rows would stay."""
    current = start
    for _ in range(ITERATIONS):
        if 1.0 - _share(near) < MIN_FITTED_SHARE:
            return None, near
        if say is not None:
            say(f"fitting {' + '.join(keys)} without the {100 * _share(near):.0f} % of samples nearer a surface than "
                "its form is trusted")
        current = fitter.candidate(keys, previous=current.previous(), hold=hold, exclude=near)
        again = near_rows(data, regressors, current.fit.effects)
        if all(np.array_equal(a, b) for a, b in zip(again, near)):
            break
        near = again
    return current, near


def _set_aside_misfit(candidate: Candidate, near: list[np.ndarray], n_eff: float) -> tuple[float, float] | None:
    """How much worse ``candidate`` (fitted on every sample) predicts the samples ``near`` a surface, held out, than
    the rows within the range: the ratio of their vertical mean squared residuals, and the largest ratio sampling
    alone explains, :data:`DESCRIBED_SIGMAS` standard errors of its logarithm (``sqrt(2 / n_near + 2 / n_within)``,
    the flight's ``n_eff`` effective samples per axis shared between them); ``None`` when either set is empty.

    Where the gain levels off as the form does, the form's account of the set-aside samples is borne out there: a
    form chosen on every sample was not chosen for their sake. Flown 4.6-14 cm over the ground with a gain levelling
    off at 0.55 of a 0.084 m radius behind a 12 mm offset, the ratio was 0.98 (sampling allowed 1.32), and within
    the range alone the plain form scored better by less than the offset's price; it was written with its radius 11 %
    small. Where an offset had only bent the gain toward the samples set aside (the gain levelling off at 0.6-0.9 of
    the radius), the ratio was 2.1 to 8.9 on the second simulator's logs."""
    share = _share(near)
    if not 0.0 < share < 1.0:
        return None
    near_ms = float(_held_out_axes(candidate, [~n for n in near])[2])  # the rows that are not within the range
    within_ms = float(_held_out_axes(candidate, near)[2])
    spread = float(np.sqrt(2.0 / (n_eff * share) + 2.0 / (n_eff * (1.0 - share))))
    return near_ms / max(within_ms, 1e-300), float(np.exp(DESCRIBED_SIGMAS * spread))


def _material(better: Candidate, worse: Candidate, near: list[np.ndarray], weight: float) -> bool:
    """Whether ``better`` explains, on the rows within the form (not ``near``), what selection asks of any effect:
    :data:`~discovery.selection.MIN_SHARE` of the held-out force-gap energy ``worse`` leaves there and
    :data:`~discovery.selection.MIN_WEIGHT_SHARE` of the weight (``weight``, N) in rms force."""
    had, left = float(np.sum(_held_out_axes(worse, near))), float(np.sum(_held_out_axes(better, near)))
    return had - left >= MIN_SHARE * had and np.sqrt(max(had - left, 0.0)) >= MIN_WEIGHT_SHARE * weight


def _simpler(fitter: Fitter, current: Candidate, near: list[np.ndarray], hold: dict[str, dict[int, float]],
             n_eff: float, weight: float, keep_forms: bool = False) -> Candidate | None:
    """The best-scoring change on the rows within the form that scores better than ``current`` there: another effect
    left out, or a ground or ceiling effect in its other form (a distance offset that only bent the gain toward the
    samples set aside; not with ``keep_forms``, when the form fitted on every sample describes them); failing that,
    another effect that explains nothing material within the form (as :func:`_material` asks), left out; ``None``
    when no change is taken.

    An effect chosen on every sample can pay there only for the form's error on the samples set aside and, within
    the range, still score a little better by bending the surface effect beside it: flown 2-15 cm under a ceiling
    whose gain levels off at 0.8 of its 0.078 m radius, a thrust scale of 0.997 explained 0.004 N rms within the
    range (0.03 % of the weight) and moved the ceiling's radius from 0.079 m to 0.091 m and its offset from 14 mm to
    25 mm (12 mm flown)."""
    best, best_score = None, _score(current, near, n_eff)
    immaterial: list[Candidate] = []
    for key in current.names:
        if effect_name(key) in SURFACE_DISTANCE:
            changes = [] if keep_forms else [[form if k == key else k for k in current.names]
                                             for form in fitter.templates
                                             if effect_name(form) == effect_name(key) and form != key]
        elif any(effect_name(k) in SURFACE_DISTANCE for k in current.names if k != key):
            changes = [[k for k in current.names if k != key]]
        else:
            changes = []
        for keys in changes:
            previous = {k: v for k, v in current.previous().items() if k in keys}
            candidate = fitter.candidate(keys, previous=previous, hold=hold, exclude=near)
            value = _score(candidate, near, n_eff)
            if value < best_score:
                if not open_cases(candidate, hold):
                    best, best_score = candidate, value
            elif effect_name(key) not in SURFACE_DISTANCE and not _material(current, candidate, near, weight) and \
                    not open_cases(candidate, hold):
                immaterial.append(candidate)
    if best is None and immaterial:
        return min(immaterial, key=lambda c: _score(c, near, n_eff))
    return best


def _from_surface_alone(fitter: Fitter, final: Candidate, near: list[np.ndarray], hold: dict[str, dict[int, float]],
                        data: FlightData, regressors: list[Regressor], n_eff: float,
                        say: Callable[[str], None] | None) -> tuple[Candidate | None, list[np.ndarray]]:
    """The range the surface effects set fitted alone, and within it each other effect of ``final`` added back where
    it pays there; ``(None, near)`` when that range too leaves too few rows.

    The range follows the radius, and a stand-in fitted beside the surface effect can set it wide: a thrust scale of
    0.96 let a ceiling effect's radius reach 0.23 m with a 9 cm offset (0.10 m and 1.2 cm flown, the gain levelling
    off at 0.6 radii on a brisk flight 5 cm under the ceiling), so that 83 % of the flight lay nearer than the form is
    trusted and the fit on all of it was kept."""
    keys = [k for k in final.names if effect_name(k) in SURFACE_DISTANCE]
    if len(keys) == len(final.names):
        return None, near
    held = {k: v for k, v in hold.items() if k in keys}
    alone = fitter.candidate(keys, previous={k: v for k, v in final.previous().items() if k in keys}, hold=held)
    current, within = _fixed_point(fitter, keys, alone, near_rows(data, regressors, alone.fit.effects), held, data,
                                   regressors, say)
    if current is None:
        return None, near
    return _added_back(fitter, current, within, final, keys, hold, data, regressors, n_eff, say)


def _added_back(fitter: Fitter, current: Candidate, near: list[np.ndarray], final: Candidate, keys: list[str],
                hold: dict[str, dict[int, float]], data: FlightData, regressors: list[Regressor], n_eff: float,
                say: Callable[[str], None] | None) -> tuple[Candidate, list[np.ndarray]]:
    """``current`` (the surface effects ``keys`` fitted within their range, ``near`` set aside) with each other effect
    of ``final`` added back where it pays within the range."""
    for key in (k for k in final.names if k not in keys):
        names = [k for k in final.names if k in current.names or k == key] + \
            [k for k in current.names if k not in final.names]
        previous = {**{k: v for k, v in final.previous().items() if k == key}, **current.previous()}
        held = {k: v for k, v in hold.items() if k in names}
        candidate = fitter.candidate(names, previous=previous, hold=held, exclude=near)
        if _score(candidate, near, n_eff) < _score(current, near, n_eff) and not open_cases(candidate, held):
            again, near_again = _fixed_point(fitter, names, candidate, near_rows(data, regressors,
                                                                                  candidate.fit.effects),
                                             held, data, regressors, say)
            if again is not None:
                current, near = again, near_again
    return current, near


def _left_out_surface(fitter: Fitter, final: Candidate, hold: dict[str, dict[int, float]], data: FlightData,
                      regressors: list[Regressor], n_eff: float, say: Callable[[str], None] | None
                      ) -> tuple[Candidate, list[np.ndarray], Candidate] | None:
    """A ground or ceiling effect that ``final`` lacks, fitted alone within the range its form is trusted, with each
    effect of ``final`` added back where it pays there; taken when the flight then determines it and it scores
    better within that range than ``final`` does: that set, the rows set aside and the effect's fit on every sample
    (``None`` otherwise).

    On every sample a form that levels off nearer the surface than the flight's own gain can lose to a thrust scale,
    which describes a flat gain: flown 8-18 cm over the ground with a gain levelling off at 0.9 of a 0.106 m radius,
    a thrust scale of 1.054 was chosen first and the ground effect beside it ran to its 0.5 m bound and was left out.
    Fitted alone where its form is trusted, its radius is 0.1060 m and the thrust scale no longer pays."""
    for key in (k for k in fitter.templates if k in SURFACE_DISTANCE):
        if SURFACE_DISTANCE[key] not in {r.name for r in regressors}:
            continue
        alone = fitter.candidate([key])
        near = near_rows(data, regressors, alone.fit.effects)
        if not any(n.any() for n in near):
            continue  # the flight never came near enough to that surface for the range to matter
        current, near = _fixed_point(fitter, [key], alone, near, {}, data, regressors, say)
        if current is None or open_cases(current, {}):
            continue
        current, near = _added_back(fitter, current, near, final, [key], hold, data, regressors, n_eff, say)
        held = {k: v for k, v in hold.items() if k in current.names}
        before = fitter.candidate(list(final.names), previous=final.previous(),
                                  hold={k: v for k, v in hold.items() if k in final.names}, exclude=near)
        if open_cases(current, held) or _score(current, near, n_eff) >= _score(before, near, n_eff):
            continue
        if not _material(current, before, near, data.weight):
            continue
        return current, near, alone
    return None


def _leaked(current: Candidate, near: list[np.ndarray], data: FlightData, regressors: list[Regressor]
            ) -> list[np.ndarray] | None:
    """Per segment, per sample: the vertical force (N) that the smoothing carries into each sample's residual from
    the samples nearer a surface than the form is trusted (``None`` when too few rows were set aside to say).

    What the form leaves there is taken from ``current``'s held-out vertical residual of the rows set aside, its
    mean in :data:`LEAKAGE_BINS` bins of distance (interpolated between them), and spread over each window with the
    kernel's own step weights, as the measured force was."""
    out = [np.zeros(seg.n) for seg in data.segments]
    found = False
    for effect in (e for e in current.fit.effects if e.name in SURFACE_DISTANCE):
        inside = _inside(data, regressors, effect)
        if not inside:
            continue
        rows = [n & i[seg.fit_rows] for seg, n, (_, i) in zip(data.segments, near, inside)]
        distance = np.concatenate([d[seg.fit_rows][r] for seg, (d, _), r in zip(data.segments, inside, rows)])
        vertical = np.concatenate([res[r, 2] for res, r in zip(current.cv_residual, rows)])
        if len(distance) < 2 * LEAKAGE_BINS:
            continue
        edges = np.quantile(distance, np.linspace(0.0, 1.0, LEAKAGE_BINS + 1))
        bins = [(distance >= a) & (distance <= b) for a, b in zip(edges[:-1], edges[1:])]
        centres = np.array([np.median(distance[b]) for b in bins])
        means = np.array([np.mean(vertical[b]) for b in bins])
        for s, (seg, (d, near_sample)) in enumerate(zip(data.segments, inside)):
            left = np.where(near_sample, np.interp(d, centres, means), 0.0)
            spread = np.correlate(0.5 * (left[:-1] + left[1:]), seg.step_weights(), mode="valid")
            out[s] += spread[np.minimum(seg.kernel.start, len(spread) - 1)]
        found = True
    return out if found else None


def leakage_shift(fitter: Fitter, current: Candidate, near: list[np.ndarray], hold: dict[str, dict[int, float]],
                  data: FlightData, regressors: list[Regressor]) -> dict[str, dict[str, Any]]:
    """How far each surface effect's parameters of ``current`` (fitted without the rows ``near``) move when the force
    the smoothing carries into the rows fitted on from the samples set aside (:func:`_leaked`) is taken out of the
    residual they are fitted to; ``{}`` when too few rows were set aside to say.

    A row's measured force is smoothed over a window (a second by default) and so carries some of what the form
    leaves on samples nearer the surface. Where the gain levels off just inside the range (0.7-0.9 of the radius)
    that bends the parameters: flown 2-15 cm under a ceiling levelling off at 0.8 of its 0.078 m radius, the offset
    came out 14 mm for 12 mm at a standard error of 0.45 mm. Removed, it moves by 2.9 mm. The leak is estimated
    roughly (it overshoots: that offset went from 14.6 % large to 9.6 % small, and a ceiling offset levelling off at
    0.9 radii from 11 % large to 63 % small), so the shift is not taken as a correction: it is counted as an
    uncertainty of the parameters (:class:`discovery.workflow.Discovery` adds it to their standard errors)."""
    from discovery.fitting import Fitter

    corrected = current
    for round_ in range(LEAKAGE_ROUNDS):
        leaked = _leaked(corrected, near, data, regressors)
        if leaked is None:
            return {}
        target = [r - np.outer(c, [0.0, 0.0, 1.0]) for r, c in zip(fitter.r_nom, leaked)]
        refit = Fitter(data, target, fitter.templates, fitter.scorer).candidate(
            list(current.names), previous=current.previous(), hold=hold, exclude=near)
        if round_ + 1 < LEAKAGE_ROUNDS:  # its residual on the measured force, from which the next round takes the leak
            corrected = fitter.candidate(list(current.names), previous=refit.previous(), exclude=near,
                                         hold={k: dict(enumerate(np.atleast_1d(v).ravel())) for k, v
                                               in refit.previous().items()})
    return {e.name: {k: (np.asarray(v, dtype=float) - np.asarray(e.params_dict()[k], dtype=float)).tolist()
                     for k, v in moved.params_dict().items()}
            for e, moved in zip(current.fit.effects, refit.fit.effects) if e.name in SURFACE_DISTANCE}


def fit_within_form(fitter: Fitter, final: Candidate, hold: dict[str, dict[int, float]], data: FlightData,
                    regressors: list[Regressor], n_eff: float, say: Callable[[str], None] | None = None
                    ) -> tuple[Candidate, dict[str, dict[int, float]], dict[str, Any] | None]:
    """``final`` refitted without the samples nearer a surface than its ground or ceiling effect's form is trusted,
    the entries held, and what was done (``None`` when ``final`` has no such effect or never flew that near).

    Within that range the set is asked again, as the backward check of :mod:`discovery.selection` does, on the
    held-out residual of the rows fitted on (``n_eff``: the flight's effective samples per axis): an effect that only
    paid for itself on the samples set aside, or a distance offset that only bent the gain toward them, goes.

    The summary holds the effects, the rotors' ``closest_m`` approach to their surfaces, ``share_set_aside`` of the
    fit rows and the seconds, each effect's parameters
    fitted on everything and within the form, the ``set_aside_misfit`` of the fit on everything (the ratio, the
    limit and whether the forms were kept for it: :func:`_set_aside_misfit`), what was ``changed`` and
    ``applied``: False (the fit on everything
    kept) when less than :data:`MIN_FITTED_SHARE` of the rows would stay or the refit leaves a parameter
    undetermined."""
    effects = [e for e in final.fit.effects if e.name in SURFACE_DISTANCE]
    values = {r.name: r.values for r in regressors}
    if effects:
        near = near_rows(data, regressors, final.fit.effects)
        if not any(n.any() for n in near):
            return final, hold, None
        misfit = _set_aside_misfit(final, near, n_eff)
        keep_forms = misfit is not None and misfit[0] <= misfit[1]
        closest = [float(np.nanmin(values[SURFACE_DISTANCE[e.name]])) for e in effects
                   if SURFACE_DISTANCE[e.name] in values]
        summary: dict[str, Any] = {"effects": [e.name for e in effects],
                                   "surfaces": [SURFACE_NAME[e.name] for e in effects],
                                   "closest_m": min(closest) if closest else None,
                                   "on_all": {e.name: e.params_dict() for e in effects}, "applied": False,
                                   "changed": []}
        if misfit is not None:
            summary["set_aside_misfit"] = {"ratio": misfit[0], "limit": misfit[1], "forms_kept": keep_forms}
        found: Candidate | None
        found, near = _fixed_point(fitter, list(final.names), final, near, hold, data, regressors, say)
        if found is None:
            found, near = _from_surface_alone(fitter, final, near, hold, data, regressors, n_eff, say)
            if found is not None and list(found.names) != list(final.names):
                summary["changed"].append({"from": list(final.names), "to": list(found.names)})
        rounds = len(final.names) + 1
    else:
        left_out = _left_out_surface(fitter, final, hold, data, regressors, n_eff, say)
        if left_out is None:
            return final, hold, None
        found, near, alone = left_out
        key = alone.names[0]
        summary = {"effects": [key], "surfaces": [SURFACE_NAME[key]],
                   "closest_m": float(np.nanmin(values[SURFACE_DISTANCE[key]])),
                   "on_all": {key: alone.fit.effects[0].params_dict()}, "applied": False,
                   "changed": [{"from": list(final.names), "to": list(found.names)}], "added": key}
        rounds = len(found.names) + 1
        keep_forms = False
    current = found
    for _ in range(rounds):
        if current is None:
            break
        simpler = _simpler(fitter, current, near, hold, n_eff, data.weight, keep_forms)
        if simpler is None:
            break
        again, near_again = _fixed_point(fitter, list(simpler.names), simpler,
                                         near_rows(data, regressors, simpler.fit.effects), hold, data, regressors, say)
        if again is None:  # the simpler set's range leaves too little: the set before it stays
            break
        change: dict[str, Any] = {"from": list(current.names), "to": list(simpler.names)}
        if _score(simpler, near, n_eff) >= _score(current, near, n_eff):
            change["immaterial"] = True  # left out as explaining nothing material within the range
        summary["changed"].append(change)
        current, near = again, near_again
    if not effects and (current is None or open_cases(current, hold)):
        return final, hold, None  # the effect left out stays out, as the fit on every sample had it
    total_s = sum(seg.n * seg.dt for seg in data.segments)
    summary["share_set_aside"] = _share(near)
    summary["seconds_set_aside"] = float(_share(near) * total_s)
    if current is None:
        summary["reason"] = (f"{100 * _share(near):.0f} % of the flight had a rotor that near: the fit on all of it "
                             "is kept")
        summary["changed"] = []
        return final, hold, summary
    if open_cases(current, hold):
        summary["reason"] = "without those samples the flight no longer determines every parameter: the fit on " \
                            "all of it is kept"
        summary["changed"] = []
        return final, hold, summary
    summary["applied"] = True
    summary["within_form"] = {e.name: e.params_dict() for e in current.fit.effects if e.name in SURFACE_DISTANCE}
    summary["leakage_shift"] = leakage_shift(fitter, current, near, hold, data, regressors)
    return current, {k: v for k, v in hold.items() if k in current.names}, summary
