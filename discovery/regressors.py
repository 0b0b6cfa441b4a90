"""Where a residual (or an effect's force) lives: candidate regressors and localisation.

Candidate regressors, per sample (SI): the distance of each rotor centre to each wall
plane and the nearest one per wall, to the nearest surface of the scene's bodies (each
rotor and the nearest rotor; PyBullet's query, :mod:`wall_env.surfaces`, as far as it
reaches), the height of the lowest rotor above the ground,
the depth of the highest rotor under the ceiling, the speed and the (signed) velocity
along each body axis, the collective thrust and the time. Rotor positions come from
the smoothed position and logged attitude.

:func:`localise_residual` asks which regressor the residual depends on: for each
regressor the residual is averaged in bins of that regressor on the training folds
and the bin means predict the held-out samples (the same cross-validation folds as
the fits). The regressor whose bin means explain the largest fraction of the held-out
residual energy localises it; the bins whose means stand out from the noise give the
region (a range of the regressor, the times the flight was there, and the mean
direction of the residual in the world frame).

:func:`describe_force` says where a fitted effect acts: the samples where its force
is at least 5 % of its peak, and the regressor that best explains its magnitude
with that regressor's range over those samples (e.g. "nearest rotor distance to wall
0 in [0.06, 0.13] m"), or "everywhere" for a steady force. Among regressors that
explain equally well (all rotor distances move together), the distance to the
nearest surface is named.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from discovery.residuals import FlightData

__all__ = ["Regressor", "regressors", "localise_residual", "describe_force", "time_intervals", "piecewise_linear"]

N_BINS = 10
_TIE = 1e-3  # scores closer than this (or 1 % of the best) are a tie, settled by _pick
_EVERYWHERE_MARGIN = 0.1  # a regressor must beat a constant by this share of what it explains to localise


@dataclass
class Regressor:
    """One candidate regressor: a name, a unit and its value at every sample (all segments concatenated)."""

    name: str
    unit: str
    values: np.ndarray

    def to_dict(self) -> dict:
        return {"name": self.name, "unit": self.unit}


def regressors(data: FlightData) -> list[Regressor]:
    """Every candidate regressor that the logs' scenes allow."""
    rotors = data.rotor_positions_body
    per_segment: dict[tuple[str, str], list[np.ndarray]] = {}

    def add(name: str, unit: str, seg_index: int, values: np.ndarray) -> None:
        per_segment.setdefault((name, unit), [np.full(s.n, np.nan) for s in data.segments])[seg_index] = values

    for s, seg in enumerate(data.segments):
        p = seg.states.p_world
        R = seg.states.R_body_to_world
        rotor_world = rotor_centres_world(p, R, rotors)
        for k, wall in enumerate(seg.scene.walls):
            d = (rotor_world - np.asarray(wall.point)) @ np.asarray(wall.normal)  # (n, 4)
            add(f"nearest rotor distance to wall {k}", "m", s, d.min(axis=1))
            for j in range(4):
                add(f"rotor {j} distance to wall {k}", "m", s, d[:, j])
        if seg.scene.has_bodies:  # the tangent plane of each rotor's nearest surface (slot 0), at this pose
            d = _body_distances(seg.scene, rotors, p, R)
            add("nearest rotor distance to the structure", "m", s, d.min(axis=1))
            for j in range(4):
                add(f"rotor {j} distance to the structure", "m", s, d[:, j])
        above_ground, below_ceiling = surface_clearances(rotor_world[:, :, 2], seg.scene)
        if above_ground is not None:
            add("height above ground", "m", s, above_ground)
        if below_ceiling is not None:
            add("distance to ceiling", "m", s, below_ceiling)
        add("speed", "m/s", s, np.linalg.norm(seg.states.v_world, axis=1))
        v_body = np.einsum("nji,nj->ni", R, seg.states.v_world)
        for axis, label in enumerate("xyz"):
            add(f"velocity along body {label}", "m/s", s, v_body[:, axis])
        add("thrust", "N", s, seg.thrust)
        add("time", "s", s, seg.t)
    return [Regressor(name, unit, np.concatenate(parts)) for (name, unit), parts in per_segment.items()]


def rotor_centres_world(p_world: np.ndarray, R_body_to_world: np.ndarray, rotors_body: np.ndarray) -> np.ndarray:
    """``(n, rotors, 3)`` m: each rotor centre in the world at every sample."""
    return p_world[:, None, :] + np.einsum("nij,rj->nri", R_body_to_world, rotors_body)


