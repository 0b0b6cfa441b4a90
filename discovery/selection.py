"""Which effects to add: greedy forward selection on held-out data with a parsimony criterion.

Every candidate is judged by its cross-validated residual: the log is cut into time
blocks dealt round robin to folds, each fold is predicted by parameters fitted on the
others (:meth:`discovery.fitting.EffectFit.cross_validate`), and the held-out mean
squared force residual (the vector norm, summed over the world axes) is what a model
scores. The score is the Gaussian log-likelihood of the force-gap vector plus a price
per parameter::

    score(M) = 3 N ln(MSE(M)) + c p(M),      MSE = sum_a MSE_a,   c = max(chi2_1(1 - alpha), ln 3N)

so every axis counts by its physical share of the force gap: a tiny gain on the
quietest axis cannot outweigh halving the error on another (a score summing each
axis' own log-error would let it). ``p(M)`` counts parameters (an option that adds none, wall suction scaled by rotor
thrust, counts as one), ``N`` is the number of
independent residual values per axis (samples divided by the smoothing kernel's
correlation length ``1 / sum(w^2)``), and ``alpha = 1e-4``: a parameter has to raise
the held-out likelihood as much as a 3.9-sigma detection would (``c = 15.1``), or by
the BIC's ``ln 3N`` on very long logs.

Forward selection adds, one at a time, the candidate that lowers the score most (all
parameters of the model refitted jointly, so two effects present together are both
found) and that explains a material share (:data:`MIN_SHARE`, 2 %) of the held-out
force-gap energy the model leaves without it, and a material force: at least
:data:`MIN_WEIGHT_SHARE` (0.2 %) of the vehicle's weight, rms over the held-out log. It
stops when none does. The force floor matters on quiet logs: on a clean 500 Hz log whose
nominal gap was 0.011 N, a thrust scale of 0.99956 took 13 % of it (0.004 N rms, 0.04 %
of the weight) and beat the parameter price, though no effect was flown; on 48 clean logs
(six scenarios, 50 to 1,000 Hz) the best candidate explained at most 0.009 N held out,
while the weakest effect of the acceptance set explains 0.19 N. A backward pass then drops any
effect whose removal does not raise the score or that no longer explains a material
share next to the others, so nothing stays that does not pay for itself.

The literature's fuller forms (:data:`VARIANTS`: wall suction scaled by rotor thrust,
ground and ceiling effects with the distance offset) are candidates of their own
(keys such as ``ground_effect[distance_offset]``), judged by the same score, at most
one form per effect, tried in a round only where the plain form improves the model,
and kept only when their extra parameters are determined (and some entry of a vector
main parameter: :func:`_form_determined`). Quadratic
drag on the air-relative velocity with a fitted steady wind (``quadratic_drag[wind]``)
looks like a steady force plus drag, so it is tried after the selection in place of
any chosen subset of :data:`WIND_REPLACES`, and kept where it scores better; the
backward pass then runs again, since the wind can leave a companion nothing to explain.

Once the effects are chosen, each is given the form that scores best next to all the
others (:func:`_refine_forms`): the round that chose an effect saw only the effects
chosen before it.

Candidates the flight cannot tell apart are recorded (:attr:`Selection.alike`): a
runner-up of the chosen step whose score is within one parameter price of the
winner's and that explains a material share on its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import chdtri

from discovery.coverage import NEAR_SURFACE, THRUST_VARIATION, thrust_variation
from discovery.fitting import STARTS, Candidate, Fitter, applicable
from discovery.layout import ParameterLayout
from discovery.motor_lag import LAG_KEY, UNDETERMINED_LAG, LagTerm, MotorLag
from discovery.noise import noise_floor
from discovery.regressors import regressors
from discovery.residuals import FlightData
from discovery.thrust_map import make_candidate
from discovery.unexplained import is_unexplained
from wall_env.effects import Effect

__all__ = ["ALPHA", "MIN_SHARE", "MIN_WEIGHT_SHARE", "VARIANTS", "Candidate", "Step", "Selection", "effective_samples",
           "parameter_price", "score", "priced", "make_fitter", "options_without_parameters", "forward_selection",
           "fit_only", "floor_left_by"]

ALPHA = 1e-4  # significance a parameter must reach on held-out data
MIN_SHARE = 0.02  # share of the held-out force-gap energy left without it that an effect must explain
MIN_WEIGHT_SHARE = 0.002  # held-out rms force an effect must explain, as a share of the vehicle's weight
VARIANTS: dict[str, list[dict]] = {
    "wall_suction": [{"thrust_scaling": True}],
    "ground_effect": [{"distance_offset": True}],
    "ceiling_effect": [{"distance_offset": True}],
    "thrust_scale": [{"affine": True}],  # an affine thrust map (discovery.thrust_map)
}
#: drag in a steady wind looks like a steady force plus drag, so it is tried after selection,
#: in place of whatever of these the selection chose
WIND_REPLACES = ("constant_force", "linear_drag", "quadratic_drag")


def effective_samples(data: FlightData) -> float:
    """Independent residual values per axis: ``sum over segments of n sum(w^2)``, ``w`` the kernel's step weights."""
    return data.effective_samples()


