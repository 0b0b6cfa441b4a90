"""Which effects to add: greedy forward selection on held-out data with a parsimony criterion.

Every candidate is judged by its cross-validated residual: the log is cut into time
blocks dealt round robin to folds, each fold is predicted by parameters fitted on the
others (:meth:`discovery.fitting.EffectFit.cross_validate`), and the held-out mean
squared force residual per world axis ``MSE_a`` is what a model scores. The score is a
Gaussian log-likelihood with its own variance per axis (the noise is far from equal:
thrust noise lives along body z) plus a price per parameter::

    score(M) = sum_a N_a ln(MSE_a(M)) + c p(M),      c = max(chi2_1(1 - alpha), ln N)

where ``p(M)`` counts parameters, ``N_a`` is the number of independent residual values
on axis ``a`` (samples divided by the smoothing kernel's correlation length
``1 / sum(w^2)``), ``N = sum_a N_a``, and ``alpha = 1e-4``: a parameter has to raise the
held-out likelihood as much as a 3.9-sigma detection would (``c = 15.1``), or by the
BIC's ``ln N`` on very long logs. This matters: the mean of the simulator's thrust
noise over a 30 s flight is itself a constant force of a few millinewtons that
cross-validation confirms; only a price calibrated to the noise keeps it from being
named.

Forward selection adds, one at a time, the candidate that lowers the score most (all
parameters of the model refitted jointly, so two effects present together are both
found), and stops when no candidate lowers it. A backward pass then drops any effect
whose removal does not raise the score, so nothing stays that does not pay for itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import chi2

from discovery.fitting import EffectFit, FitResult, applicable
from discovery.residuals import FlightData
from wall_env.effects import Effect

__all__ = ["ALPHA", "Candidate", "Step", "Selection", "effective_samples", "parameter_price", "score",
           "forward_selection", "fit_only"]

ALPHA = 1e-4  # significance a parameter must reach on held-out data


def effective_samples(data: FlightData) -> float:
    """Independent residual values per axis: ``sum over segments of n sum(w^2)``, ``w`` the kernel's step weights."""
    total = 0.0
    for seg in data.segments:
        weights = seg.kernel.interior["step"] if seg.kernel.uniform else seg.kernel.edge["step"][seg.n // 2]
        total += seg.n * float(np.sum(weights**2))
    return max(total, 1.0)


def parameter_price(n_eff_per_axis: float, alpha: float = ALPHA) -> float:
    """``max(chi2_1 quantile at 1 - alpha, ln N)``: what each parameter must buy in ``2 x`` log-likelihood."""
    return max(float(chi2.ppf(1.0 - alpha, 1)), math.log(3.0 * n_eff_per_axis))


def score(mse_axes: np.ndarray, n_params: int, n_eff_per_axis: float, alpha: float = ALPHA) -> float:
    """``sum_a N_a ln(MSE_a) + c p``: lower is better."""
    mse_axes = np.maximum(np.asarray(mse_axes, dtype=float), 1e-300)
    return float(n_eff_per_axis * np.sum(np.log(mse_axes))) + parameter_price(n_eff_per_axis, alpha) * n_params


@dataclass
class Candidate:
    """One effect set tried: its full-data fit, held-out residual and score."""

    names: list[str]
    fit: FitResult
    cv_residual: list[np.ndarray]
    mse: float  # held-out mean squared residual (vector norm), N^2
    mse_axes: np.ndarray  # per world axis, N^2
    score: float

    @property
    def n_params(self) -> int:
        return int(self.fit.theta.size)


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


def _mse_axes(parts: list[np.ndarray]) -> np.ndarray:
    return np.mean(np.concatenate(parts) ** 2, axis=0)


class _Evaluator:
    """Fits effect sets and caches them by name."""

    def __init__(self, data: FlightData, r_nom: list[np.ndarray], templates: dict[str, Effect], n_eff: float):
        self.data = data
        self.r_nom = r_nom
        self.templates = templates
        self.n_eff = n_eff
        self.terms: dict = {}
        self.cache: dict[tuple[str, ...], Candidate] = {}

    def evaluate(self, names: list[str], previous: dict[str, np.ndarray] | None = None) -> Candidate:
        key = tuple(names)
        if key not in self.cache:
            problem = EffectFit(self.data, [self.templates[n] for n in names], self.r_nom, self.terms)
            fit = problem.fit(previous=previous)
            cv, _ = problem.cross_validate(fit)
            axes = _mse_axes(cv)
            self.cache[key] = Candidate(list(names), fit, cv, float(axes.sum()), axes,
                                        score(axes, int(fit.theta.size), self.n_eff))
        return self.cache[key]


def _params_by_name(candidate: Candidate) -> dict[str, np.ndarray]:
    return {e.name: e.param_vector() for e in candidate.fit.effects}


def forward_selection(data: FlightData, r_nom: list[np.ndarray], candidates: list[Effect], max_effects: int = 3,
                      progress=None) -> Selection:
    """Greedy forward selection (then a backward check) over ``candidates``; see the module docstring."""
    templates = {e.name: e for e in candidates if applicable(e, data)}
    n_eff = effective_samples(data)
    evaluator = _Evaluator(data, r_nom, templates, n_eff)
    nominal = evaluator.evaluate([])
    current = nominal
    steps: list[Step] = []
    while len(current.names) < max_effects:
        remaining = [n for n in templates if n not in current.names]
        if not remaining:
            break
        tried: list[dict[str, Any]] = []
        best = None
        for name in remaining:
            if progress is not None:
                progress(f"trying {' + '.join(current.names + [name])}")
            cand = evaluator.evaluate(current.names + [name], previous=_params_by_name(current))
            gain = 1.0 - cand.mse / current.mse if current.mse > 0 else 0.0
            tried.append({"name": name, "cv_mse_N2": cand.mse, "gain": gain, "score": cand.score,
                          "params": cand.fit.effects[-1].params_dict()})
            if best is None or cand.score < best.score:
                best = cand
        tried.sort(key=lambda r: r["score"])
        if best is None or best.score >= current.score:
            steps.append(Step(tried, None, current.mse, current.mse))
            break
        steps.append(Step(tried, best.names[-1], current.mse, best.mse))
        current = best
    # backward check: drop what does not pay for itself next to the others
    removed = []
    changed = True
    while changed and len(current.names) > 1:
        changed = False
        for name in list(current.names):
            reduced_names = [n for n in current.names if n != name]
            reduced = evaluator.evaluate(reduced_names, previous=_params_by_name(current))
            if reduced.score <= current.score:
                current = reduced
                removed.append(name)
                changed = True
                break
    explained = _sequential_explained(evaluator, current, nominal)
    return Selection(current, nominal, steps, removed, explained, n_eff)


def _sequential_explained(evaluator: _Evaluator, chosen: Candidate, nominal: Candidate) -> dict[str, float]:
    """Share of the nominal held-out residual energy each effect explains, in the order of addition."""
    out = {}
    previous = nominal
    for i, name in enumerate(chosen.names):
        step = evaluator.evaluate(chosen.names[: i + 1], previous=_params_by_name(chosen))
        out[name] = (previous.mse - step.mse) / nominal.mse if nominal.mse > 0 else 0.0
        previous = step
    return out


def fit_only(data: FlightData, r_nom: list[np.ndarray], effect: Effect) -> Selection:
    """The paper's identification (Sec. 3.4): fit one named effect, without asking whether it pays."""
    if not applicable(effect, data):
        raise ValueError(f"{effect.name} has nothing to act against in these logs' scenes")
    evaluator = _Evaluator(data, r_nom, {effect.name: effect}, effective_samples(data))
    nominal = evaluator.evaluate([])
    chosen = evaluator.evaluate([effect.name])
    step = Step([{"name": effect.name, "cv_mse_N2": chosen.mse, "gain": 1.0 - chosen.mse / nominal.mse,
                  "score": chosen.score, "params": chosen.fit.effects[0].params_dict()}], effect.name,
                nominal.mse, chosen.mse)
    explained = {effect.name: (nominal.mse - chosen.mse) / nominal.mse if nominal.mse > 0 else 0.0}
    return Selection(chosen, nominal, [step], [], explained, evaluator.n_eff)
