"""Fitting effects to force residuals: nonlinear least squares with the library's own Jacobians.

Given the nominal residual ``r_nom`` (:mod:`discovery.residuals`) and a set of effects,
:class:`EffectFit` finds the parameters that minimise ``sum_k |r_nom,k - sum_i K[F_i(theta_i)]_k|^2``
with :func:`scipy.optimize.least_squares` (trust-region reflective, within each
parameter's range), the Jacobian being CasADi's derivative of the same effect
definition the simulator uses (:class:`~discovery.aero_eval.ForceEvaluator`). The packed
vector ``theta`` is laid out by a :class:`~discovery.layout.ParameterLayout`: across
several flights each flight has its own wind while the rest is shared, and entries can be
held at a value (an undetermined entry nulled, a nuisance parameter a fold holds).

Relation to the paper (Sec. 3.4): for ``wall_suction`` the Jacobian is CasADi's exact
derivative of the per-rotor model (Eq. 10). It equals Eq. 29 for ``k_s``; for ``d_thr``
it sums ``k_s`` over the rotors inside the threshold only, where Eq. 30 writes
``4 k_s`` as if all four rotors were. The paper solves with Levenberg-Marquardt; SciPy's
trust-region reflective method used here is the same kind of damped Gauss-Newton
step, kept inside each parameter's range from the library.

Speed without shortcuts in the model:

- an effect whose force is affine in its parameters (drag, constant force, thrust
  scale; checked numerically on the data, never assumed from its name) is evaluated
  once; its residual at any parameter value is then exact linear algebra;
- nonlinear effects (wall suction's threshold, ground and ceiling radius) are fitted
  from a few starting points (:data:`STARTS`) and the best solution kept.

Fits and cross-validation use every ``window / 10``-th residual row
(:attr:`~discovery.residuals.Segment.fit_rows`; rows a tenth of the smoothing window
apart carry nearly the same information); :meth:`EffectFit.out_of_fold` gives the
held-out residual of a result at every sample for the reported figures.
Standard errors are Newey-West's sandwich at the solution (:meth:`EffectFit._standard_errors`):
each axis keeps its own noise level, and residual rows are correlated over the smoothing
window, or longer where what the fit leaves is still correlated beyond it (:func:`influence_lags`).

:class:`Fitter` owns every fit of one run: the effects' terms (evaluated once per
parameter value and shared by every set they appear in) and each candidate set's fit,
held-out residual and score, so that no effect set is fitted twice.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from discovery.layout import ParameterLayout
from discovery.residuals import FlightData
from discovery.terms import EffectTerm, Term
from wall_env.effects import Effect, make_effect

__all__ = ["CV_TOL", "STARTS", "EffectFit", "FitResult", "Candidate", "Fitter", "applicable",
           "term_key", "hac_lags", "influence_lags", "long_run_variance", "SLOW_CORRELATION_SIGMAS"]

# Starting points for effects whose force is not affine in their parameters (plausible
# physical values; the fit is bounded by each parameter's range from the library).
STARTS: dict[str, list[dict[str, Any]]] = {
    "wall_suction": [{"k_s": 5.0, "d_thr": d} for d in (0.06, 0.1, 0.15, 0.22, 0.32)],
    "ground_effect": [{"radius": r} for r in (0.03, 0.06, 0.12, 0.24)],
    "ceiling_effect": [{"radius": r} for r in (0.03, 0.06, 0.12, 0.24)],
}


#: tolerance of the cross-validation refits: they start from the full fit, and a held-out score needs
#: the refit's cost to a millionth (scores move in the third decimal against a parameter price of ~10),
#: not to 1e-10; this saves a sixth of discovery's force evaluations
CV_TOL = 1e-6


def term_key(effect: Effect) -> tuple:
    """The key of ``effect``'s term in a cache shared by fits: its name and options (forms of one effect differ)."""
    return (effect.name, tuple(sorted(effect.option_values.items())))