def parameter_price(n_eff_per_axis: float, alpha: float = ALPHA) -> float:
    """``max(chi2_1 quantile at 1 - alpha, ln 3N)``: what each parameter must buy in ``2 x`` log-likelihood."""
    return max(float(chdtri(1, alpha)), math.log(3.0 * n_eff_per_axis))  # chdtri: chi2's inverse survival


def score(mse_axes: np.ndarray, n_params: int, n_eff_per_axis: float, alpha: float = ALPHA) -> float:
    """``3 N ln(sum_a MSE_a) + c p``: lower is better."""
    total = max(float(np.sum(np.asarray(mse_axes, dtype=float))), 1e-300)
    return 3.0 * n_eff_per_axis * math.log(total) + parameter_price(n_eff_per_axis, alpha) * n_params


@dataclass
class Step:
    """One round of forward selection."""

    tried: list[dict]  # per candidate: name, cv_mse, gain, score, params
    chosen: str | None
    mse_before: float
    mse_after: float


@dataclass
class Selection:
    """What forward selection found."""

    chosen: Candidate
    nominal: Candidate
    steps: list[Step] = field(default_factory=list)
    removed: list[str] = field(default_factory=list)
    explained: dict[str, float] = field(default_factory=dict)  # name -> share of the nominal held-out energy
    n_eff: float = 1.0  # independent residual values per axis
    alike: list[dict] = field(default_factory=list)  # candidates the flight could not tell apart
    forms: list[dict] = field(default_factory=list)  # the form (candidate key) of each chosen effect
    form_limits: list[dict] = field(default_factory=list)  # fuller forms of chosen effects the flight left open
    motor_lag: dict | None = None  # the lag fitted with the chosen effects, when one was looked for (_motor_lag)
    fitter: Fitter | None = field(default=None, repr=False)  # every fit made, for refits next to the chosen ones


def make_fitter(data: FlightData, r_nom: list[np.ndarray], templates: dict[str, Effect],
               n_eff: float | None = None) -> Fitter:
    """The run's :class:`~discovery.fitting.Fitter`, scoring every set by :func:`score` with :func:`priced`."""
    n = data.effective_samples() if n_eff is None else n_eff

    def scorer(mse_axes: np.ndarray, layout: ParameterLayout, held: np.ndarray) -> float:
        return score(mse_axes, priced(layout, held), n)

    return Fitter(data, r_nom, templates, scorer)


def priced(layout: ParameterLayout, held: np.ndarray | None = None) -> int:
    """Parameters the score prices a set laid out by ``layout`` at: every free packed entry (a flight's own wind
    counts once per flight), plus each effect's options without parameters; a motor lag counts one
    (:func:`priced_parameters`); entries ``held`` at a value are not parameters."""
    held = np.zeros(layout.size, dtype=bool) if held is None or held.size != layout.size else held
    total = 0
    for e, effect in enumerate(layout.templates):
        if isinstance(effect, MotorLag):
            total += priced_parameters(effect)
            continue
        total += int((layout.entries_of(e) & ~held).sum()) + options_without_parameters(effect)
    return total


def priced_parameters(effect: Effect) -> int:
    """How many parameters the score prices ``effect`` at: its own, plus its options without parameters.

    A motor lag's segment start errors are not priced: a cross-validation fold whose held-out rows
    a start error reaches takes that start settled (:meth:`discovery.motor_lag.LagTerm.fold_fixed`),
    so no held-out row is predicted with a start error fitted to it and the errors cannot flatter
    the held-out score; they only keep the time constant from being biased by a start the rotors
    were not settled at.
    """
    if isinstance(effect, MotorLag):
        return 1
    return effect.param_size + options_without_parameters(effect)


def options_without_parameters(effect: Effect) -> int:
    """Options switched on from their default that add no parameter (wall suction's thrust scaling).

    Such a form has as many parameters as the plain one, so on a flight that cannot tell them
    apart either would win by noise; each such option is priced as one parameter, so the data
    choose it only when it explains more by as much as a parameter must.
    """
    return 0 if _extra_parameters(effect) else len(_switched_options(effect))


def _extra_parameters(effect: Effect) -> list:
    """The parameters a fuller form has beyond its plain form (the distance offset, a wind)."""
    return [p for p in effect.parameters if p not in type(effect).parameters]


def _switched_options(effect: Effect) -> list[str]:
    """The options ``effect`` sets away from their defaults."""
    return [k for k, v in effect.option_values.items() if v != type(effect).options.get(k)]


def variant_key(name: str, options: dict) -> str:
    """The candidate key of a fuller form, e.g. ``quadratic_drag[wind]``."""
    return f"{name}[{','.join(sorted(k for k, v in options.items() if v))}]"


