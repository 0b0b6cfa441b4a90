"""One effect's force on a log, as the fit needs it: per step, and smoothed at every segment's fit rows with its
Jacobian.

:class:`Term` is what :class:`discovery.fitting.EffectFit` sums; :class:`EffectTerm` evaluates a library effect
through its CasADi function. Discovery's own candidates build their own terms (``effect.fitting_term(data)``): a
motor lag (:mod:`discovery.motor_lag`), an affine thrust map (:mod:`discovery.thrust_map`), a residual's structure
(:mod:`discovery.standins`) and a wall that ends (:mod:`discovery.wall_extent`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from discovery.residuals import FlightData, step_average_samples
from wall_env.aero import AeroModel
from wall_env.effects import Effect

__all__ = ["Term", "EffectTerm"]


class Term(ABC):
    """One effect's contribution ``K[F(theta)]`` per segment of ``data`` (what :class:`EffectFit` sums).

    A term gives its force per step (:meth:`steps`) and, with its Jacobian, at the fit rows
    (:meth:`at_rows`); its force at every sample (:meth:`smoothed`) is the steps through each
    segment's kernel. ``affine`` says the Jacobian does not depend on ``theta``.
    """

    data: FlightData
    size: int
    low: np.ndarray
    high: np.ndarray
    affine: bool

    @abstractmethod
    def at_rows(self, segment: int, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``K[F]`` ``(m, 3)`` and its Jacobian ``(m, 3, size)`` at the segment's fit rows."""

    @abstractmethod
    def steps(self, segment: int, theta: np.ndarray) -> np.ndarray:
        """``F`` averaged over each step ``(n - 1, 3)`` (unsmoothed: what the per-step residual of
        :func:`discovery.noise.step_residual` holds of it); ``theta`` ``(size,)`` or one row per sample."""

    def smoothed(self, segment: int, theta: np.ndarray) -> np.ndarray:
        """``K[F]`` ``(n, 3)`` at every sample: :meth:`steps` through the segment's kernel."""
        return self.data.segments[segment].kernel.step_average(self.steps(segment, theta))

    def fold_fixed(self, theta: np.ndarray, train: list[np.ndarray], held: list[np.ndarray]) -> np.ndarray:
        """Entries a cross-validation fold must hold at their defaults (nuisance parameters that reach
        its held-out rows ``held``); a term without nuisance parameters holds none."""
        return np.zeros(self.size, dtype=bool)


class EffectTerm(Term):
    """A library effect's ``K[F(theta)]`` at every segment's fit rows, through its CasADi function, with caching."""

    def __init__(self, data: FlightData, effect: Effect):
        self.data = data
        self.effect = effect
        self.model = AeroModel([effect])
        self.size = effect.param_size
        self.low, self.high = effect.param_bounds()
        self._evaluators = [seg.evaluator(self.model, data.rotor_positions_body) for seg in data.segments]
        self._active = [effect.applies_to(seg.scene.structure) for seg in data.segments]
        self._cache: dict[int, tuple[bytes, tuple[np.ndarray, np.ndarray]]] = {}
        self.affine = False
        self._affine_base: list[tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        self._check_affine()

    def _sample_mask(self, s: int) -> np.ndarray | None:
        """Which samples of segment ``s`` the effect acts on (``None``: all of them)."""
        return None

    def _evaluate(self, s: int, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        seg = self.data.segments[s]
        rows = seg.fit_rows
        if not self._active[s]:
            return np.zeros((len(rows), 3)), np.zeros((len(rows), 3, self.size))
        f, j = self._evaluators[s].force_and_jacobian(seg.states, theta)
        mask = self._sample_mask(s)
        if mask is not None:
            f, j = f * mask[:, None], j * mask[:, None, None]
        return seg.smooth_force(f, rows), seg.smooth_force(j, rows)

    def _check_affine(self) -> None:
        """An effect is affine if its Jacobian is the same at two distant parameter values."""
        a = np.clip(self.effect.param_vector(), self.low, self.high)
        span = np.where(np.isfinite(self.high - self.low), self.high - self.low, 1.0)
        b = np.clip(a + 0.137 * span + 0.01, self.low, self.high)
        at_a = [self._evaluate(s, a) for s in range(len(self.data.segments))]
        at_b = [self._evaluate(s, b) for s in range(len(self.data.segments))]
        scale = max(max((np.abs(j).max() if j.size else 0.0) for _, j in at_a), 1e-12)
        if all(np.allclose(ja, jb, rtol=1e-9, atol=1e-9 * scale) for (_, ja), (_, jb) in zip(at_a, at_b)):
            self.affine = True
            self._affine_base = [(f, j, a) for f, j in at_a]

    def at_rows(self, segment: int, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        theta = np.asarray(theta, dtype=float)
        if self._affine_base is not None:
            f, j, a = self._affine_base[segment]
            return f + j @ (theta - a), j
        key = theta.tobytes()
        cached = self._cache.get(segment)
        if cached is None or cached[0] != key:
            cached = (key, self._evaluate(segment, theta))
            self._cache[segment] = cached
        return cached[1]

    def steps(self, segment: int, theta: np.ndarray) -> np.ndarray:
        seg = self.data.segments[segment]
        if not self._active[segment]:
            return np.zeros((seg.n - 1, 3))
        force = self._evaluators[segment].force(seg.states, theta)
        mask = self._sample_mask(segment)
        return step_average_samples(force if mask is None else force * mask[:, None])