def applicable(effect: Effect, data: FlightData) -> bool:
    """Whether any segment's scene has what ``effect`` acts against."""
    return any(effect.applies_to(seg.scene.structure) for seg in data.segments)


def hac_lags(segment) -> int:
    """Lags (in fit rows) of the Newey-West sum: :meth:`~discovery.residuals.Segment.hac_lags`."""
    return segment.hac_lags()


#: an entry's influence counts as still correlated one lag window apart (a turbulent wind, a gust: a force the
#: effects leave that lasts seconds) when its correlation there is this many times what white residuals would show
SLOW_CORRELATION_SIGMAS = 3.0


def influence_lags(influence: list[np.ndarray], windows: list[int]) -> list[np.ndarray]:
    """Newey-West lags (fit rows, ``(entries,)`` per segment) for the influence of each fitted entry on each row
    (``(rows, entries)`` per segment); ``windows``: each segment's :meth:`~discovery.residuals.Segment.hac_lags`.

    An entry whose influence one window apart is correlated beyond :data:`SLOW_CORRELATION_SIGMAS` times its
    standard error on white residuals (``1 / sqrt(rows / window)``, pooled over the segments) gets Andrews' (1991)
    AR(1) plug-in bandwidth for the Bartlett kernel, ``1.1447 (alpha T)^(1/3)`` with
    ``alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)``, ``rho`` the correlation per row that decays to the one
    measured a window apart, and ``T`` the segment's rows; every other entry keeps the window. The smoothing alone
    correlates rows within a window, never beyond, so on what an effect's fit leaves as white noise nothing
    changes, while a 2 s turbulent wind left in the residual of a 50 Hz log (its correlation a window apart
    about 0.7) is summed over about 7 s.
    """
    size = influence[0].shape[1]
    near, total, independent = np.zeros(size), np.zeros(size), 0.0
    for u, window in zip(influence, windows):
        if len(u) > window:
            near += np.sum(u[window:] * u[:-window], axis=0)
        total += np.sum(u * u, axis=0)
        independent += len(u) / window
    rho = np.divide(near, total, out=np.zeros(size), where=total > 0)
    slow = rho > SLOW_CORRELATION_SIGMAS / np.sqrt(max(independent, 1.0))
    out = []
    for u, window in zip(influence, windows):
        lags = np.full(size, float(window))
        if slow.any():
            per_row = np.clip(rho[slow], 0.0, 0.999) ** (1.0 / window)
            alpha = 4.0 * per_row**2 / ((1.0 - per_row) ** 2 * (1.0 + per_row) ** 2)
            lags[slow] = np.clip(1.1447 * (alpha * len(u)) ** (1.0 / 3.0), window, max(len(u) - 1, window))
        out.append(np.floor(lags))
    return out


def long_run_variance(influence: list[np.ndarray], lags: list[np.ndarray]) -> np.ndarray:
    """Variance of each column's sum over all rows (``(rows, entries)`` per segment, segments independent): the
    Newey-West sum within each segment, with Bartlett weights ``1 - l / (L + 1)`` up to each entry's ``L`` of
    ``lags`` (:func:`influence_lags`)."""
    variance = np.zeros(influence[0].shape[1])
    for u, seg_lags in zip(influence, lags):
        variance += np.sum(u * u, axis=0)
        for lag in range(1, min(int(seg_lags.max()), len(u) - 1) + 1):
            weight = np.where(lag <= seg_lags, 1.0 - lag / (seg_lags + 1.0), 0.0)
            variance += 2.0 * weight * np.sum(u[lag:] * u[:-lag], axis=0)
    return variance


def make_term(data: FlightData, effect: Effect) -> Term:
    """The term that evaluates ``effect`` on ``data``: discovery's own candidates (a motor lag, an affine thrust
    map, a residual's structure, a wall that ends) build theirs (``effect.fitting_term(data)``); a library effect
    is evaluated through its CasADi function (:class:`~discovery.terms.EffectTerm`)."""
    own = getattr(effect, "fitting_term", None)
    return own(data) if own is not None else EffectTerm(data, effect)