def effect_name(key: str) -> str:
    return key.split("[", 1)[0]


def _with_variants(templates: dict[str, Effect], variants: dict[str, list[dict]]) -> dict[str, Effect]:
    out = dict(templates)
    for name, template in templates.items():
        for options in variants.get(name, []):
            if all(template.option_values.get(k) == v for k, v in options.items()):
                continue
            out[variant_key(name, options)] = make_candidate(name, **{**template.option_values, **options})
    return out


def forward_selection(data: FlightData, r_nom: list[np.ndarray], candidates: list[Effect], max_effects: int = 3,
                      progress=None, variants: dict[str, list[dict]] | None = None,
                      look_for_lag: bool = False) -> Selection:
    """Greedy forward selection over the candidates and their fuller forms, then a backward check; with
    ``look_for_lag``, a motor lag fitted next to the chosen effects (:attr:`Selection.motor_lag`)."""
    base = {e.name: e for e in candidates if applicable(e, data)}
    templates = _with_variants(base, VARIANTS if variants is None else variants)
    thrust = data.concat([seg.thrust for seg in data.segments])
    steady = len(thrust) > 0 and thrust_variation(thrust) < THRUST_VARIATION
    steady_limits = _affine_map_confounded(data, thrust) if steady and AFFINE_MAP in templates else []
    if steady_limits:  # on this flight the affine map would fit the surface's pull: not a candidate
        del templates[AFFINE_MAP]
    n_eff = effective_samples(data)
    price = parameter_price(n_eff)
    fitter = make_fitter(data, r_nom, templates, n_eff)
    nominal = fitter.candidate([])
    current = nominal
    steps: list[Step] = []
    alike: list[dict] = []

    floor = (MIN_WEIGHT_SHARE * data.weight) ** 2  # N^2

    def material(better: Candidate, worse: Candidate) -> bool:
        """``better`` explains at least MIN_SHARE of the force-gap energy that ``worse`` leaves, and at least
        MIN_WEIGHT_SHARE of the weight in rms force."""
        explained = worse.mse - better.mse
        return worse.mse > 0 and explained / worse.mse >= MIN_SHARE and explained >= floor

    def ask(key: str, current: Candidate, tried: list[dict[str, Any]], scored: list[Candidate],
            helpful: set[str]) -> None:
        """Fit ``current`` with ``key`` added; record it in ``tried``, in ``scored`` when it is usable, and its effect
        in ``helpful`` when it scores better than ``current``."""
        if progress is not None:
            progress(f"trying {' + '.join(current.names + [key])}")
        cand = fitter.candidate(current.names + [key], previous=current.previous())
        gain = 1.0 - cand.mse / current.mse if current.mse > 0 else 0.0
        usable = cand.score < current.score and material(cand, current) and _form_determined(cand, key)
        tried.append({"name": key, "cv_mse_N2": cand.mse, "gain": gain, "score": cand.score,
                      "material": material(cand, current), "params": cand.fit.effects[-1].params_dict()})
        if cand.score < current.score:
            helpful.add(effect_name(key))
        if usable:
            scored.append(cand)

    def grow(current: Candidate, skip: tuple[str, ...] = ()) -> Candidate:
        """Forward steps from ``current``: the effect whose addition scores best, while one pays (effects named
        in ``skip`` are not asked)."""
        while len(current.names) < max_effects:
            taken = {effect_name(k) for k in current.names} | set(skip)
            remaining = [k for k in templates if effect_name(k) not in taken]
            if not remaining:
                break
            tried: list[dict[str, Any]] = []
            scored: list[Candidate] = []
            helpful: set[str] = set()  # plain forms that improve on the current model this round
            for key in remaining:
                if "[" in key and effect_name(key) not in helpful:
                    continue  # a fuller form is worth fitting only where its plain form already helps
                ask(key, current, tried, scored, helpful)
            if not scored and not current.names and AFFINE_MAP in remaining and \
                    AFFINE_MAP not in {t["name"] for t in tried}:
                # from the nominal model, a thrust scale and a steady force that cancel near hover pay only together:
                # so may the map. Not later: beside a linear drag the map stood in for a motor lag, whose own fit
                # comes after the effects are chosen, and bent it from 58.6 ms to 64.4 ms (57.7 ms flown)
                ask(AFFINE_MAP, current, tried, scored, helpful)
            tried.sort(key=lambda r: r["score"])
            if not scored:
                steps.append(Step(tried, None, current.mse, current.mse))
                break
            scored.sort(key=lambda c: c.score)
            best, tie = _closed_loop_tie(scored, price, steady)
            for other in scored:  # one record per pair: an effect's plain and fuller forms may both be within a price
                pair = (effect_name(best.names[-1]), effect_name(other.names[-1]))
                if other is not best and abs(other.score - best.score) < price and pair[0] != pair[1] \
                        and not any((a["chosen"], a["alike"]) == pair for a in alike):
                    alike.append({"chosen": pair[0], "alike": pair[1],
                                  "score_difference": round(other.score - best.score, 2),
                                  "explained_chosen": round((current.mse - best.mse) / nominal.mse, 4),
                                  "explained_alike": round((current.mse - other.mse) / nominal.mse, 4),
                                  **({"why_chosen": CLOSED_LOOP_TIE} if tie and other is scored[0] else {})})
            steps.append(Step(tried, best.names[-1], current.mse, best.mse))
            current = best
        return current

    current = grow(current)
    current, removed = _backward(fitter, current, material)
    refined, swaps = _refine_forms(fitter, current)
    if swaps:  # another form may leave a companion effect nothing to explain
        current, dropped = _backward(fitter, refined, material)
        removed += dropped
    if "quadratic_drag" in base and variants is None:
        in_wind = _drag_in_wind(fitter, current, base["quadratic_drag"], progress)
        if in_wind is not current:  # the wind may leave a companion nothing to explain (a thrust scale of 0.9999)
            current, dropped = _backward(fitter, in_wind, material)
            removed += dropped
            # and another effect may now pay: several flights' own winds took what a steady force and a linear
            # drag could not, and a wall suction they had crowded out (k_s 5.15 N/m, scoring -6150 against -3688
            # beside the drag in wind) is then found. What the wind may replace is not asked again: the drag in
            # wind was tried beside each subset of it
            grown = grow(current, skip=WIND_REPLACES)
            if grown is not current:
                current, dropped = _backward(fitter, grown, material)
                removed += dropped
    explained = sequential_explained(fitter, current, nominal)
    chosen_names = {effect_name(k) for k in current.names}
    alike = [a for a in alike if a["chosen"] in chosen_names]
    forms = [{"effect": effect_name(k), "form": k, **({"chosen_first_as": swaps[k]} if k in swaps else {})}
             for k in current.names]
    form_limits = steady_limits + _form_limits(fitter, current)
    lag = _motor_lag(fitter, current, nominal, price, progress) if look_for_lag else None
    return Selection(current, nominal, steps, removed, explained, n_eff, alike, forms, form_limits, lag, fitter)