def surface_clearances(rotor_z: np.ndarray, scene: Any) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(above_ground, below_ceiling)`` (m) from the rotors' heights ``rotor_z`` ``(n, rotors)``: the lowest rotor's
    height above the ground and the highest rotor's distance under the ceiling, negative past the plane; None where
    the scene has no such surface."""
    above_ground = rotor_z.min(axis=1) - scene.ground_z if scene.ground_z is not None else None
    below_ceiling = scene.ceiling_z - rotor_z.max(axis=1) if scene.ceiling_z is not None else None
    return above_ground, below_ceiling


def _bins(x: np.ndarray, n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Quantile bin edges of the finite values and each sample's bin (-1 where undefined)."""
    finite = np.isfinite(x)
    edges = np.unique(np.quantile(x[finite], np.linspace(0, 1, n_bins + 1))) if finite.any() else np.zeros(2)
    index = np.full(len(x), -1)
    if len(edges) >= 2:
        index[finite] = np.clip(np.searchsorted(edges, x[finite], side="right") - 1, 0, len(edges) - 2)
    return edges, index


def time_intervals(data: FlightData, mask: np.ndarray, min_gap_s: float = 0.5) -> list[dict]:
    """Stretches of flight where ``mask`` holds: ``[{"log", "from_s", "to_s"}, ...]``, merging short gaps."""
    out: list[dict] = []
    start = 0
    for seg in data.segments:
        part = mask[start:start + seg.n]
        start += seg.n
        current: list[float] | None = None
        for time, on in zip(seg.t, part):
            if not on:
                continue
            if current is not None and time - current[1] <= min_gap_s:
                current[1] = float(time)
            else:
                if current is not None:
                    out.append({"log": seg.source, "from_s": round(current[0], 3), "to_s": round(current[1], 3)})
                current = [float(time), float(time)]
        if current is not None:
            out.append({"log": seg.source, "from_s": round(current[0], 3), "to_s": round(current[1], 3)})
    return out


