"""Stand-ins: a kept effect whose parameter only soaks up a structure the library cannot describe.

A model may keep an effect only because it correlates with a residual it cannot describe:
a thrust scale that mimics a force growing with height on a climb and descent (the thrust
falls as the vehicle rises), a steady force that is the mean of it. Such an effect is a
*stand-in*: its parameter describes the flight, not the vehicle, and written as physics it
would be wrong in any other flight.

When the final model leaves more than noise (:mod:`discovery.unexplained`), each kept effect
is taken out in turn and the residual without it is asked where it lives. Unless that is
the effect's own quantity (:data:`OWN_QUANTITIES`: a ground effect and the height above
the ground), the residual gets a shape-free description of its own, :class:`Structure` (a
term linear in its coefficients, along the residual's main direction): piecewise-linear in
the localising quantity (zero where a force of that quantity vanishes: far from a surface
the flight stays near, at rest for a velocity; away from surfaces a force that depends on
where the vehicle is keeps its level, so a steady force equal to its mean is one of its
shapes; the level is the description's own along every axis, unless a steady force is fitted
beside it), one mean per cell of the position map, a sinusoid at its spectrum's peak, or
piecewise-linear in time (knots :data:`TIME_KNOT_S` apart, without its mean: a steady force
is the same at every time). Then the held-out scores decide, every parameter priced
(:func:`test_effect`): when the description in the effect's place scores better, and the
effect does not pay for itself next to it, the effect only stood in for that residual. It is
not written, and the report names it. Against a state the description is tried at several
resolutions (:data:`STATE_KNOTS`) and the best-scoring one is weighed. Parsimony protects a real
effect: a thrust scale that leaves nothing but noise beats any shape-free description of the same
force (which on a sinusoidal flight is also a function of the position). An effect that stays but whose
parameter moves by more than :data:`PROXY_SHARE` and two standard errors next to the
description acts partly as a proxy: the report gives both values.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from discovery.fitting import Candidate, Fitter
from discovery.regressors import Regressor
from discovery.residuals import FlightData, step_average_samples
from discovery.terms import Term
from wall_env.effects import Effect, FlightContext, Parameter, Wrench

__all__ = ["Structure", "StructureTerm", "structure_for", "structures_for", "test_effect", "own_quantity", "depends_on",
           "TIME_KNOT_S", "PROXY_SHARE", "OWN_QUANTITIES", "PLACE_QUANTITIES"]

TIME_KNOT_S = 2.0  # s between knots of a slowly varying structure in time
PROXY_SHARE = 0.05  # a kept parameter moving by more than this share (and two standard errors) acts partly as a proxy
_KNOTS = 8
STATE_KNOTS = (2, 4, _KNOTS)  # knots of the piecewise-linear descriptions against a state
#: the regressors that say where the vehicle is (a residual living in the position map may depend on one of them)
PLACE_QUANTITIES = ("height above ground", "distance to ceiling", "nearest rotor distance to wall")
#: the regressors an effect's own form depends on: a structure along them is that effect's shape, not a stand-in's
OWN_QUANTITIES = {
    "wall_suction": ("distance to wall",),
    "ground_effect": ("height above ground",),
    "ceiling_effect": ("distance to ceiling",),
    "linear_drag": ("velocity along body", "speed"),
    "quadratic_drag": ("velocity along body", "speed"),
    "thrust_scale": ("thrust",),
}


class Structure(Effect):
    """A shape-free force: ``sum_j c_j b_j`` over basis forces ``b_j`` per sample (a nuisance term, never written).

    The basis (per segment, ``(n, 3, size)`` N) is attached as :attr:`basis`; ``label`` names what it describes.
    """

    name = "unexplained_structure"
    description = "a shape-free description of what the model leaves (nuisance)"
    parameters = (Parameter("c", "N", 0.0, -1e4, 1e4, "coefficients of the basis forces"),)
    options = {"size": 1, "label": "", "zero": False}  # zero: the description is zero where its force vanishes

    basis: list[np.ndarray]

    def base_parameters(self) -> tuple[Parameter, ...]:
        size = int(self.option_values["size"])
        if size < 1:
            raise ValueError(f"{self.name}.size must be at least 1, got {size}")
        return (Parameter("c", "N", (0.0,) * size if size > 1 else 0.0, -1e4, 1e4, "coefficients of the basis forces"),)

    def wrench(self, ctx: FlightContext, theta: dict[str, Any]) -> Wrench:
        raise TypeError("a structure is a description of a residual, not a force on the vehicle")

    def fitting_term(self, data: FlightData) -> StructureTerm:
        """The structure's force on ``data`` as the fit sums it (:func:`discovery.fitting.make_term`)."""
        return StructureTerm(data, self)