AFFINE_MAP = variant_key("thrust_scale", {"affine": True})
#: the regressors of the surfaces whose effects scale the thrust (ground and ceiling effects)
THRUST_SURFACES = ("height above ground", "distance to ceiling")
NEAR_SHARE = 0.1  # of the samples near such a surface before its pull is much of what a steady thrust answers
HOLD_VARIATION = 0.01  # std/mean of the thrust below which a flight is a hold, wherever it is flown


def _affine_map_confounded(data: FlightData, thrust: np.ndarray) -> list[dict]:
    """Why the affine thrust map is not a candidate, as a limit (empty when it is), on a flight whose thrust varies
    by less than :data:`~discovery.coverage.THRUST_VARIATION`: when the flight spends :data:`NEAR_SHARE` of its
    samples within :data:`~discovery.coverage.NEAR_SURFACE` of the ground or a ceiling (not a take-off and a landing
    alone), or anywhere when it varies by less than :data:`HOLD_VARIATION` (a hold).

    The map's scale and offset are told apart by how the force follows the thrust's changes. A steady thrust's small
    changes are the closed loop answering the forces on the vehicle, and near the ground or a ceiling much of that
    force is the surface's, a function of the height the thrust then follows: hovering 13 cm under a ceiling (the
    thrust varying by 0.5 %), a map of scale 0.38 with an 8.1 N offset fitted the ceiling's pull through the
    thrust and scored two parameters' prices ahead of the ceiling effect. Away from surfaces the loop mostly answers
    a random force the thrust cannot foretell, and a hover whose thrust varies by 2 % determined a map within 2 %.
    Holding still it answers little else but the forces the flight carries, whatever they depend on: holding near
    1.2 m against a force growing with height (the thrust varying by 0.5 %), a map of scale 1.50 with a -7.6 N
    offset was written. The plain thrust scale and the steady force stay (the flight limits say they look alike)."""
    from discovery.determination import determining_manoeuvre

    near = [r.name for r in regressors(data) if r.name in THRUST_SURFACES
            and np.mean(np.nan_to_num(r.values, nan=np.inf) <= NEAR_SURFACE) >= NEAR_SHARE]
    if not near:
        if thrust_variation(thrust) >= HOLD_VARIATION:
            return []
        return [{"effects": [AFFINE_MAP], "reason": f"not fitted: the thrust varies by only "
                                                    f"{100 * thrust_variation(thrust):.2f} % (std/mean), a hold, and "
                                                    "a thrust map's scale and offset are told apart by how the force "
                                                    "follows the thrust's changes, which in a hold are the closed "
                                                    "loop answering the forces on the vehicle",
                 "manoeuvre": determining_manoeuvre("thrust_scale", "offset")}]
    surfaces = " and ".join("the ground" if n == "height above ground" else "the ceiling" for n in near)
    return [{"effects": [AFFINE_MAP], "reason": f"not fitted: the thrust varies by only "
                                                f"{100 * thrust_variation(thrust):.1f} % (std/mean) near {surfaces}, "
                                                "and a thrust map's scale and offset are told apart by how the force "
                                                "follows the thrust's changes, which there are the closed loop "
                                                "answering the surface's pull",
             "manoeuvre": determining_manoeuvre("thrust_scale", "offset") + ", away from the ground and ceilings"}]