def _body_distances(scene: Any, rotors: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Each rotor centre's distance ``(n, 4)`` to the nearest surface of the scene's bodies (the query's reach
    where none is nearer)."""
    from discovery.aero_eval import SURFACE_REACH, _surface_query
    from wall_env.scene import SURFACE_SIZE, SURFACE_SLOTS

    slots = _surface_query(scene, tuple(map(tuple, rotors))).rotor_surfaces_at(p, R)
    slots = slots.reshape(len(p), 4, SURFACE_SLOTS, SURFACE_SIZE)[:, :, 0]  # slot 0: the nearest
    rotor_world = rotor_centres_world(p, R, rotors)
    d = np.einsum("nrj,nrj->nr", slots[:, :, 3:6], rotor_world - slots[:, :, 0:3])
    return np.where(slots[:, :, 6] > 0, d, SURFACE_REACH)


def localise_residual(data: FlightData, residual: np.ndarray, candidates: list[Regressor] | None = None,
                      n_bins: int = N_BINS, exclude: tuple[str, ...] = ("time",)) -> dict:
    """Which regressor the residual ``(N, 3)`` depends on, by cross-validated bin means.

    Returns ``{"regressor", "unit", "explained_fraction", "range", "direction_world",
    "fraction_of_flight", "time_intervals", "ranking", "all_explained"}``; ``explained_fraction`` is the
    share of the held-out residual energy the best regressor's bin means predict (``ranking``: the best
    five regressors, ``all_explained``: every one).
    ``time`` is ranked but not used to localise (it says when, not what).
    """
    candidates = candidates if candidates is not None else regressors(data)
    folds = data.folds
    energy = float(np.sum(residual**2))
    ranking: list[dict[str, Any]] = []
    scored = []
    for reg in candidates:
        edges, index = _bins(reg.values, n_bins)
        n_b = len(edges) - 1
        predicted = np.zeros_like(residual)
        for k in range(data.n_folds):
            train = (folds != k) & (index >= 0)
            held = (folds == k) & (index >= 0)
            if not held.any() or not train.any():
                continue
            sums = np.zeros((n_b, 3))
            np.add.at(sums, index[train], residual[train])
            counts = np.bincount(index[train], minlength=n_b)[:, None]
            means = np.divide(sums, counts, out=np.zeros_like(sums), where=counts > 0)
            predicted[held] = means[index[held]]
        explained = 1.0 - float(np.sum((residual - predicted) ** 2)) / energy if energy > 0 else 0.0
        ranking.append({"regressor": reg.name, "explained_fraction": round(explained, 4)})
        if reg.name not in exclude:
            scored.append((explained, reg))
    ranking.sort(key=lambda r: -r["explained_fraction"])
    picked = _pick(scored)
    best = None
    if picked is not None:
        edges, index = _bins(picked[1].values, n_bins)
        best = (picked[0], picked[1], edges, index)
    if best is None:
        return {"regressor": None, "explained_fraction": 0.0, "ranking": ranking, "all_explained": ranking}
    constant = _constant_explained(residual, folds, data.n_folds, energy)
    if best[0] > 0 and best[0] - constant < _EVERYWHERE_MARGIN * best[0]:
        # the residual is about the same everywhere: no regressor localises it
        mask = np.ones(len(residual), dtype=bool)
        return {"regressor": "everywhere", "unit": None, "explained_fraction": round(best[0], 4), "range": None,
                "fraction_of_flight": 1.0, "direction_world": _direction(residual, mask),
                "time_intervals": time_intervals(data, mask), "ranking": ranking[:5], "all_explained": ranking}
    explained, reg, edges, index = best
    n_b = len(edges) - 1
    counts = np.bincount(index[index >= 0], minlength=n_b)
    sums = np.zeros((n_b, 3))
    np.add.at(sums, index[index >= 0], residual[index >= 0])
    means = sums / np.maximum(counts, 1)[:, None]
    # noise of a bin mean: residual spread over the effective number of independent samples
    tau = max(1.0, float(np.median([s.kernel.window for s in data.segments])))
    spread = np.sqrt(np.mean(np.sum((residual - means[np.clip(index, 0, None)]) ** 2, axis=1)))
    standard_error = spread / np.sqrt(np.maximum(counts / tau, 1.0))
    magnitude = np.linalg.norm(means, axis=1)
    significant = (magnitude > 3.0 * standard_error) & (magnitude > 0.2 * magnitude.max())
    region = _region_from_bins(reg, edges, index, significant)
    mask = region.pop("mask")
    return {"regressor": reg.name, "unit": reg.unit, "explained_fraction": round(explained, 4), **region,
            "direction_world": _direction(residual, mask), "time_intervals": time_intervals(data, mask),
            "ranking": ranking[:5], "all_explained": ranking}


def _constant_explained(residual: np.ndarray, folds: np.ndarray, n_folds: int, energy: float) -> float:
    """Held-out explained fraction of a constant (the training mean)."""
    if energy <= 0:
        return 0.0
    predicted = np.zeros_like(residual)
    for k in range(n_folds):
        held = folds == k
        if held.any() and (~held).any():
            predicted[held] = residual[~held].mean(axis=0)
    return 1.0 - float(np.sum((residual - predicted) ** 2)) / energy


def _region_from_bins(reg: Regressor, edges: np.ndarray, index: np.ndarray, significant: np.ndarray) -> dict:
    if not significant.any():
        mask = np.zeros(len(index), dtype=bool)
        return {"range": None, "fraction_of_flight": 0.0, "mask": mask}
    chosen = np.flatnonzero(significant)
    low, high = float(edges[chosen.min()]), float(edges[chosen.max() + 1])
    mask = np.isin(index, chosen)
    return {"range": [round(low, 4), round(high, 4)], "fraction_of_flight": round(float(mask.mean()), 3), "mask": mask}


def _direction(vectors: np.ndarray, mask: np.ndarray) -> list[float] | None:
    if not mask.any():
        return None
    mean = vectors[mask].mean(axis=0)
    norm = float(np.linalg.norm(mean))
    return [round(float(c), 3) for c in mean / norm] if norm > 0 else None


def _binned_r2(x: np.ndarray, y: np.ndarray, n_bins: int = N_BINS) -> float:
    """Share of the variance of ``y`` explained by its means in quantile bins of ``x``."""
    finite = np.isfinite(x)
    if finite.sum() < 2 * n_bins:
        return -np.inf
    _, index = _bins(x[finite], n_bins)
    yy = y[finite]
    n_b = index.max() + 1
    means = np.bincount(index, weights=yy, minlength=n_b) / np.maximum(np.bincount(index, minlength=n_b), 1)
    total = float(np.sum((yy - yy.mean()) ** 2))
    return 1.0 - float(np.sum((yy - means[index]) ** 2)) / total if total > 0 else -np.inf


def _pick(scored: list[tuple[float, Regressor]]) -> tuple[float, Regressor] | None:
    """Best score; among near ties, a distance regressor to the nearest surface (smallest median)."""
    if not scored:
        return None
    top = max(v for v, _ in scored)
    ties = [(v, r) for v, r in scored if v >= top - max(_TIE, 0.01 * abs(top))]
    return min(ties, key=lambda item: (item[1].unit != "m", float(np.nanmedian(np.abs(item[1].values)))
                                       if item[1].unit == "m" else 0.0))


def describe_force(data: FlightData, force: np.ndarray, candidates: list[Regressor] | None = None,
                   min_r2: float = 0.5) -> dict:
    """Where a fitted effect's (smoothed) force ``(N, 3)`` acts and what it depends on.

    The force *acts* where its magnitude is at least 5 % of its peak (98th
    percentile). The regressor whose bin means best explain the magnitude (``r2``) is
    reported with its range over the acting samples; ``"everywhere"`` when no regressor
    explains at least ``min_r2`` of the magnitude's variation (a steady force).
    Returns ``{"regressor", "unit", "range", "r2", "fraction_of_flight", "direction_world",
    "peak_force_N", "time_intervals"}``.
    """
    candidates = candidates if candidates is not None else regressors(data)
    magnitude = np.linalg.norm(force, axis=1)
    peak = float(np.quantile(magnitude, 0.98)) if len(magnitude) else 0.0
    if peak <= 0:
        return {"regressor": None, "unit": None, "range": None, "r2": None, "fraction_of_flight": 0.0,
                "direction_world": None, "peak_force_N": 0.0, "time_intervals": []}
    acting = magnitude >= 0.05 * peak
    common = {"fraction_of_flight": round(float(acting.mean()), 3), "direction_world": _direction(force, acting),
              "peak_force_N": round(peak, 4), "time_intervals": time_intervals(data, acting)}
    steady = float(np.std(magnitude)) <= 0.05 * float(np.mean(magnitude))
    scored = [] if steady else [(_binned_r2(r.values, magnitude), r) for r in candidates if r.name != "time"]
    best = _pick([(v, r) for v, r in scored if np.isfinite(v)])
    if best is None or best[0] < min_r2:
        return {"regressor": "everywhere", "unit": None, "range": None,
                "r2": None if best is None else round(best[0], 3), **common}
    r2, reg = best
    inside = reg.values[acting & np.isfinite(reg.values)]
    value_range = [round(float(inside.min()), 4), round(float(inside.max()), 4)] if inside.size else None
    return {"regressor": reg.name, "unit": reg.unit, "range": value_range, "r2": round(r2, 3), **common}


def piecewise_linear(x: np.ndarray, y: np.ndarray, n_knots: int = 8) -> dict | None:
    """A shape-free description of ``y`` against ``x``: the least-squares piecewise-linear curve.

    Knots sit at quantiles of the finite ``x`` (so every piece holds data); the curve is
    the sum of hat functions at the knots with least-squares heights. Returns
    ``{"knots": [...], "values": [...], "explained_fraction"}`` or None when ``x`` has
    too few distinct values.
    """
    finite = np.isfinite(x) & np.isfinite(y)
    if finite.sum() < 2 * n_knots:
        return None
    xs, ys = x[finite], y[finite]
    knots = np.unique(np.quantile(xs, np.linspace(0.0, 1.0, n_knots)))
    if len(knots) < 2:
        return None
    basis = np.column_stack([np.interp(xs, knots, np.eye(len(knots))[k]) for k in range(len(knots))])
    heights, *_ = np.linalg.lstsq(basis, ys, rcond=None)
    fitted = basis @ heights
    total = float(np.sum(ys**2))
    return {"knots": [round(float(k), 5) for k in knots], "values": [round(float(v), 5) for v in heights],
            "explained_fraction": round(1.0 - float(np.sum((ys - fitted) ** 2)) / total, 4) if total > 0 else 0.0}
