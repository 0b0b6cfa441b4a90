"""Helpers for the discovery tests: the hidden-effect protocol."""

from __future__ import annotations

import math

import numpy as np

ARM = 0.1 / math.sqrt(2.0)  # the default vehicle's rotor offset along body x (m)


def effect_spec(name: str, params: dict) -> str:
    """The command-line form of one effect, e.g. ``wall_suction:k_s=4.1,d_thr=0.132``."""
    def value(v):
        return "/".join(f"{x:.9g}" for x in v) if isinstance(v, (list, tuple, np.ndarray)) else f"{v:.9g}"

    return name + ":" + ",".join(f"{k}={value(v)}" for k, v in params.items())


def draw_hidden_effect(name: str, rng: np.random.Generator) -> tuple[dict, dict]:
    """Parameters in a realistic range for effect ``name`` and a flight that excites it.

    Returns ``(params, fly keyword arguments)``. The ranges: wall suction k_s 3.5-8 N/m,
    d_thr 0.11-0.15 m (paper: 4.1 N/m, 0.132 m; simulation 1-10 N/m, 0.10 m); ground and
    ceiling effective radius 6-10 cm and 5-8 cm (rotor radius 3.3 cm plus the multirotor
    gain); thrust error 5-15 % either way; steady force 0.15-0.5 N per axis; extra linear
    drag 0.1-0.4 N s/m per axis (nominal 0.3, 0.3, 0.2); quadratic drag 0.05-0.15
    N s^2/m^2 per axis.
    """
    if name == "wall_suction":
        k_s, d_thr = rng.uniform(3.5, 8.0), rng.uniform(0.11, 0.15)
        # near rotors from 3 cm outside the zone to where the pull is at most ~0.5 N (never nearer than 7.5 cm)
        d_min = max(0.075, d_thr - min(0.06, 0.5 / (2 * k_s)))
        d_max = d_thr + 0.03
        survey = {"amplitude": ((d_max - d_min) / 2, 0.6, 0.3), "period": (6.0, 9.0, 5.0),
                  "centre": ((d_max + d_min) / 2 + ARM, 0.0, 1.0)}
        return {"k_s": k_s, "d_thr": d_thr}, {"scenario": "wall-survey", "survey": survey}
    if name == "ground_effect":
        return {"radius": rng.uniform(0.06, 0.10)}, {"scenario": "ground-survey"}
    if name == "ceiling_effect":
        return {"radius": rng.uniform(0.05, 0.08)}, {"scenario": "ceiling-survey"}
    if name == "thrust_scale":
        return {"scale": 1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.05, 0.15)}, {"scenario": "survey"}
    if name == "constant_force":
        return {"F": list(rng.choice([-1.0, 1.0], 3) * rng.uniform(0.15, 0.5, 3))}, {"scenario": "survey"}
    if name == "linear_drag":
        return {"D": list(rng.uniform(0.1, 0.4, 3))}, {"scenario": "survey"}
    if name == "quadratic_drag":
        return {"C": list(rng.uniform(0.05, 0.15, 3))}, {"scenario": "survey"}
    raise ValueError(name)


def relative_errors(fitted: dict, truth: dict) -> list[float]:
    """|fitted - true| / |true| for every parameter entry."""
    out = []
    for key, value in truth.items():
        f, v = np.atleast_1d(np.asarray(fitted[key], float)), np.atleast_1d(np.asarray(value, float))
        out += list(np.abs(f - v) / np.abs(v))
    return out