#: why an effect within one price of a thrust map was chosen over it on a steady thrust (:func:`_closed_loop_tie`)
CLOSED_LOOP_TIE = ("the thrust varied too little to tell a thrust map by, and under a stiff loop its small changes "
                   "answer the random forces on the vehicle, which a thrust map then fits: the tie goes to the other")


def _closed_loop_tie(scored: list[Candidate], price: float, steady: bool) -> tuple[Candidate, bool]:
    """The candidate a round chooses from ``scored`` (best score first): the best, except that on a flight whose
    thrust is ``steady`` (varies by less than :data:`~discovery.coverage.THRUST_VARIATION`) a thrust scale within
    one parameter's price of another effect with no more parameters gives way to it; and whether it did.

    Under a stiff altitude loop the thrust's changes answer every vertical force, the random one included, so a
    thrust map with a scale below 1 fits part of that force, and the bias goes its way on every flight: hovering
    under a ceiling with the second simulator's random force doubled (0.5 N rms), an affine map of scale 0.32-0.35
    scored better than the ceiling effect by less than a price on 4 of 6 seeds; given the tie, the ceiling effect
    came out with its radius within 0.5 % on all 6. A map ahead by more than a price is kept (see the discovery
    guide: a vertical sweep of 3.6 cm put it 1.6 prices ahead).
    """
    best = scored[0]
    if not steady or effect_name(best.names[-1]) != "thrust_scale":
        return best, False
    for other in scored[1:]:
        if other.score - best.score >= price:
            break
        # parsimony is not overridden: a steady force (three parameters) tied with a thrust scale (one) stays behind
        if effect_name(other.names[-1]) != "thrust_scale" and other.n_params <= best.n_params:
            return other, True
    return best, False