@dataclass
class FitResult:
    """Fitted effects and what the fit says about them."""

    effects: list[Effect]  # with fitted parameters (the first flight's conditions)
    theta: np.ndarray  # all parameters, packed by ``layout``
    param_std: np.ndarray  # standard errors, same packing (NaN where held)
    cost: float  # 0.5 * sum of squared residuals on the fitted samples
    n_rows: int  # residual rows (3 per sample)
    success: bool
    message: str = ""
    fold_theta: list[np.ndarray] = field(default_factory=list)  # per cross-validation fold
    layout: ParameterLayout | None = None
    held: np.ndarray | None = None  # (size,) bool: entries held at their value, not fitted

    def param_dicts(self) -> list[dict[str, Any]]:
        return [e.params_dict() for e in self.effects]

    def std_dicts(self, flight: int = 0) -> list[dict[str, Any]]:
        """Standard errors as each effect's named parameters (``flight``'s own entries for its conditions)."""
        if self.layout is None:
            return []
        return self.layout.dicts(self.param_std, flight)

    def flight_effects(self, flight: int) -> list[Effect]:
        """The effects with ``flight``'s conditions (its own wind)."""
        return self.effects if self.layout is None else self.layout.effects(self.theta, flight)


class EffectFit:
    """Least-squares fit of a set of effects to the nominal force residual.

    ``EffectFit(data, [make_effect("wall_suction"), ...], nominal_residual)``, then
    :meth:`fit` (all data or per-segment masks over the fit rows), :meth:`residuals` at
    any parameters and :meth:`cross_validate`. Everything here works on each segment's
    :attr:`~discovery.residuals.Segment.fit_rows`; :meth:`out_of_fold` evaluates a result on
    every sample. ``keys`` name the effects (candidate keys; default their names) and
    ``terms`` is a term cache shared between fits (see :class:`Fitter`). ``exclude`` (per segment, over the fit
    rows) marks rows no fit uses, as where an effect's form is not trusted; they are still held out and scored.
    """

    def __init__(self, data: FlightData, effects: list[Effect], nominal_residual: list[np.ndarray],
                 terms: dict[Any, Term] | None = None, keys: list[str] | None = None,
                 exclude: list[np.ndarray] | None = None):
        self.data = data
        self.templates = list(effects)
        self.layout = ParameterLayout(keys or [e.name for e in effects], self.templates, data.n_flights)
        self.rows = [seg.fit_rows for seg in data.segments]
        self.r_nom = [r[rows] for r, rows in zip(nominal_residual, self.rows)]
        self.folds = [seg.fold[rows] for seg, rows in zip(data.segments, self.rows)]
        self.usable = [np.ones(len(rows), dtype=bool) for rows in self.rows] if exclude is None \
            else [~np.asarray(x, dtype=bool) for x in exclude]
        cache = terms if terms is not None else {}
        self.terms: list[Term] = []
        for effect in effects:
            key = term_key(effect)
            if key not in cache:
                cache[key] = make_term(data, effect)
            self.terms.append(cache[key])
        self.low, self.high = self.layout.low, self.layout.high

    @property
    def size(self) -> int:
        return self.layout.size

    # ------------------------------------------------------------------ residuals
    def _parts(self, theta: np.ndarray, s: int) -> list[tuple[np.ndarray, np.ndarray]]:
        flight = self.data.segments[s].flight
        return [term.at_rows(s, th) for term, th in zip(self.terms, self.layout.split(theta, flight))]

    def residuals(self, theta: np.ndarray) -> list[np.ndarray]:
        """Residual per segment ``(m, 3)`` at the fit rows with all effects at ``theta``."""
        theta = np.asarray(theta, dtype=float)
        out = []
        for s, r in enumerate(self.r_nom):
            r = r.copy()
            for force, _ in self._parts(theta, s):
                r -= force
            out.append(r)
        return out

    def _jacobians(self, theta: np.ndarray) -> list[np.ndarray]:
        """Jacobian of the residual ``(m, 3, size)`` per segment at the fit rows."""
        out = []
        for s, rows in enumerate(self.rows):
            flight = self.data.segments[s].flight
            jac = np.zeros((len(rows), 3, self.size))
            for e, (_, j) in enumerate(self._parts(theta, s)):
                jac[:, :, self.layout.index[e][flight]] -= j
            out.append(jac)
        return out

    def informed(self, theta: np.ndarray, masks: list[np.ndarray]) -> np.ndarray:
        """Mask of the packed entries that move the residual at the fit rows selected by ``masks`` (per segment):
        a column of the Jacobian there that is not zero. An entry no selected row depends on (a wall's suction on
        flights without a wall) is not determined by those rows at all."""
        informed = np.zeros(self.size, dtype=bool)
        for jac, mask in zip(self._jacobians(theta), masks):
            informed |= np.any(jac[mask] != 0.0, axis=(0, 1))
        return informed

    def _stacked(self, theta: np.ndarray, masks: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        residual = self.residuals(theta)
        jacobians = self._jacobians(theta)
        rows_r = [r[mask].reshape(-1) for r, mask in zip(residual, masks)]
        rows_j = [j[mask].reshape(-1, j.shape[2]) for j, mask in zip(jacobians, masks)]
        return np.concatenate(rows_r), np.concatenate(rows_j, axis=0)

    # ------------------------------------------------------------------ fitting
    def _solve(self, theta0: np.ndarray, masks: list[np.ndarray], tol: float = 1e-10,
               free: np.ndarray | None = None) -> Any:
        """:func:`~scipy.optimize.least_squares` from ``theta0``; only the ``free`` entries move (all if None).

        The result's ``x`` is the full parameter vector."""
        free = np.ones(theta0.size, dtype=bool) if free is None else free
        cache: dict[str, Any] = {}
        x0 = np.clip(theta0, self.low, self.high)
        if not free.any():
            r, j = self._stacked(x0, masks)
            return _Solution(x0, r, np.zeros((r.size, 0)))

        def both(x_free):
            key = x_free.tobytes()
            if cache.get("key") != key:
                theta = x0.copy()
                theta[free] = x_free
                r, j = self._stacked(theta, masks)
                cache["key"], cache["value"] = key, (r, j[:, free])
            return cache["value"]

        low, high = self.low[free], self.high[free]
        # least_squares needs strictly feasible starts inside the bounds
        inside = np.clip(x0[free], low + 1e-9 * (1 + np.abs(low)), high - 1e-9 * (1 + np.abs(high)))
        result = least_squares(lambda x: both(x)[0], inside, jac=lambda x: both(x)[1], bounds=(low, high),
                               method="trf", x_scale="jac", xtol=tol, ftol=tol, gtol=tol, max_nfev=200)
        theta = x0.copy()
        theta[free] = result.x
        result.x = theta
        return result

    def starts(self, previous: dict[str, np.ndarray] | None = None,
               base: np.ndarray | None = None) -> list[np.ndarray]:
        """Starting points: previous values (by key) where known, else the effect's default or :data:`STARTS`."""
        per_term: list[list[np.ndarray]] = []
        for key, term, template in zip(self.layout.keys, self.terms, self.templates):
            if previous and key in previous:
                per_term.append([np.asarray(previous[key], dtype=float)])
            elif term.affine or template.name not in STARTS:
                per_term.append([template.param_vector()])
            else:
                options = []
                for values in STARTS[template.name]:
                    options.append(make_effect(template.name, **values, **template.option_values).param_vector())
                per_term.append(options)
        # one start per option of the term with most options; the others keep their first
        n = max((len(o) for o in per_term), default=1)
        out = []
        for i in range(n):
            vectors = {key: o[min(i, len(o) - 1)] for key, o in zip(self.layout.keys, per_term)}
            out.append(self.layout.pack(vectors, base))
        return out

    def fit(self, masks: list[np.ndarray] | None = None, previous: dict[str, np.ndarray] | None = None,
            theta0: np.ndarray | None = None, held: np.ndarray | None = None,
            restart: dict[str, np.ndarray] | None = None) -> FitResult:
        """Fit on the fit rows selected by ``masks`` (all if None), from several starts (those of ``previous``,
        and of ``restart`` too when given); the entries ``held`` (a mask over the packed vector) keep their value
        in ``theta0`` or the start."""
        masks = [m & u for m, u in zip(masks, self.usable)] if masks else self.usable
        if not self.terms:  # nothing to fit: the nominal model
            rows = np.concatenate([r[m].reshape(-1) for r, m in zip(self.r_nom, masks)])
            return FitResult([], np.zeros(0), np.zeros(0), 0.5 * float(rows @ rows), rows.size, True, "no parameters",
                             layout=self.layout, held=np.zeros(0, dtype=bool))
        held = np.zeros(self.size, dtype=bool) if held is None else np.asarray(held, dtype=bool)
        starts = [theta0] if theta0 is not None else self.starts(previous) + (self.starts(restart) if restart else [])
        best = None
        for x0 in starts:
            result = self._solve(np.asarray(x0, dtype=float), masks, free=~held)
            if best is None or result.cost < best.cost:
                best = result
        assert best is not None  # starts is never empty
        theta = best.x
        std = np.full(self.size, np.nan)  # an entry held at a value has no standard error
        std[~held] = self._standard_errors(theta, masks, ~held)
        effects = self.layout.effects(theta, 0)
        return FitResult(effects, theta, std, float(best.cost), int(best.fun.size), bool(best.success),
                         str(best.message), layout=self.layout, held=held)

    def _standard_errors(self, theta: np.ndarray, masks: list[np.ndarray], free: np.ndarray) -> np.ndarray:
        """Heteroscedasticity- and autocorrelation-consistent (Newey-West) standard errors of the ``free`` entries.

        ``cov = A^-1 B A^-1`` with ``A = J^T J`` and ``B`` the long-run covariance of the
        per-row scores ``g_k = J_k^T r_k`` (all three axes of a row together). An entry's variance is the long-run
        variance of its influence ``u_k = (A^-1 g_k)_i``, summed with Bartlett weights within each segment over
        :func:`influence_lags`: two smoothing windows (:meth:`~discovery.residuals.Segment.hac_lags`), or longer
        where what the fit leaves is still correlated beyond them. Unlike ``sigma^2 (J^T J)^-1`` this lets each axis
        have its own noise level (a vertical parameter is not credited with the quieter horizontal axes) and lets
        the noise be correlated over the smoothing window, or over a turbulent wind's seconds.
        """
        p = int(free.sum())
        if p == 0:
            return np.zeros(0)
        residuals, jacobians = self.residuals(theta), self._jacobians(theta)
        a = np.zeros((p, p))
        n = 0
        scores = []
        for r, j, mask in zip(residuals, jacobians, masks):
            j = j[:, :, free]
            rows = j[mask].reshape(-1, p)
            a += rows.T @ rows
            n += rows.shape[0]
            scores.append(np.einsum("ma,map->mp", r * mask[:, None], j))
        a_inv = np.linalg.pinv(a)
        influence = [g @ a_inv for g in scores]  # A^-1 symmetric: each row's pull on each entry
        windows = [seg.hac_lags() for seg in self.data.segments]
        variance = long_run_variance(influence, influence_lags(influence, windows))
        return np.sqrt(np.clip(variance * n / max(n - p, 1), 0.0, None))

    # ------------------------------------------------------------------ cross-validation
    def cross_validate(self, full: FitResult) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Out-of-fold residuals per segment at the fit rows, each fold refitted (from ``full``) without it.

        Returns the out-of-fold residuals and the fold parameter vectors (also stored in ``full.fold_theta``).
        Entries ``full`` held stay held in every fold.
        """
        out = [np.empty_like(r) for r in self.r_nom]
        fold_theta = []
        held_full = full.held if full.held is not None and full.held.size == self.size \
            else np.zeros(self.size, dtype=bool)
        for k in range(self.data.n_folds):
            masks = [seg.train_mask[k][rows] & usable for seg, rows, usable
                     in zip(self.data.segments, self.rows, self.usable)]
            if self.terms and any(m.any() for m in masks):
                # a nuisance parameter that reaches the held-out rows (a lag's start error, its segment's start
                # held out) is not fitted: it takes its default, so no held-out row sees a value fitted to it
                held_rows = [folds == k for folds in self.folds]
                fixed = self._fold_fixed(full.theta, masks, held_rows)
                start = np.where(fixed, self.layout.defaults, full.theta)
                theta_k = self._solve(start, masks, CV_TOL, free=~(fixed | held_full)).x
            else:
                theta_k = full.theta.copy()
            fold_theta.append(theta_k)
            residual = self.residuals(theta_k)
            for s, folds in enumerate(self.folds):
                held = folds == k
                out[s][held] = residual[s][held]
        full.fold_theta = fold_theta
        return out, fold_theta

    def _fold_fixed(self, theta: np.ndarray, train: list[np.ndarray], held: list[np.ndarray]) -> np.ndarray:
        fixed = np.zeros(self.size, dtype=bool)
        for e, term in enumerate(self.terms):
            own = term.fold_fixed(self.layout.split(theta, 0)[e], train, held)
            if own.any():
                fixed[self.layout.index[e][0][own]] = True
        return fixed

    def out_of_fold(self, fold_theta: list[np.ndarray], nominal_residual: list[np.ndarray]) -> list[np.ndarray]:
        """Residual at every sample, each fold's samples against the effects fitted without that fold."""
        out = [r.copy() for r in nominal_residual]
        for s, seg in enumerate(self.data.segments):
            for e, term in enumerate(self.terms):
                rows = self.layout.index[e][seg.flight]
                theta = np.stack([fold_theta[k][rows] for k in seg.fold]) if fold_theta else \
                    self.layout.defaults[rows]
                out[s] -= term.smoothed(s, theta)
        return out

    def steps(self, theta: np.ndarray, segment: int) -> np.ndarray:
        """The effects' summed force over each step of ``segment`` ``(n - 1, 3)``, unsmoothed
        (:meth:`discovery.terms.Term.steps`)."""
        flight = self.data.segments[segment].flight
        parts = self.layout.split(theta, flight)
        return sum((term.steps(segment, parts[e]) for e, term in enumerate(self.terms)),
                   np.zeros((self.data.segments[segment].n - 1, 3)))

    def forces(self, theta: np.ndarray) -> list[list[np.ndarray]]:
        """Each effect's ``K[F]`` ``(n, 3)`` at every sample, per segment: ``out[e][s]``."""
        return [[term.smoothed(s, self.layout.split(theta, seg.flight)[e]) for s, seg in enumerate(self.data.segments)]
                for e, term in enumerate(self.terms)]


@dataclass
class _Solution:
    """What :meth:`EffectFit._solve` returns when nothing is free (the shape of ``least_squares``' result)."""

    x: np.ndarray
    fun: np.ndarray
    jac: np.ndarray
    cost: float = field(init=False)
    success: bool = True
    message: str = "nothing free"

    def __post_init__(self) -> None:
        self.cost = 0.5 * float(self.fun @ self.fun)


@dataclass
class Candidate:
    """One effect set tried: its full-data fit, held-out residual and score."""

    names: list[str]  # candidate keys
    fit: FitResult
    cv_residual: list[np.ndarray]
    mse: float  # held-out mean squared residual (vector norm), N^2
    mse_axes: np.ndarray  # per world axis, N^2
    score: float
    problem: EffectFit | None = field(default=None, repr=False)

    @property
    def n_params(self) -> int:
        return int(self.fit.theta.size) if self.fit.held is None else int((~self.fit.held).sum())

    def previous(self) -> dict[str, np.ndarray]:
        """Fitted parameter vectors by candidate key (the first flight's), as starting values for other sets."""
        return {key: e.param_vector() for key, e in zip(self.names, self.fit.effects)}


#: ``score(mse_axes, layout, held) -> float``, lower is better (see :func:`discovery.selection.score`)
Scorer = Callable[[np.ndarray, ParameterLayout, np.ndarray], float]


class Fitter:
    """Every fit of one run on one prepared data set: the one owner of the term and candidate caches.

    ``Fitter(data, r_nom, templates, scorer)``; :meth:`candidate` fits a set of candidate keys
    (all parameters jointly, from previous values where given), cross-validates it and scores
    it, once per set (and per set of held entries); :meth:`add` registers another template.
    """

    def __init__(self, data: FlightData, r_nom: list[np.ndarray], templates: dict[str, Effect], scorer: Scorer):
        self.data = data
        self.r_nom = r_nom
        self.templates = dict(templates)
        self.scorer = scorer
        self.terms: dict[Any, Term] = {}
        self._fits: dict[tuple, Candidate] = {}

    def add(self, key: str, template: Effect) -> None:
        """Register ``template`` under ``key``; one that replaces another drops the fits and the term made of that
        one (a term is cached by the effect's name and options, which two descriptions of different residuals with
        the same label share: the second had been fitted with the first's basis)."""
        if key in self.templates and self.templates[key] is not template:
            self._fits = {k: v for k, v in self._fits.items() if key not in k[0]}
            self.terms.pop(term_key(self.templates[key]), None)
        self.templates[key] = template

    def problem(self, keys: list[str], exclude: list[np.ndarray] | None = None) -> EffectFit:
        return EffectFit(self.data, [self.templates[k] for k in keys], self.r_nom, self.terms, list(keys), exclude)

    def candidate(self, keys: list[str], previous: dict[str, np.ndarray] | None = None,
                  hold: dict[str, dict[int, float]] | None = None,
                  exclude: list[np.ndarray] | None = None,
                  restart: dict[str, np.ndarray] | None = None) -> Candidate:
        """Fit, cross-validate and score the set ``keys``; ``previous`` holds starting values by key (``restart``,
        other starting values to try too, the first time the set is fitted),
        ``hold`` entries of effects' own vectors to keep at a value (``{key: {entry: value}}``) and ``exclude``
        (per segment, over its fit rows) rows the fits leave out (see :class:`EffectFit`)."""
        hold = {k: v for k, v in (hold or {}).items() if v and k in keys}
        cache_key = (tuple(keys), tuple(sorted((k, tuple(sorted(v.items()))) for k, v in hold.items())),
                     None if exclude is None else b"".join(np.packbits(x).tobytes() for x in exclude))
        if cache_key not in self._fits:
            problem = self.problem(list(keys), exclude)
            start = {k: previous[k] for k in keys if previous and k in previous}
            held_mask = np.zeros(problem.size, dtype=bool)
            theta0 = None
            if hold:
                theta0 = problem.starts(start)[0]
                held_mask = problem.layout.hold(theta0, hold)
            fit = problem.fit(previous=start, theta0=theta0, held=held_mask, restart=restart)
            cv, _ = problem.cross_validate(fit)
            axes = np.mean(np.concatenate(cv) ** 2, axis=0) if cv else np.zeros(3)
            score = self.scorer(axes, problem.layout, fit.held if fit.held is not None else held_mask)
            self._fits[cache_key] = Candidate(list(keys), fit, cv, float(axes.sum()), axes, score, problem)
        return self._fits[cache_key]