class StructureTerm(Term):
    """``K[sum_j c_j b_j]`` per segment; affine (see :class:`discovery.terms.Term`)."""

    affine = True

    def __init__(self, data: FlightData, effect: Structure):
        self.data = data
        self.size = effect.param_size
        self.low, self.high = effect.param_bounds()
        self._basis = effect.basis
        self._at_rows = [seg.smooth_force(b, seg.fit_rows) for seg, b in zip(data.segments, effect.basis)]

    def at_rows(self, segment: int, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        jacobian = self._at_rows[segment]
        return jacobian @ np.asarray(theta, dtype=float), jacobian

    def steps(self, segment: int, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        basis = self._basis[segment]
        return step_average_samples(basis @ theta if theta.ndim == 1 else np.einsum("nap,np->na", basis, theta))


def _along(columns: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Scalar basis functions ``(n, k)`` along one world direction: ``(n, 3, k)``."""
    return columns[:, None, :] * direction[None, :, None]


def _split(data: FlightData, values: np.ndarray) -> list[np.ndarray]:
    out, start = [], 0
    for seg in data.segments:
        out.append(values[start:start + seg.n])
        start += seg.n
    return out


def structures_for(data: FlightData, where: dict, candidates: list[Regressor], effect: str = "",
                   steady_beside: bool = False, residual: np.ndarray | None = None) -> list[Structure]:
    """The :class:`Structure` descriptions of the residual that lives where ``where`` says, coarsest first: against a
    state, piecewise linear with each of :data:`STATE_KNOTS` knots (a force linear in height is two knots, and eight
    priced it out of replacing the thrust map that stood in for it); elsewhere the one of :func:`structure_for`.

    A residual that lives in the position map may vary along one of its coordinates only: it is also described
    against each distance to a surface (:data:`PLACE_QUANTITIES`) that the form of ``effect`` (the one asked about)
    does not depend on, as a state. A force growing with height, which a heavier vehicle's climb and descent left
    in the map's cells once its thrust map was taken out, took twenty-odd cell means to describe there, and the
    thrust map that stood in for it was written; two knots in height describe it.

    ``steady_beside``: a steady force is among the effects the description is fitted beside, and gives it its level
    along every axis (:func:`structure_for`). ``residual`` (``(samples, 3)`` N, the one ``where`` describes): a
    description against a distance for a residual that lives in the position map has its shape along the direction
    in which the residual varies with that distance (:func:`_varies_along`), not along the residual's main direction:
    a force growing with height, its vertical part taken by a thrust map beside it, left a residual mostly along x."""
    if where["lives_in"] == "states":
        found = [structure_for(data, where, candidates, knots=k, steady_beside=steady_beside) for k in STATE_KNOTS]
    else:
        found = [structure_for(data, where, candidates, steady_beside=steady_beside)]
    if where["lives_in"] == "position":
        for reg in candidates:
            if reg.name.startswith(PLACE_QUANTITIES) and not depends_on(effect, reg.name):
                along = {**where, "lives_in": "states", "states": {"regressor": reg.name}}
                if residual is not None:
                    along["direction_world"] = _varies_along(reg, residual) or where.get("direction_world")
                found += [structure_for(data, along, candidates, knots=k, steady_beside=steady_beside)
                          for k in STATE_KNOTS]
    return [s for s in found if s is not None]


def structure_for(data: FlightData, where: dict, candidates: list[Regressor], knots: int = _KNOTS,
                  steady_beside: bool = False) -> Structure | None:
    """A :class:`Structure` for the residual that lives where ``where`` (:func:`discovery.unexplained.where_it_lives`)
    says (against a state, piecewise linear with ``knots`` knots at its quantiles), or None when it lives nowhere in
    particular.

    A description against a state or the position map has a level of its own along every world axis, unless
    ``steady_beside``: a steady force fitted beside it is that level, and a second copy would only be priced. A force
    growing with height, flown slowly by a 2.4 kg vehicle under 2.5 times the noise: two knots in height described
    it better than the affine thrust map standing in for it, but paid for a level along every axis beside the steady
    force's, lost by 13.8 on the held-out score, and the thrust map was written."""
    lives = where["lives_in"]
    if lives == "states":
        reg = next((r for r in candidates if r.name == where["states"].get("regressor")), None)
        if reg is None:
            return None
        x = reg.values
        finite = np.isfinite(x)
        at = np.unique(np.quantile(x[finite], np.linspace(0.0, 1.0, knots)))
        if len(at) < 2:
            return None
        hats = np.zeros((len(x), len(at)))
        hats[finite] = np.column_stack([np.interp(x[finite], at, np.eye(len(at))[k]) for k in range(len(at))])
        columns, label = hats, f"piecewise linear in {reg.name} ({len(at)} knots)"
        zero = _vanishes_at(reg, x[finite])
        if zero is not None:  # the description is zero where such a force vanishes: no level of its own
            there = np.array([np.interp(zero, at, np.eye(len(at))[k]) for k in range(len(at))])
            columns = (hats - there) * finite[:, None]
            columns = np.delete(columns, int(np.argmax(there)), axis=1)
            label += f", zero at {zero:.3g} {reg.unit}"
    elif lives == "position":
        cells = where["position"]["cells"]
        p = data.concat([seg.states.p_world for seg in data.segments])
        axis = np.asarray(where["position"]["along_axis_world"], dtype=float)
        wall = next((seg.scene.walls[0] for seg in data.segments if seg.scene.walls), None)
        along = (p - (np.asarray(wall.point) if wall is not None else 0.0)) @ axis
        grounds = [seg.scene.ground_z for seg in data.segments]
        height = p[:, 2] - (grounds[0] if grounds[0] is not None and all(g == grounds[0] for g in grounds) else 0.0)
        columns = np.zeros((len(p), len(cells)))
        for c, cell in enumerate(cells):
            (u0, u1), (h0, h1) = cell["along_m"], cell["height_m"]
            columns[:, c] = (along >= u0) & (along <= u1) & (height >= h0) & (height <= h1)
        columns /= np.maximum(columns.sum(axis=1, keepdims=True), 1.0)  # samples on a cell edge are shared
        columns = columns[:, columns.any(axis=0)]
        label = "one mean per cell of the position map"
    elif lives == "time (periodic)":
        frequency = where["time"]["peak_hz"]
        t = data.times
        columns = np.column_stack([np.sin(2 * np.pi * frequency * t), np.cos(2 * np.pi * frequency * t)])
        label = f"a sinusoid at {frequency:.3g} Hz"
    elif lives == "time (slow)":
        blocks = []
        for seg in data.segments:
            times = np.arange(seg.t[0], seg.t[-1] + TIME_KNOT_S, TIME_KNOT_S)
            blocks.append(np.column_stack([np.interp(seg.t, times, np.eye(len(times))[k]) for k in range(len(times))]))
        width = sum(b.shape[1] for b in blocks)
        columns = np.zeros((data.n_samples, width))
        row = col = 0
        for b in blocks:
            # less each segment's mean: a steady force is the same at every time, and a description of how the
            # residual varies in time must leave it to the effects
            columns[row:row + b.shape[0], col:col + b.shape[1]] = b - b.mean(axis=0)
            row, col = row + b.shape[0], col + b.shape[1]
        label = f"piecewise linear in time, knots {TIME_KNOT_S:g} s apart, without its mean"
    else:
        return None
    direction = np.asarray(where.get("direction_world") or (0.0, 0.0, 1.0), dtype=float)
    basis = _along(columns, direction / np.linalg.norm(direction))
    zero = lives == "states" and "zero at" in label
    if lives in ("states", "position") and not zero:
        # its level is its own, along every world axis (the residual's main direction is only estimated): the
        # shape along that direction less one of its functions (they sum to one), and a constant per axis unless
        # a steady force beside it is that constant
        level = np.zeros((len(columns), 3, 0 if steady_beside else 3))
        if steady_beside:
            label += ", its level the steady force's"
        else:
            level[:, 0, 0] = level[:, 1, 1] = level[:, 2, 2] = 1.0
        basis = np.concatenate([basis[:, :, :-1], level], axis=2)
    structure = Structure(size=basis.shape[2], label=label, zero=zero)
    structure.basis = _split(data, basis)
    return structure


def _varies_along(reg: Regressor, residual: np.ndarray) -> list[float] | None:
    """The unit world direction of the covariance of ``residual`` (``(samples, 3)`` N) with ``reg``'s values, over
    the samples where they are known; ``None`` when it vanishes."""
    x = np.asarray(reg.values, dtype=float)
    known = np.isfinite(x) & np.all(np.isfinite(residual), axis=1)
    if known.sum() < 2:
        return None
    covariance = (x[known] - x[known].mean()) @ (residual[known] - residual[known].mean(axis=0))
    size = float(np.linalg.norm(covariance))
    return (covariance / size).tolist() if size > 0.0 else None


def _vanishes_at(reg: Regressor, values: np.ndarray) -> float | None:
    """Where a force that depends on ``reg`` vanishes, when physics says it does: far from a surface it is near
    (within :data:`~discovery.coverage.NEAR_SURFACE` over most of the flight), and at rest for a velocity. A force
    that depends on where the vehicle is, away from any surface, has no such place: its level is its own."""
    from discovery.coverage import NEAR_SURFACE

    if any(q in reg.name for q in ("distance to wall", "height above ground", "distance to ceiling")):
        return float(values.max()) if float(np.median(values)) <= NEAR_SURFACE else None
    if reg.name.startswith("velocity along body") or reg.name == "speed":
        return 0.0
    return None


def depends_on(effect_name: str, regressor: str) -> bool:
    """Whether the form of the effect ``effect_name`` depends on the regressor named ``regressor``
    (:data:`OWN_QUANTITIES`)."""
    return any(q in regressor for q in OWN_QUANTITIES.get(effect_name, ()))


def own_quantity(effect: Effect, where: dict) -> bool:
    """Whether the residual lives along ``effect``'s own quantity: the structure's regressor is one ``effect``'s form
    depends on."""
    return where["lives_in"] == "states" and depends_on(effect.name, where["states"].get("regressor") or "")


def test_effect(fitter: Fitter, final: Candidate, index: int, structures: list[Structure], where: dict, price: float,
                hold: dict[str, dict[int, float]]) -> tuple[dict | None, list[dict]]:
    """Effect ``index`` of the kept set ``final`` (fitted with the entries ``hold`` held) against the one of
    ``structures`` that scores best in its place, on held-out data (the fitter's scores): a stand-in record when that
    structure in its place scores better and the effect does not pay next to it, else the parameters the structure
    moves (proxies). In its place the other effects are fitted with nothing held: an entry held at zero only because
    this effect stood beside it (a vertical steady force that a thrust scale had taken over) takes its share back."""
    keys = list(final.names)
    key = keys[index]
    others = [k for k in keys if k != key]
    previous = final.previous()
    tried = []
    for structure in structures:
        label = f"structure: {structure.option_values['label']}"
        fitter.add(label, structure)
        tried.append((fitter.candidate(others + [label], previous=previous), label, structure))
    replaced, label, structure = min(tried, key=lambda t: t[0].score)
    joint = fitter.candidate(keys + [label], previous=previous, hold=hold)
    effect = final.fit.effects[index]
    if replaced.score < final.score and joint.score > replaced.score - price:
        return {"effect": effect.name, "key": key, "params": effect.params_dict(),
                "with_structure": joint.fit.effects[index].params_dict(), "lives_in": where["lives_in"],
                "reason": f"without it, the residual {_describe(where)}; {structure.option_values['label']} in its "
                          f"place scores better on held-out data ({replaced.score - final.score:.1f}, parameters "
                          f"priced), and next to that description {effect.name} does not pay for itself "
                          f"({joint.score - replaced.score:+.1f} against a price of {price:.1f}): it only stood in "
                          "for that residual"}, []
    moved, std = joint.fit.effects[index], final.fit.std_dicts()[index]
    proxies = []
    for p in effect.parameters:
        without = np.atleast_1d(effect.values[p.name])
        with_ = np.atleast_1d(moved.values[p.name])
        error = np.atleast_1d(np.asarray(std.get(p.name, np.nan), dtype=float))
        largest = float(np.max(np.abs(without))) if without.size else 0.0
        for j, (x, y) in enumerate(zip(without, with_)):
            e = float(error[j]) if j < error.size else float("nan")
            material = abs(x) >= PROXY_SHARE * largest * 2  # a vector's small entries move by their noise
            if material and x != 0 and abs(y - x) > PROXY_SHARE * abs(x) and np.isfinite(e) and abs(y - x) > 2 * e:
                proxies.append({"effect": effect.name, "parameter": p.entry_name(j),
                                "without": float(x), "with": float(y), "std": e, "lives_in": _describe(where)})
    return None, proxies


def _describe(where: dict) -> str:
    lives = where["lives_in"]
    if lives == "states":
        return f"depends on {where['states'].get('regressor')}"
    if lives == "position":
        return "lives in a region of the flight"
    if lives.startswith("time"):
        return f"varies in time ({lives[6:-1]})"
    return "is spread over the flight"