def _motor_lag(fitter: Fitter, current: Candidate, nominal: Candidate, price: float, progress) -> dict:
    """A motor lag fitted jointly with the chosen effects (:mod:`discovery.motor_lag`), and whether it counts.

    It counts when its 95 % interval is away from zero and from its bounds and it lowers the
    held-out score. When the chosen effects leave no more than noise, that score may also be taken
    on the rows no segment's start error reaches (predicted from a settled start, a rotor that
    began far from its command made a right lag score worse there than none), and a lag short of a
    parameter's price counts when it predicts those rows better at all, the fit determines it
    beyond that price (``(tau / std)^2``) and leaving it out moves a chosen parameter (30 ms flown
    on the second simulator's flights with new periods: 28.2 +- 5.0 ms, the held-out gap 6.5 %
    smaller, one price short, and D[2] 23 % low without it). Next to a structure the effects leave,
    neither relaxation is trusted (a 94 ms lag was kept beside a force growing with height).
    Returns ``{"time_constant_s", "std_s", "interval_95_share", "to_narrow", "explained",
    "force_rms_N", "kept", "reason", "determined", "moves", "effect_std"}`` (``interval_95_share``: the largest
    error the 95 % interval allows, as a share of the true time constant
    (:func:`~discovery.determination.interval_share`); ``to_narrow``: the manoeuvre that determines it better,
    when that share is above :data:`~discovery.determination.NARROW_INTERVAL_SHARE`, else None;
    ``explained``: the share of the nominal held-out energy it adds to the chosen effects, on the
    rows past the starts;
    ``force_rms_N``: the force it accounts for; ``determined``: its interval is away from zero
    and its bounds; ``moves``: :func:`_moves`; ``effect_std``: each chosen effect's standard errors
    fitted beside the lag, which carry the lag's own uncertainty).

    A lag found on a climb and descent at one pace is told apart from a vertical drag only by the
    thrust's other changes, so one minute of such a flight determines it to about 6 % (one
    standard error; 30 ms flown, second simulator, 22 logs: 1.7 ms on average, the errors 1.1
    standard errors rms): the summary then gives the interval and the manoeuvre that narrows it.

    Unlike an effect it need not explain a share of the force gap the chosen effects leave, nor a
    share of the weight. It is not an effect to be named but a property of the vehicle, and one
    that is determined matters for what is fitted next to it even when its own force is small:
    on a climb and descent at one pace a lag looks like a negative vertical drag, so a drag chosen
    first absorbs most of it and the pair lowers the gap only a little (30 ms lag, second
    simulator: 23.6 +- 3.2 ms, the pair explaining 0.5 % more), yet the drag left without it is
    41 % low; and hovering over the ground a 30 ms lag accounting for 0.005 N rms (0.04 % of the
    weight, fitted as 29.6 +- 2.2 ms) left the ground effect's distance offset 12.5 % low, 3.0 %
    with the lag known.
    """
    from discovery.determination import MANOEUVRES, NARROW_INTERVAL_SHARE, interval_share, undetermined_cases

    scale = [float(e.values["scale"][0]) for e in current.fit.effects if e.name == "thrust_scale"]
    template = MotorLag(segments=len(fitter.data.segments), thrust_scale=scale[0] if scale else 1.0)
    fitter.add(LAG_KEY, template)
    if progress is not None:
        progress(f"trying {' + '.join(current.names + [LAG_KEY])}")
    cand = fitter.candidate(current.names + [LAG_KEY], previous=current.previous())
    lag, std = cand.fit.effects[-1], cand.fit.std_dicts()[-1]
    tau, tau_std = float(lag.values["time_constant"][0]), float(std["time_constant"])
    cases = [c for c in undetermined_cases([lag], [std]) if c["name"] == "time_constant"]  # start errors: nuisance
    assert cand.problem is not None
    term = cand.problem.terms[-1]
    assert isinstance(term, LagTerm)
    forces = [term.at_rows(s, lag.param_vector())[0] for s in range(len(fitter.data.segments))]
    force_rms = float(np.sqrt(np.mean(np.sum(np.concatenate(forces) ** 2, axis=1))))
    moves = _moves(current, cand)
    clear = term.clear_of_starts(lag.param_vector())
    with_lag, without = _scored_on(fitter, cand, clear), _scored_on(fitter, current, clear)
    if cand.score < current.score:
        pays = True
    elif is_unexplained(math.sqrt(without[1]), floor_left_by(fitter.data, current), fitter.data.weight,
                        MIN_WEIGHT_SHARE):
        # next to a structure the chosen effects leave, neither the rows past the starts nor the lag's standard
        # error can be trusted to tell a lag from a share of that structure
        pays = False
    else:
        # a lag the fit determines beyond a parameter's price, and without which a chosen parameter would be
        # written wrong, counts once it predicts held-out rows at all better
        sure = moves is not None and tau_std > 0 and (tau / tau_std) ** 2 >= price and with_lag[1] < without[1]
        pays = with_lag[0] < without[0] or sure
    if not pays:
        reason = "it does not lower the held-out score"
    elif cases:
        reason = f"{UNDETERMINED_LAG}: {cases[0]['reason']}"
    else:
        reason = ""
    nominal_mse = _scored_on(fitter, nominal, clear)[1]
    explained = (without[1] - with_lag[1]) / nominal_mse if nominal_mse > 0 else 0.0
    share = interval_share(tau, tau_std)  # inf when the interval reaches zero
    to_narrow = MANOEUVRES[(LAG_KEY, "time_constant")] if share > NARROW_INTERVAL_SHARE else None
    joint_std = {e.name: std for e, std in zip(cand.fit.effects[:-1], cand.fit.std_dicts()[:-1])}
    return {"time_constant_s": tau, "std_s": tau_std, "interval_95_share": share, "to_narrow": to_narrow,
            "explained": explained, "force_rms_N": force_rms,
            "kept": not reason, "reason": reason, "determined": not cases, "moves": moves, "effect_std": joint_std}


def floor_left_by(data: FlightData, cand: Candidate) -> dict:
    """:func:`discovery.noise.noise_floor` on what ``cand``'s effects leave."""
    problem = cand.problem
    return noise_floor(data, None if problem is None else lambda s: problem.steps(cand.fit.theta, s))


def _scored_on(fitter: Fitter, cand: Candidate, rows: list[np.ndarray]) -> tuple[float, float]:
    """``cand``'s score and held-out mean squared residual (N^2) on the fit rows ``rows`` (a mask per segment)."""
    held_out = np.concatenate([r[keep] for r, keep in zip(cand.cv_residual, rows)])
    axes = np.mean(held_out**2, axis=0)
    assert cand.problem is not None
    held = cand.fit.held if cand.fit.held is not None else np.zeros(cand.fit.theta.size, dtype=bool)
    return fitter.scorer(axes, cand.problem.layout, held), float(axes.sum())


#: a chosen parameter that changes by more than this share (and two of its standard errors) when the lag is
#: added depends on it (the acceptance figures ask parameters within 10 %)
MOVE_SHARE = 0.05


def _moves(current: Candidate, with_lag: Candidate) -> dict | None:
    """The chosen effects' parameter entry that the lag moves most, if one moves by more than
    :data:`MOVE_SHARE` of its value and two standard errors: ``{"effect", "parameter", "without", "with"}``."""
    # the chosen effects come first in the lag's fit, packed alike
    layout = current.fit.layout
    labels = [] if layout is None else [(layout.templates[layout.effect_of(i)].name, label.split(".", 1)[1])
                                        for i, label in enumerate(layout.labels())]
    without, errors = current.fit.theta, current.fit.param_std
    with_ = with_lag.fit.theta[:without.size]
    best, largest = None, MOVE_SHARE
    for (name, label), x, y, error in zip(labels, without, with_, errors):
        share = abs(y - x) / abs(x) if x != 0 else 0.0
        if share > largest and abs(y - x) > 2 * error:
            best, largest = {"effect": name, "parameter": label, "without": float(x), "with": float(y)}, share
    return best


