"""Effects that cancel each other: look-alikes a flight near hover cannot tell apart, and the simpler account.

At nearly constant thrust a thrust scale, a vertical steady force and a vertical wind in
the quadratic drag all push along the vertical by a nearly constant amount: fitted
together, they can grow large in opposite directions while their sum stays what the
data show (a 1.39 thrust scale, a -11.9 N steady force and a 16.3 m/s vertical wind on one
wind-tunnel flight in still air). :func:`cancelling_sets` finds such sets among the kept
effects: two or more effects, each with a material force, whose summed force is less
than :data:`CANCEL_SHARE` of the largest of them (rms over the flight).

Each set is reported as look-alikes with the manoeuvre that separates them; and the
simpler accounts are scored on held-out data (:func:`simpler`): the set without one of
its members, the affine thrust map in the set's place (when a thrust scale is in it), or
nothing in its place. The simplest account within one parameter's price of the best
score is kept: the data cannot tell it from the cancelling set, and it says less that
is wrong.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from discovery.determination import separating_manoeuvre
from discovery.fitting import Candidate, Fitter

__all__ = ["CANCEL_SHARE", "cancelling_sets", "simpler", "manoeuvre"]

CANCEL_SHARE = 0.3  # a set whose summed force is less than this share of its largest member's cancels


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(x**2, axis=1)))) if len(x) else 0.0


def cancelling_sets(names: list[str], forces: list[np.ndarray], floor: float) -> list[dict]:
    """Subsets of the kept effects (``names``, their forces ``(N, 3)`` at every sample) that cancel: each member's
    force at least ``floor`` (N rms), their sum less than :data:`CANCEL_SHARE` of the largest.
    ``[{"effects", "force_rms_N", "sum_rms_N"}]``, largest sets first, no set inside another."""
    sizes = [_rms(f) for f in forces]
    found: list[dict] = []
    for size in range(len(names), 1, -1):
        for subset in combinations(range(len(names)), size):
            if any(set(subset) <= set(s["index"]) for s in found):
                continue
            if min(sizes[i] for i in subset) < floor:
                continue
            total = _rms(np.sum([forces[i] for i in subset], axis=0))
            if total < CANCEL_SHARE * max(sizes[i] for i in subset):
                found.append({"index": list(subset), "effects": [names[i] for i in subset],
                              "force_rms_N": [round(sizes[i], 4) for i in subset], "sum_rms_N": round(total, 4)})
    return found


def manoeuvre(effects: list[str]) -> str:
    """The flight that separates a set of look-alikes."""
    names = sorted(set(effects))
    if len(names) == 2:
        return separating_manoeuvre(names[0], names[1])
    return ("climb and descend briskly over a wide range of thrust (70 % to 130 % of the weight), fly at several "
            "speeds in each direction, and, with a wind, fly in it and in still air: each of these effects grows "
            "with a different one of these")


def simpler(fitter: Fitter, final: Candidate, cancelling: dict, price: float,
            hold: dict[str, dict[int, float]]) -> tuple[Candidate, str]:
    """The simplest account of a cancelling set within one parameter's ``price`` of the best held-out score among:
    the kept set, it without one or more members of the set, and the affine thrust map in the set's place."""
    keys = list(final.names)
    members = [keys[i] for i in cancelling["index"]]
    others = [k for k in keys if k not in members]
    options: list[tuple[list[str], str]] = [(keys, "the kept effects")]
    for size in range(len(members) - 1, -1, -1):
        for kept in combinations(members, size):
            options.append((others + list(kept), f"without {', '.join(m for m in members if m not in kept)}"))
    if any(m.split("[")[0] == "thrust_scale" for m in members) and "thrust_scale[affine]" in fitter.templates:
        options.append((others + ["thrust_scale[affine]"], "the affine thrust map in their place"))
    scored = []
    for names, label in options:
        candidate = fitter.candidate(names, previous=final.previous(),
                                     hold={k: v for k, v in hold.items() if k in names})
        scored.append((candidate, label))
    best = min(c.score for c, _ in scored)
    within = [(c, label) for c, label in scored if c.score <= best + price]
    return min(within, key=lambda item: (item[0].n_params, item[0].score))
