"""A wall that ends: wall suction where the wall is, none beyond its edge, though the scene says an infinite plane.

A scene file gives each wall as a plane. A real wall ends (at a height, at its sides), and a
flight that passes its edge meets suction on one side and none on the other. Fitted as an
infinite plane, wall suction then comes out wrong (k_s 45 % high and d_thr 23 % low on one
such flight) and the residual it leaves is small and spread out.

:func:`find_edge` looks for the edge after the effects are chosen: where the fitted suction
acts, the data's suction (the residual with the fitted suction added back) is compared with
the fitted one on either side of every candidate edge, across the vehicle's height and its
position along the wall. An edge is proposed when one side shows less than
:data:`OUTSIDE_GAIN` of the modelled suction and the other at least :data:`INSIDE_GAIN`. Wall
suction is then fitted again as :class:`BoundedWall`, acting only on the wall's side of the
edge, and kept when it scores better on held-out data (one parameter more). The model file
cannot hold a wall's extent (the scene's wall is a plane), so it gets the library's
``wall_suction`` with the parameters fitted on the wall, and the report says where the wall
seems to end.
"""

from __future__ import annotations

import math

import numpy as np

from discovery.residuals import FlightData
from discovery.terms import EffectTerm
from wall_env.effects import Effect, WallSuction, make_effect

__all__ = ["BoundedWall", "BoundedWallTerm", "find_edge", "side_gains", "plain_wall", "OUTSIDE_GAIN", "INSIDE_GAIN"]

OUTSIDE_GAIN = 0.3  # beyond the edge the data show less than this share of the modelled suction
INSIDE_GAIN = 0.6  # and on the wall's side at least this share
MIN_SIDE_SHARE = 0.1  # each side holds at least this share of the samples where the suction acts
AXES = ("height", "along")


class BoundedWall(WallSuction):
    """Wall suction on the wall's side of an edge only: ``axis`` is ``height`` (world z of the centre of mass) or
    ``along`` (position along wall 0), the wall is where that coordinate is ``below`` or ``above`` ``edge_m``."""

    options = {**WallSuction.options, "axis": "height", "side": "below", "edge_m": math.inf}

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        if self.option_values["axis"] not in AXES or self.option_values["side"] not in ("below", "above"):
            raise ValueError(f"{self.name}: axis must be one of {AXES} and side 'below' or 'above', got "
                             f"{self.option_values['axis']!r}, {self.option_values['side']!r}")

    def describe(self) -> str:
        o = self.option_values
        what = "height" if o["axis"] == "height" else "position along wall 0"
        return f"the wall is where the vehicle's {what} is {o['side']} {o['edge_m']:.3g} m"

    def fitting_term(self, data: FlightData) -> BoundedWallTerm:
        """The suction on the wall's side only, on ``data``, as the fit sums it (:func:`discovery.fitting.make_term`)."""
        return BoundedWallTerm(data, self)


def plain_wall(effect: Effect) -> Effect:
    """The library's wall suction with ``effect``'s parameters (a :class:`BoundedWall` loses its edge)."""
    if not isinstance(effect, BoundedWall):
        return effect
    options = {k: v for k, v in effect.option_values.items() if k in WallSuction.options}
    return make_effect("wall_suction", **effect.params_dict(), **options)


def _coordinates(data: FlightData) -> dict[str, list[np.ndarray]]:
    """Per segment, the vehicle's height (world z) and position along wall 0 (horizontal, in the wall's plane)."""
    out: dict[str, list[np.ndarray]] = {"height": [], "along": []}
    wall = next((seg.scene.walls[0] for seg in data.segments if seg.scene.walls), None)
    axis = np.array([1.0, 0.0, 0.0])
    if wall is not None:
        axis = np.cross([0.0, 0.0, 1.0], np.asarray(wall.normal, dtype=float))
        axis = axis / np.linalg.norm(axis) if np.linalg.norm(axis) > 1e-9 else np.array([1.0, 0.0, 0.0])
    for seg in data.segments:
        p = seg.states.p_world
        out["height"].append(p[:, 2])
        out["along"].append((p - (np.asarray(wall.point) if wall is not None else 0.0)) @ axis)
    return out