def _refine_forms(fitter: Fitter, current: Candidate) -> tuple[Candidate, dict[str, str]]:
    """Each chosen effect in the form that scores best next to all the others.

    A round of forward selection weighs an effect's forms against the model of that round
    only, and another effect found later can change which form the data favour: under a
    ceiling with a thrust error, a steady force chosen first absorbs the thrust error's share
    and the plain ceiling form wins its round, while next to the thrust scale chosen later the
    form with the distance offset lowers the held-out force gap by a further 29 %. So, once
    the effects are chosen, each one's other forms (plain or fuller) are tried in its place and
    the best-scoring swap is made while one lowers the score (a fuller form only with its extra
    parameters determined); every swap lowers the score, so this ends. Returns the model and
    the form each swapped effect was chosen in (by its new key).
    """
    swaps: dict[str, str] = {}
    while True:
        best = current
        for key in current.names:
            for form in (k for k in fitter.templates if effect_name(k) == effect_name(key) and k != key):
                names = [form if k == key else k for k in current.names]
                previous = {k: v for k, v in current.previous().items() if k != key}
                cand = fitter.candidate(names, previous=previous)
                if cand.score < best.score and _form_determined(cand, form):
                    best, swap = cand, (key, form)
        if best is current:
            return current, swaps
        swaps[swap[1]] = swaps.pop(swap[0], swap[0])
        current = best


def _form_limits(fitter: Fitter, current: Candidate) -> list[dict]:
    """Why each chosen effect kept its plain form where the literature has a fuller one (the ground and
    ceiling effects' distance offset, wall suction scaled by rotor thrust), with the manoeuvre that
    would tell them apart, as
    ``{"effects", "reason", "manoeuvre"}`` like :func:`discovery.coverage.flight_limits`.

    The plain form is kept when the fuller one does not pay for its extra parameters or leaves
    them undetermined; the plain form's parameters then describe the flown range only, and the
    user learns that the literature's form was tried and what its extra parameters came to."""
    from discovery.determination import determining_manoeuvre, undetermined_cases

    out = []
    for key in current.names:
        for form in (k for k in fitter.templates if "[" in k and effect_name(k) == key):
            effect = fitter.templates[form]
            extra = _extra_parameters(effect)
            options = _switched_options(effect)
            names = [form if k == key else k for k in current.names]
            fuller = fitter.candidate(names, previous={k: v for k, v in current.previous().items() if k != key})
            index = names.index(form)
            fitted, std = fuller.fit.effects[index], fuller.fit.std_dicts()[index]
            open_ = {c["name"] for c in undetermined_cases([fitted], [std])}
            gain = (current.mse - fuller.mse) / current.mse if current.mse > 0 else 0.0
            lowers = (f"lowers the held-out force gap left by the plain form by only {100 * gain:.2g} %" if gain > 0
                      else "does not lower the held-out force gap left by the plain form")
            if not extra:  # an option of the same parameters (wall suction scaled by rotor thrust)
                out.append({"effects": [form], "reason": f"the form with {' and '.join(options)} was fitted but it "
                                                         f"{lowers}, less than a parameter must; the plain form is kept",
                            "manoeuvre": determining_manoeuvre(key, options[0])})
                continue
            values = ", ".join(f"{p.name} = {float(np.ravel(fitted.values[p.name])[0]):.3g} +- "
                               f"{float(np.ravel(std[p.name])[0]):.2g} {p.unit}" for p in extra)
            if open_ & {p.name for p in extra}:
                why = "the flight does not determine its extra parameter"
            else:
                why = f"it {lowers}, which does not pay for its extra parameter"
            out.append({"effects": [form], "reason": f"the fuller form was fitted ({values}) but {why}; the plain form "
                                                     "is kept and its parameters describe the flown distances only",
                        "manoeuvre": determining_manoeuvre(key, extra[0].name)})
    return out


