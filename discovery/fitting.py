"""Fitting effects to force residuals: nonlinear least squares with the library's own Jacobians.

Given the nominal residual ``r_nom`` (:mod:`discovery.residuals`) and a set of effects,
:class:`EffectFit` finds the parameters that minimise ``sum_k |r_nom,k - sum_i K[F_i(theta_i)]_k|^2``
with :func:`scipy.optimize.least_squares` (trust-region reflective, within each
parameter's range), the Jacobian being CasADi's derivative of the same effect
definition the simulator uses (:class:`~discovery.aero_eval.ForceEvaluator`).

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
apart carry nearly the same information); :func:`out_of_fold_residuals` gives the
held-out residual of a result at every sample for the reported figures.
Standard errors are Newey-West's sandwich at the solution (:meth:`EffectFit._standard_errors`):
each axis keeps its own noise level, and residual rows are correlated over the smoothing
window.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from discovery.motor_lag import LagTerm, MotorLag
from discovery.residuals import FlightData, Segment
from wall_env.aero import AeroModel
from wall_env.effects import Effect, make_effect

__all__ = ["CV_TOL", "STARTS", "EffectFit", "FitResult", "applicable", "term_key", "hac_lags", "out_of_fold_residuals"]

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


#: smoothing windows of lags over which the standard errors sum the scores' correlation (:func:`hac_lags`)
HAC_WINDOWS = 2.0


def hac_lags(segment: Segment) -> int:
    """Lags (in fit rows) of the Newey-West sum: :data:`HAC_WINDOWS` smoothing windows.

    Rows less than a window apart share smoothed samples, so their residuals are correlated up to
    one window; the sum runs to two for margin (over ten noisy ground-offset logs the rms of
    error / standard error was 0.91 with one window and 0.78 with three).
    """
    rows_per_window = segment.kernel.window / max(1, segment.kernel.window // 10)
    return max(1, int(round(HAC_WINDOWS * rows_per_window)))


@dataclass
class FitResult:
    """Fitted effects and what the fit says about them."""

    effects: list[Effect]  # with fitted parameters
    theta: np.ndarray  # all parameters, packed in effect order
    param_std: np.ndarray  # standard errors, same packing
    cost: float  # 0.5 * sum of squared residuals on the fitted samples
    n_rows: int  # residual rows (3 per sample)
    success: bool
    message: str = ""
    fold_theta: list[np.ndarray] = field(default_factory=list)  # per cross-validation fold

    def param_dicts(self) -> list[dict[str, Any]]:
        return [e.params_dict() for e in self.effects]

    def std_dicts(self) -> list[dict[str, Any]]:
        out, index = [], 0
        for e in self.effects:
            size = e.param_size
            out.append(e.params_dict(self.param_std[index:index + size]))
            index += size
        return out


class _Term:
    """One effect's contribution ``K[F(theta)]`` at every segment's fit rows, with caching."""

    def __init__(self, data: FlightData, effect: Effect):
        self.data = data
        self.effect = effect
        self.model = AeroModel([effect])
        self.size = effect.param_size
        self.low, self.high = effect.param_bounds()
        self._evaluators = [seg.evaluator(self.model, data.rotor_positions_body) for seg in data.segments]
        self._active = [effect.applies_to(seg.scene.structure) for seg in data.segments]
        self._rows = [seg.fit_rows for seg in data.segments]
        self._cache_theta: np.ndarray | None = None
        self._cache: tuple[list[np.ndarray], list[np.ndarray]] | None = None
        self.affine = False
        self._affine_base: list[tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        self._check_affine()

    def _evaluate(self, theta: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        forces, jacobians = [], []
        for seg, ev, active, rows in zip(self.data.segments, self._evaluators, self._active, self._rows):
            if not active:
                forces.append(np.zeros((len(rows), 3)))
                jacobians.append(np.zeros((len(rows), 3, self.size)))
                continue
            f, j = ev.force_and_jacobian(seg.states, theta)
            forces.append(seg.smooth_force(f, rows))
            jacobians.append(seg.smooth_force(j, rows))
        return forces, jacobians

    def _check_affine(self) -> None:
        """An effect is affine if its Jacobian is the same at two distant parameter values."""
        a = np.clip(self.effect.param_vector(), self.low, self.high)
        span = np.where(np.isfinite(self.high - self.low), self.high - self.low, 1.0)
        b = np.clip(a + 0.137 * span + 0.01, self.low, self.high)
        fa, ja = self._evaluate(a)
        fb, jb = self._evaluate(b)
        scale = max(max((np.abs(j).max() if j.size else 0.0) for j in ja), 1e-12)
        same = all(np.allclose(x, y, rtol=1e-9, atol=1e-9 * scale) for x, y in zip(ja, jb))
        if same:
            self.affine = True
            self._affine_base = [(f, j, a) for f, j in zip(fa, ja)]

    def fold_fixed(self, theta: np.ndarray, train: list[np.ndarray], held: list[np.ndarray]) -> np.ndarray:
        """Nuisance parameters a fold must hold at their defaults: an effect has none."""
        return np.zeros(self.size, dtype=bool)

    def evaluate(self, theta: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """``K[F]`` ``(m, 3)`` and its Jacobian ``(m, 3, p)`` per segment at the fit rows."""
        theta = np.asarray(theta, dtype=float)
        if self.affine and self._affine_base is not None:
            forces = [f + j @ (theta - a) for f, j, a in self._affine_base]
            return forces, [j for _, j, _ in self._affine_base]
        if self._cache is not None and self._cache_theta is not None and np.array_equal(theta, self._cache_theta):
            return self._cache
        self._cache = self._evaluate(theta)
        self._cache_theta = theta.copy()
        return self._cache


class EffectFit:
    """Least-squares fit of a set of effects to the nominal force residual.

    ``EffectFit(data, [make_effect("wall_suction"), ...], nominal_residual)``, then
    :meth:`fit` (all data or per-segment masks over the fit rows), :meth:`residuals` at
    any parameters and :meth:`cross_validate`. Everything here works on each segment's
    :attr:`~discovery.residuals.Segment.fit_rows`; :func:`out_of_fold_residuals`
    evaluates a result on every sample.
    """

    def __init__(self, data: FlightData, effects: list[Effect], nominal_residual: list[np.ndarray],
                 terms: dict[Any, _Term | LagTerm] | None = None):
        self.data = data
        self.templates = list(effects)
        self.rows = [seg.fit_rows for seg in data.segments]
        self.r_nom = [r[rows] for r, rows in zip(nominal_residual, self.rows)]
        self.folds = [seg.fold[rows] for seg, rows in zip(data.segments, self.rows)]
        cache = terms if terms is not None else {}
        self.terms: list[_Term | LagTerm] = []
        for effect in effects:
            key = term_key(effect)
            if key not in cache:
                cache[key] = LagTerm(data, effect) if isinstance(effect, MotorLag) else _Term(data, effect)
            self.terms.append(cache[key])
        self.sizes = [t.size for t in self.terms]
        self._defaults = np.concatenate([e.param_vector() for e in effects]) if effects else np.zeros(0)
        self.low = np.concatenate([t.low for t in self.terms]) if self.terms else np.zeros(0)
        self.high = np.concatenate([t.high for t in self.terms]) if self.terms else np.zeros(0)

    # ------------------------------------------------------------------ residuals
    def _split(self, theta: np.ndarray) -> list[np.ndarray]:
        out, index = [], 0
        for size in self.sizes:
            out.append(theta[index:index + size])
            index += size
        return out

    def residuals(self, theta: np.ndarray) -> list[np.ndarray]:
        """Residual per segment ``(m, 3)`` at the fit rows with all effects at ``theta``."""
        out = [r.copy() for r in self.r_nom]
        for term, th in zip(self.terms, self._split(np.asarray(theta, dtype=float))):
            forces, _ = term.evaluate(th)
            for r, f in zip(out, forces):
                r -= f
        return out

    def _jacobians(self, theta: np.ndarray) -> list[np.ndarray]:
        """Jacobian of the residual ``(m, 3, p)`` per segment at the fit rows."""
        parts: list[list[np.ndarray]] = [[] for _ in self.data.segments]
        for term, th in zip(self.terms, self._split(theta)):
            _, jacobians = term.evaluate(th)
            for s, j in enumerate(jacobians):
                parts[s].append(-j)
        return [np.concatenate(p, axis=2) for p in parts]

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

    def starts(self, previous: dict[str, np.ndarray] | None = None) -> list[np.ndarray]:
        """Starting points: previous values where known, else the effect's default or :data:`STARTS`."""
        per_term: list[list[np.ndarray]] = []
        for term, template in zip(self.terms, self.templates):
            if previous and template.name in previous:
                per_term.append([previous[template.name]])
            elif term.affine or template.name not in STARTS:
                per_term.append([template.param_vector()])
            else:
                options = []
                for values in STARTS[template.name]:
                    options.append(make_effect(template.name, **values, **template.option_values).param_vector())
                per_term.append(options)
        # one start per option of the term with most options; the others keep their first
        n = max((len(o) for o in per_term), default=1)
        return [np.concatenate([o[min(i, len(o) - 1)] for o in per_term]) if per_term else np.zeros(0)
                for i in range(n)]

    def fit(self, masks: list[np.ndarray] | None = None, previous: dict[str, np.ndarray] | None = None,
            theta0: np.ndarray | None = None) -> FitResult:
        """Fit on the fit rows selected by ``masks`` (all if None), from several starts."""
        masks = masks or [np.ones(len(rows), dtype=bool) for rows in self.rows]
        if not self.terms:  # nothing to fit: the nominal model
            rows = np.concatenate([r[m].reshape(-1) for r, m in zip(self.r_nom, masks)])
            return FitResult([], np.zeros(0), np.zeros(0), 0.5 * float(rows @ rows), rows.size, True, "no parameters")
        starts = [theta0] if theta0 is not None else self.starts(previous)
        best = None
        for x0 in starts:
            result = self._solve(np.asarray(x0, dtype=float), masks)
            if best is None or result.cost < best.cost:
                best = result
        assert best is not None  # starts is never empty
        theta = best.x
        std = self._standard_errors(theta, masks, best.jac)
        effects = [template.with_params(th) for template, th in zip(self.templates, self._split(theta))]
        return FitResult(effects, theta, std, float(best.cost), int(best.fun.size), bool(best.success), best.message)

    def _standard_errors(self, theta: np.ndarray, masks: list[np.ndarray], jac: np.ndarray) -> np.ndarray:
        """Heteroscedasticity- and autocorrelation-consistent (Newey-West) standard errors.

        ``cov = A^-1 B A^-1`` with ``A = J^T J`` and ``B`` the long-run covariance of the
        per-row scores ``g_k = J_k^T r_k`` (all three axes of a row together), summed over
        lags up to :func:`hac_lags` with Bartlett weights, within each segment. Unlike
        ``sigma^2 (J^T J)^-1`` this lets each axis have its own noise level (a vertical
        parameter is not credited with the quieter horizontal axes) and lets the noise be
        correlated over the smoothing window.
        """
        n, p = jac.shape
        if p == 0:
            return np.zeros(0)
        a_inv = np.linalg.pinv(jac.T @ jac)
        b = np.zeros((p, p))
        for seg, r, j, mask in zip(self.data.segments, self.residuals(theta), self._jacobians(theta), masks):
            scores = np.einsum("ma,map->mp", r * mask[:, None], j)
            b += scores.T @ scores
            lags = hac_lags(seg)
            for lag in range(1, min(lags, len(scores) - 1) + 1):
                c = scores[lag:].T @ scores[:-lag]
                b += (1.0 - lag / (lags + 1.0)) * (c + c.T)
        cov = a_inv @ b @ a_inv * n / max(n - p, 1)
        return np.sqrt(np.clip(np.diag(cov), 0.0, None))

    # ------------------------------------------------------------------ cross-validation
    def cross_validate(self, full: FitResult) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Out-of-fold residuals per segment at the fit rows, each fold refitted (from ``full``) without it.

        Returns the out-of-fold residuals and the fold parameter vectors (also stored in ``full.fold_theta``).
        """
        out = [np.empty_like(r) for r in self.r_nom]
        fold_theta = []
        for k in range(self.data.n_folds):
            masks = [seg.train_mask[k][rows] for seg, rows in zip(self.data.segments, self.rows)]
            if self.terms and any(m.any() for m in masks):
                # a nuisance parameter that reaches the held-out rows (a lag's start error, its segment's start
                # held out) is not fitted: it takes its default, so no held-out row sees a value fitted to it
                held = [folds == k for folds in self.folds]
                fixed = np.concatenate([t.fold_fixed(th, masks, held)
                                        for t, th in zip(self.terms, self._split(full.theta))])
                start = np.where(fixed, self._defaults, full.theta)
                theta_k = self._solve(start, masks, CV_TOL, free=~fixed).x
            else:
                theta_k = full.theta.copy()
            fold_theta.append(theta_k)
            residual = self.residuals(theta_k)
            for s, folds in enumerate(self.folds):
                held = folds == k
                out[s][held] = residual[s][held]
        full.fold_theta = fold_theta
        return out, fold_theta


def out_of_fold_residuals(data: FlightData, effects: list[Effect], fold_theta: list[np.ndarray],
                          nominal_residual: list[np.ndarray]) -> list[np.ndarray]:
    """Residual at every sample, each fold's samples against the effects fitted without that fold."""
    out = [r.copy() for r in nominal_residual]
    for seg_index, seg in enumerate(data.segments):
        index = 0
        for effect in effects:
            size = effect.param_size
            model = AeroModel([effect])
            if not effect.applies_to(seg.scene.structure):
                index += size
                continue
            evaluator = seg.evaluator(model, data.rotor_positions_body)
            theta = np.stack([fold_theta[k][index:index + size] for k in seg.fold]) if fold_theta else \
                effect.param_vector()
            out[seg_index] -= seg.smooth_force(evaluator.force(seg.states, theta))
            index += size
    return out
