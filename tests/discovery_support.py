"""Helpers for the discovery tests: the hidden-effect protocol."""

from __future__ import annotations

import numpy as np

from discovery.hidden_effects import draw, spec


def effect_spec(name: str, params: dict) -> str:
    """The command-line form of one effect, e.g. ``wall_suction:k_s=4.1,d_thr=0.132``."""
    return spec([{"name": name, "params": params}])


def draw_hidden_effect(name: str, rng: np.random.Generator) -> tuple[dict, dict]:
    """Parameters in a realistic range for effect ``name`` and a flight that excites it
    (:func:`discovery.hidden_effects.draw`, whose module text gives the ranges).

    Returns ``(params, fly keyword arguments)``.
    """
    effect, flight = draw(name, rng)
    return effect["params"], flight


def relative_errors(fitted: dict, truth: dict) -> list[float]:
    """|fitted - true| / |true| for every parameter entry."""
    out = []
    for key, value in truth.items():
        f, v = np.atleast_1d(np.asarray(fitted[key], float)), np.atleast_1d(np.asarray(value, float))
        out += list(np.abs(f - v) / np.abs(v))
    return out