def _drag_in_wind(fitter: Fitter, current: Candidate, template: Effect, progress) -> Candidate:
    """Quadratic drag on the air-relative velocity with a fitted wind (each flight's own), in place of any chosen
    subset of :data:`WIND_REPLACES`, where it scores better and its wind is determined."""
    replaceable = [k for k in current.names if k in WIND_REPLACES]
    if not replaceable:
        return current
    key = variant_key("quadratic_drag", {"wind": True})
    fitter.add(key, make_candidate("quadratic_drag", **{**template.option_values, "wind": True}))
    best = current
    for size in range(1, len(replaceable) + 1):
        for dropped in _subsets(replaceable, size):
            if "quadratic_drag" in current.names and "quadratic_drag" not in dropped:
                continue  # one form of an effect at a time
            names = [k for k in current.names if k not in dropped] + [key]
            if progress is not None:
                progress(f"trying {' + '.join(names)}")
            previous = {k: v for k, v in current.previous().items() if k in names}
            if "quadratic_drag" in dropped:
                previous[key] = np.concatenate([current.previous()["quadratic_drag"], np.zeros(3)])
            # a term with several starts (a wall suction) is also started from its default: beside what the wind
            # replaces it may have stood in for that wind (a suction reaching 0.3 m out, one flight's own wind
            # pushing as it does), a false minimum the joint fit would stay in
            restart = {k: fitter.templates[k].param_vector() if fitter.templates[k].name in STARTS else v
                       for k, v in previous.items()}
            cand = fitter.candidate(names, previous=previous,
                                    restart=restart if any(fitter.templates[k].name in STARTS for k in previous)
                                    else None)
            if cand.score < best.score and _form_determined(cand, key):
                best = cand
    return best


def _subsets(items: list[str], size: int) -> list[tuple[str, ...]]:
    from itertools import combinations

    return list(combinations(items, size))


def _form_determined(candidate: Candidate, key: str) -> bool:
    """A fuller form counts only if, on some flight, some entry of its extra parameters is determined (else the
    plain form says as much) and, where its main parameter is a vector, some entry of that (else every entry is
    nulled afterwards and nothing of it is written: a drag in wind whose coefficients are all undetermined, its wind
    at a bound, is only ``C w^2`` standing in for a steady force, and leaving it out afterwards left no effect at
    all). A single main parameter is not asked: an affine thrust map's scale may sit at 1 with its offset all of it.
    Undetermined entries (a wind's vertical component, a flight in near-still air) are nulled later."""
    if "[" not in key:
        return True
    from discovery.determination import undetermined_cases

    index = candidate.names.index(key)
    extra = _extra_parameters(candidate.fit.effects[index])
    main = candidate.fit.effects[index].parameters[0]
    layout = candidate.fit.layout
    extra_seen = not extra  # an option without parameters of its own (priced as one by the score)
    main_seen = main.size == 1
    for flight in range(layout.n_flights if layout is not None else 1):
        effect = layout.effects(candidate.fit.theta, flight)[index] if layout is not None \
            else candidate.fit.effects[index]
        cases = undetermined_cases([effect], [candidate.fit.std_dicts(flight)[index]])
        extra_seen = extra_seen or \
            sum(1 for c in cases if c["name"] in {p.name for p in extra}) < sum(p.size for p in extra)
        main_seen = main_seen or sum(1 for c in cases if c["name"] == main.name) < main.size
        if extra_seen and main_seen:
            return True
    return False


def _backward(fitter: Fitter, current: Candidate, material) -> tuple[Candidate, list[str]]:
    """Drop what does not pay for itself next to the others, or no longer explains a material share."""
    removed = []
    changed = True
    while changed and current.names:
        changed = False
        for name in list(current.names):
            reduced_names = [n for n in current.names if n != name]
            reduced = fitter.candidate(reduced_names, previous=current.previous())
            if reduced.score <= current.score or not material(current, reduced):
                current = reduced
                removed.append(name)
                changed = True
                break
    return current, removed


def sequential_explained(fitter: Fitter, chosen: Candidate, nominal: Candidate,
                         hold: dict[str, dict[int, float]] | None = None) -> dict[str, float]:
    """Share of the nominal held-out residual energy each effect of ``chosen`` explains, in the order of addition
    (``hold``: entries held at a value, by key); keyed by effect name."""
    out = {}
    previous = nominal
    for i, name in enumerate(chosen.names):
        step = fitter.candidate(chosen.names[: i + 1], previous=chosen.previous(), hold=hold)
        out[effect_name(name)] = (previous.mse - step.mse) / nominal.mse if nominal.mse > 0 else 0.0
        previous = step
    return out


def fit_only(data: FlightData, r_nom: list[np.ndarray], effect: Effect) -> Selection:
    """The paper's identification (Sec. 3.4): fit one named effect, without asking whether it pays."""
    if not applicable(effect, data):
        raise ValueError(f"{effect.name} has nothing to act against in these logs' scenes")
    fitter = make_fitter(data, r_nom, {effect.name: effect})
    nominal = fitter.candidate([])
    chosen = fitter.candidate([effect.name])
    step = Step([{"name": effect.name, "cv_mse_N2": chosen.mse, "gain": 1.0 - chosen.mse / nominal.mse,
                  "score": chosen.score, "params": chosen.fit.effects[0].params_dict()}], effect.name,
                nominal.mse, chosen.mse)
    explained = {effect.name: (nominal.mse - chosen.mse) / nominal.mse if nominal.mse > 0 else 0.0}
    return Selection(chosen, nominal, [step], [], explained, data.effective_samples(), fitter=fitter)
