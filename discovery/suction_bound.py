"""How strong a wall suction the flight could have missed, when none was found near a wall.

"No wall suction" from a flight that came near a wall means only that none stood out of the
noise. :func:`suction_bound` says how much could hide there: for each threshold distance
``d_thr`` of :data:`THRESHOLDS_M` that reaches :data:`INSIDE_M` past the rotors' closest approach, ``k_s`` is
fitted (beside the effects kept) with ``d_thr`` held, and its 95 % upper bound turned into the
pull on one rotor at that closest approach, ``(k_s + 1.96 sigma) (d_thr - d_min)``. The largest
over the thresholds is the bound: a suction with its threshold in that range that pulls a rotor
less than that at the closest approach cannot be told from none on this flight. One acting only
nearer the wall than the rotors came has no force on the flight at all.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from discovery.determination import Z_95, determining_manoeuvre, entry

if TYPE_CHECKING:
    from discovery.fitting import Candidate, Fitter

__all__ = ["THRESHOLDS_M", "INSIDE_M", "suction_bound"]

#: threshold distances (m) the bound is taken over: from well inside the paper's 0.13 m to twice it
THRESHOLDS_M = (0.07, 0.1, 0.13, 0.17, 0.22, 0.28)
#: m: a threshold is used when it reaches this far past the closest approach (a suction felt over the last few
#: millimetres only is bounded by a handful of samples)
INSIDE_M = 0.02


def suction_bound(fitter: Fitter, final: Candidate, closest_m: float, hold: dict[str, dict[int, float]] | None = None,
                  key: str = "wall_suction") -> dict | None:
    """The limit ``{"effects", "reason", "manoeuvre", "bound_N"}`` on a wall suction the flight did not find,
    its rotors having come within ``closest_m`` of a wall; ``hold``: entries the kept effects were fitted with held
    (``{key: {entry: value}}``, kept held). None when no threshold reaches past that distance or the fits cannot
    bound it (nothing of the suction's force on the flight)."""
    template = fitter.templates.get(key)
    if template is None:
        return None
    keys = [k for k in final.names if fitter.templates[k].name != template.name] + [key]
    position = entry(template, "d_thr", None)
    problem = fitter.problem(keys)
    e = problem.layout.keys.index(key)
    start = problem.starts({k: v for k, v in final.previous().items() if k in keys})[0]
    bounds = []
    for d_thr in (d for d in THRESHOLDS_M if d >= closest_m + INSIDE_M):
        theta0 = start.copy()
        held = problem.layout.hold(theta0, {**(hold or {}), key: {position: d_thr}})
        fit = problem.fit(theta0=theta0, held=held)
        k_s, sigma = problem.layout.split(fit.theta, 0)[e][0], problem.layout.split(fit.param_std, 0)[e][0]
        if not (np.isfinite(sigma) and sigma > 0):
            continue
        bounds.append(((max(float(k_s), 0.0) + Z_95 * float(sigma)) * (d_thr - closest_m), d_thr))
    if not bounds:
        return None
    pull, d_thr = max(bounds)
    used = [d for _, d in bounds]
    return {"effects": [template.name],
            "reason": f"no wall suction found, though the rotors came within {100 * closest_m:.1f} cm of a wall: "
                      f"there its pull on a rotor is at most {pull:.2g} N (95 %, the largest over thresholds "
                      f"d_thr of {100 * min(used):.0f}-{100 * max(used):.0f} cm, at {100 * d_thr:.0f} cm; with the "
                      "scene's walls as given): a suction with its threshold in that range that pulls less cannot be "
                      "told from none on this flight",
            "manoeuvre": determining_manoeuvre(template.name, "d_thr"),
            "bound_N": pull}