class BoundedWallTerm(EffectTerm):
    """The library's wall suction, its per-sample force and Jacobian zeroed off the wall's side, then smoothed."""

    def __init__(self, data: FlightData, effect: BoundedWall):
        o = effect.option_values
        coordinates = _coordinates(data)[o["axis"]]
        self._masks = [(c <= o["edge_m"]) if o["side"] == "below" else (c >= o["edge_m"]) for c in coordinates]
        super().__init__(data, plain_wall(effect))

    def _sample_mask(self, s: int) -> np.ndarray | None:
        return self._masks[s]


def find_edge(data: FlightData, suction_force: np.ndarray, data_suction: np.ndarray) -> dict | None:
    """The edge across which the data's suction ``data_suction`` ``(N, 3)`` stops following the fitted suction
    ``suction_force`` ``(N, 3)`` (both smoothed, all segments), or None.

    Returns ``{"axis", "side", "edge_m", "gain_inside", "gain_outside", "sse_share"}``: the coordinate, the side
    the wall is on, the edge, the share of the modelled suction the data show on each side, and the share of the
    misfit (where the suction acts) that the edge removes."""
    magnitude = np.linalg.norm(suction_force, axis=1)
    peak = float(np.quantile(magnitude, 0.98)) if len(magnitude) else 0.0
    if peak <= 0:
        return None
    acting = magnitude >= 0.1 * peak
    if acting.sum() < 20:
        return None
    f, y = suction_force[acting], data_suction[acting]
    plain = float(np.sum((y - _gain(y, f) * f) ** 2))
    best: dict | None = None
    for axis, values in _coordinates(data).items():
        x = np.concatenate(values)[acting]
        coarse = np.quantile(x, np.linspace(0.05, 0.95, 19))
        step = float(coarse[1] - coarse[0]) if len(coarse) > 1 else 0.0
        for stage in (coarse, None):
            if stage is None:
                if best is None or best["axis"] != axis:
                    break
                stage = np.linspace(best["edge_m"] - step, best["edge_m"] + step, 21)
            for edge in stage:
                for side in ("below", "above"):
                    inside = x <= edge if side == "below" else x >= edge
                    share = float(inside.mean())
                    if not MIN_SIDE_SHARE <= share <= 1.0 - MIN_SIDE_SHARE:
                        continue
                    g_in, g_out = _gain(y[inside], f[inside]), _gain(y[~inside], f[~inside])
                    sse = float(np.sum((y[inside] - g_in * f[inside]) ** 2) + np.sum(y[~inside] ** 2))
                    if g_out < OUTSIDE_GAIN and g_in >= INSIDE_GAIN and (best is None or sse < best["sse"]):
                        best = {"axis": axis, "side": side, "edge_m": float(edge), "gain_inside": g_in,
                                "gain_outside": g_out, "sse": sse}
    if best is None:
        return None
    best["sse_share"] = 1.0 - best.pop("sse") / plain if plain > 0 else 0.0
    return best


def side_gains(data: FlightData, suction_force: np.ndarray, data_suction: np.ndarray, edge: dict) -> dict[str, float]:
    """``{"gain_inside", "gain_outside"}``: the share of the modelled suction ``suction_force`` ``(N, 3)`` that the
    data's ``data_suction`` show on the wall's side of ``edge`` (``axis``, ``side``, ``edge_m``) and beyond it, where
    the suction acts."""
    magnitude = np.linalg.norm(suction_force, axis=1)
    acting = magnitude >= 0.1 * float(np.quantile(magnitude, 0.98)) if len(magnitude) else np.zeros(0, dtype=bool)
    x = np.concatenate(_coordinates(data)[edge["axis"]])[acting]
    inside = x <= edge["edge_m"] if edge["side"] == "below" else x >= edge["edge_m"]
    f, y = suction_force[acting], data_suction[acting]
    return {"gain_inside": _gain(y[inside], f[inside]), "gain_outside": _gain(y[~inside], f[~inside])}


def _gain(y: np.ndarray, f: np.ndarray) -> float:
    """Least-squares ``g`` in ``y = g f``."""
    denominator = float(np.sum(f * f))
    return float(np.sum(y * f)) / denominator if denominator > 0 else 0.0
