"""What a model leaves unexplained, how much, and where it lives: in time, in position or against a state.

A held-out residual is *unexplained* when it is more than :data:`~discovery.noise.FLOOR_FACTOR`
times the log's own noise floor (:func:`discovery.noise.noise_floor`; its 95 % upper bound, as
the floor is itself measured with an error) and the excess over that is at least
:data:`~discovery.selection.MIN_WEIGHT_SHARE` of the weight, or when cross-validated bin means
against a regressor predict a material share of it (a localised residual inside the noise).
Then :func:`where_it_lives` asks three questions, each answered by predicting held-out folds,
and names the best answer:

- **states** (:func:`discovery.regressors.localise_residual`): bin means against one
  regressor (a distance to a surface, a velocity, the thrust) predict it: it depends on
  that quantity, with its range and a shape-free curve;
- **position**: cell means over a 2-D map of the flight's position, height against position
  along the wall (:func:`position_map`): it lives in a region of space (the edge of a wall
  that ends, say), given as the ranges of the cells that stand out;
- **time**: the spectrum of its excess over the noise (:func:`discovery.noise.residual_spectrum`)
  and a sinusoid at the spectrum's peak fitted on the other folds (:func:`periodic_explained`):
  periodic (a gust at that frequency) or, when nothing predicts it but most of its excess is
  slow, a force that varies over seconds with no relation to the flight's state (a changing
  wind, turbulence).

A quantity that moves with the manoeuvre (the height on a sinusoidal climb) and a time
period can predict alike; the state is then preferred, since it names a cause. A position
map names none: on a flight that repeats its path, a gust at nearly the path's period is
also a function of where the vehicle is (a 0.202 Hz gust on a 5 s sweep: the map predicted
80 % of it, the sinusoid 99 %), so the map is named only when it predicts at least as much
as the sinusoid.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from discovery.noise import FLOOR_FACTOR, SLOW_HZ, judged_floor, residual_spectrum
from discovery.regressors import Regressor, localise_residual, time_intervals
from discovery.residuals import FlightData

__all__ = ["position_map", "periodic_explained", "principal_direction", "is_unexplained", "where_it_lives",
           "MAP_BINS"]

MAP_BINS = (6, 6)  # along the wall x height
_STATE_OVER_TIME = 0.8  # a state is named when it predicts at least this share of what a time period predicts
MAX_REGION_SHARE = 0.7  # a region of more than this share of the flight does not localise a residual


def principal_direction(residual: np.ndarray) -> list[float] | None:
    """The world direction along which ``residual`` ``(N, 3)`` is largest (its second moment's main axis), signed
    along its mean where it has one."""
    if len(residual) == 0:
        return None
    moment = residual.T @ residual / len(residual)
    values, vectors = np.linalg.eigh(moment)
    axis = vectors[:, -1]
    mean = residual.mean(axis=0)
    if float(axis @ mean) < 0 or (abs(float(axis @ mean)) < 1e-12 and axis[np.argmax(np.abs(axis))] < 0):
        axis = -axis
    return [round(float(c), 3) for c in axis]


def _cv_cell_means(residual: np.ndarray, cell: np.ndarray, folds: np.ndarray, n_folds: int,
                   n_cells: int) -> tuple[float, np.ndarray]:
    """Held-out explained share of cell means (cells ``cell``, -1 outside), and the predictions."""
    predicted = np.zeros_like(residual)
    for k in range(n_folds):
        train = (folds != k) & (cell >= 0)
        held = (folds == k) & (cell >= 0)
        if not held.any() or not train.any():
            continue
        sums = np.zeros((n_cells, 3))
        np.add.at(sums, cell[train], residual[train])
        counts = np.bincount(cell[train], minlength=n_cells)[:, None]
        means = np.divide(sums, counts, out=np.zeros_like(sums), where=counts > 0)
        predicted[held] = means[cell[held]]
    energy = float(np.sum(residual**2))
    return (1.0 - float(np.sum((residual - predicted) ** 2)) / energy if energy > 0 else 0.0), predicted


def _quantile_index(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, n + 1)))
    if len(edges) < 2:
        return np.array([float(x.min()), float(x.max())]), np.zeros(len(x), dtype=int)
    return edges, np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)


def position_map(data: FlightData, residual: np.ndarray, bins: tuple[int, int] = MAP_BINS) -> dict:
    """Cell means of ``residual`` over the flight's position: height against position along the first wall
    (the horizontal direction in its plane; world x without a wall).

    Returns ``{"along", "height_unit", "explained_fraction", "cells", "region"}``: what the along-axis is,
    the held-out share the cell means predict, every cell (ranges, samples, mean force) and the region of
    the cells whose mean stands out from the noise (height and along-wall ranges), or None."""
    p = data.concat([seg.states.p_world for seg in data.segments])
    wall = next((seg.scene.walls[0] for seg in data.segments if seg.scene.walls), None)
    if wall is not None:
        normal = np.asarray(wall.normal, dtype=float)
        along_axis = np.cross([0.0, 0.0, 1.0], normal)
        if np.linalg.norm(along_axis) < 1e-6:  # a floor-like wall: any horizontal direction
            along_axis = np.array([1.0, 0.0, 0.0])
        along_axis /= np.linalg.norm(along_axis)
        along = (p - np.asarray(wall.point, dtype=float)) @ along_axis
        label = "position along wall 0"
    else:
        along, along_axis, label = p[:, 0], np.array([1.0, 0.0, 0.0]), "world x"
    grounds = [seg.scene.ground_z for seg in data.segments]
    height = p[:, 2] - (grounds[0] if grounds[0] is not None and all(g == grounds[0] for g in grounds) else 0.0)
    u_edges, u_index = _quantile_index(along, bins[0])
    h_edges, h_index = _quantile_index(height, bins[1])
    n_u, n_h = len(u_edges) - 1, len(h_edges) - 1
    cell = u_index * n_h + h_index
    explained, _ = _cv_cell_means(residual, cell, data.folds, data.n_folds, n_u * n_h)
    counts = np.bincount(cell, minlength=n_u * n_h)
    sums = np.zeros((n_u * n_h, 3))
    np.add.at(sums, cell, residual)
    means = sums / np.maximum(counts, 1)[:, None]
    window = max(1.0, float(np.median([s.kernel.window for s in data.segments])))
    spread = float(np.sqrt(np.mean(np.sum((residual - means[cell]) ** 2, axis=1))))
    standard_error = spread / np.sqrt(np.maximum(counts / window, 1.0))
    magnitude = np.linalg.norm(means, axis=1)
    stands_out = (magnitude > 3.0 * standard_error) & (magnitude > 0.3 * magnitude.max()) & (counts > 0)
    cells = []
    for c in range(n_u * n_h):
        i, j = divmod(c, n_h)
        cells.append({"along_m": [round(float(u_edges[i]), 3), round(float(u_edges[i + 1]), 3)],
                      "height_m": [round(float(h_edges[j]), 3), round(float(h_edges[j + 1]), 3)],
                      "samples": int(counts[c]), "force_N": [round(float(x), 4) for x in means[c]],
                      "stands_out": bool(stands_out[c])})
    region = None
    if stands_out.any():
        chosen = np.flatnonzero(stands_out)
        u_cells, h_cells = chosen // n_h, chosen % n_h
        region = {"along_m": [round(float(u_edges[u_cells.min()]), 3), round(float(u_edges[u_cells.max() + 1]), 3)],
                  "height_m": [round(float(h_edges[h_cells.min()]), 3), round(float(h_edges[h_cells.max() + 1]), 3)],
                  "top_of_flight": bool(h_cells.min() > 0 and h_cells.max() == n_h - 1),
                  "bottom_of_flight": bool(h_cells.max() < n_h - 1 and h_cells.min() == 0),
                  "fraction_of_flight": round(float(np.isin(cell, chosen).mean()), 3),
                  "time_intervals": time_intervals(data, np.isin(cell, chosen))}
    return {"along": label, "along_axis_world": [round(float(c), 3) for c in along_axis],
            "explained_fraction": round(explained, 4), "cells": cells, "region": region}


def periodic_explained(data: FlightData, residual: np.ndarray, frequency_hz: float | None) -> float:
    """Held-out share of ``residual`` that a sinusoid at ``frequency_hz`` (a sine and a cosine per axis, fitted on
    the other folds) predicts: a periodic force predicts itself across folds, a random one does not."""
    if not frequency_hz:
        return 0.0
    t = data.times
    basis = np.column_stack([np.sin(2 * np.pi * frequency_hz * t), np.cos(2 * np.pi * frequency_hz * t)])
    folds = data.folds
    predicted = np.zeros_like(residual)
    for k in range(data.n_folds):
        train, held = folds != k, folds == k
        if not held.any() or train.sum() < 4:
            continue
        coefficients, *_ = np.linalg.lstsq(basis[train], residual[train], rcond=None)
        predicted[held] = basis[held] @ coefficients
    energy = float(np.sum(residual**2))
    return 1.0 - float(np.sum((residual - predicted) ** 2)) / energy if energy > 0 else 0.0


def is_unexplained(residual_rms: float, floor: dict, weight: float, min_weight_share: float) -> bool:
    """More than :data:`FLOOR_FACTOR` times the noise floor (its 95 % upper bound, :func:`~discovery.noise.judged_floor`),
    by at least ``min_weight_share`` of the weight."""
    noise = judged_floor(floor)
    if not np.isfinite(noise) or not np.isfinite(residual_rms):
        return False
    excess = float(np.sqrt(max(residual_rms**2 - noise**2, 0.0)))
    return residual_rms > FLOOR_FACTOR * noise and excess >= min_weight_share * weight


def where_it_lives(data: FlightData, residual: np.ndarray, candidates: list[Regressor], floor: dict,
                   threshold: float) -> dict[str, Any]:
    """States, position and time (see the module text) and which of them the residual ``(N, 3)`` lives in:
    ``{"lives_in", "states", "position", "time", "level_N", "direction_world"}``; ``lives_in`` is ``"everywhere"``
    (a steady force: what varies is within the noise), ``"states"``, ``"position"``, ``"time (periodic)"``,
    ``"time (slow)"`` or ``"nowhere in particular"``. The three questions are asked of the residual less its
    level (each flight's mean): the level alone is a steady force."""
    # the residual's level (each flight's mean) is a steady force; where it lives is asked of how it varies
    level = np.zeros_like(residual)
    flights = np.concatenate([np.full(seg.n, seg.flight) for seg in data.segments])
    for f in np.unique(flights):
        level[flights == f] = residual[flights == f].mean(axis=0)
    variation = residual - level
    noise = judged_floor(floor)
    steady = bool(np.isfinite(noise) and _rms(variation) <= FLOOR_FACTOR * noise)
    # where the force is (its range, direction, times) is asked of the residual itself when a regressor localises
    # it there; a residual whose level swamps how it varies is asked of its variation
    states = localise_residual(data, residual, candidates)
    if states.get("regressor") in (None, "everywhere") or states.get("range") is None:
        states = localise_residual(data, variation, candidates)
        states["direction_world"] = principal_direction(variation)
    position = position_map(data, variation)
    spectrum = residual_spectrum(data, residual, floor) or {}
    periodic = periodic_explained(data, variation, spectrum.get("peak_hz"))
    time = {**spectrum, "periodic_explained_fraction": round(periodic, 4)}
    by_state = states["explained_fraction"] if states.get("regressor") not in (None, "everywhere") \
        and states.get("range") is not None else 0.0
    # a region that covers most of the flight says nothing about where the residual lives
    region = position.get("region")
    by_place = position["explained_fraction"] if region is not None \
        and region["fraction_of_flight"] <= MAX_REGION_SHARE else 0.0
    # a state names a cause and is preferred over a period it nearly matches; a map of cells names none and is
    # preferred only when it predicts at least as much as the sinusoid of two coefficients per axis
    named_state = by_state >= threshold and by_state >= _STATE_OVER_TIME * periodic
    named_place = by_place >= threshold and by_place >= periodic
    if steady:
        lives_in = "everywhere"
    elif named_state or named_place:
        lives_in = "states" if named_state and (by_state >= by_place or not named_place) else "position"
    elif periodic >= threshold:
        lives_in = "time (periodic)"
    elif spectrum.get("slow_share", 0.0) >= 0.5:
        lives_in = "time (slow)"
    else:
        lives_in = "nowhere in particular"
    return {"lives_in": lives_in, "states": {k: v for k, v in states.items() if k not in ("ranking", "all_explained")},
            "ranking": states.get("ranking", []), "all_explained": states.get("all_explained", []),
            "position": position, "time": time, "best_explained": max(by_state, by_place, periodic),
            "level_N": [round(float(x), 4) for x in residual.mean(axis=0)],
            "direction_world": principal_direction(variation if not steady else residual), "slow_hz": SLOW_HZ}


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(x**2, axis=1)))) if len(x) else 0.0
