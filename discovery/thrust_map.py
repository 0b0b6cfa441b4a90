"""An affine thrust map as one candidate: the rotors produce ``scale x command + offset``.

A log's thrust is a command mapped to newtons by a nominal thrust map (a hover fit, a
datasheet coefficient, PX4's hover thrust). When the map is off by a scale and an
offset, the residual of the nominal model is ``((scale - 1) T + offset) z_body``: the
library's ``thrust_scale`` describes the first part, and a steady vertical force plus
other effects stand in for the second. In still air near hover the three cancel each
other (a 1.39 thrust scale, a -11.9 N vertical steady force and a 16.3 m/s vertical wind
in one wind-tunnel flight), and the model file says something wrong about all three.

So the fuller form of ``thrust_scale`` with the ``affine`` option is a candidate of its own
(key ``thrust_scale[affine]``, :data:`discovery.selection.VARIANTS`): two parameters, the
scale and the offset (N, of the collective thrust, along the body z axis), judged like every
other fuller form, kept only when its offset is determined. Its scale part is exactly the
library's ``thrust_scale`` (``(scale - 1) f_j`` at each rotor); the offset adds ``offset / 4``
to each rotor. :class:`ThrustMap` is that form; :class:`ThrustMapTerm` evaluates it for the
fits (it is affine in its parameters: ``((scale - 1) T + offset) z_body``).

The effects library has no thrust offset, so a model file cannot carry one as such:
:func:`written_effects` writes the map as the library's ``thrust_scale`` and a steady force
``(0, 0, offset)`` (the same force in level flight, ``offset`` times the tilt's sine off
sideways when tilted), and the report says so.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from discovery.residuals import FlightData, step_average_samples
from discovery.terms import Term
from wall_env.effects import Effect, FlightContext, Parameter, ThrustScale, Wrench, make_effect

__all__ = ["ThrustMap", "ThrustMapTerm", "OFFSET", "make_candidate", "written_effects", "WRITTEN_NOTE"]

OFFSET = Parameter("offset", "N", 0.0, -50.0, 50.0,
                   "thrust produced at zero command (collective, along body z): the affine thrust map's offset")

WRITTEN_NOTE = ("the affine thrust map is written into the model file as thrust_scale and a vertical steady force "
                "equal to its offset (the effects library has no thrust offset): the same force in level flight, "
                "the offset times the sine of the tilt off sideways when tilted")


class ThrustMap(ThrustScale):
    """``thrust_scale`` with an offset: actual rotor thrust = scale x command + offset / 4 (an affine thrust map)."""

    description = "actual collective thrust = scale x command + offset (affine thrust map)"
    reference = "thrust map (command to newtons) off by a scale and an offset"
    options = {"affine": True}
    optional_parameters = {"affine": (OFFSET,)}

    def __init__(self, **kwargs) -> None:
        kwargs.setdefault("affine", True)
        super().__init__(**kwargs)
        if not self.option_values["affine"]:
            raise ValueError("thrust_scale[affine] is the affine thrust map; the plain form is wall_env's thrust_scale")

    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        return Wrench.from_rotor_thrust_changes(
            ctx, [(theta["scale"] - 1.0) * ctx.rotor_thrusts[j] + theta["offset"] / 4.0 for j in range(4)])

    def fitting_term(self, data: FlightData) -> ThrustMapTerm:
        """The map's force on ``data`` as the fit sums it (:func:`discovery.fitting.make_term`)."""
        return ThrustMapTerm(data, self)


def make_candidate(name: str, **options) -> Effect:
    """A library effect by name, or the thrust map for ``thrust_scale`` with the ``affine`` option."""
    if name == "thrust_scale" and options.get("affine"):
        return ThrustMap(**options)
    return make_effect(name, **options)


class ThrustMapTerm(Term):
    """``K[((scale - 1) T + offset) z_body]`` per segment; affine, so evaluated once (see
    :class:`discovery.terms.Term`). ``T`` is the rotor thrust the nominal model takes as produced."""

    affine = True

    def __init__(self, data: FlightData, effect: ThrustMap):
        self.data = data
        self.size = effect.param_size  # scale, offset
        self.low, self.high = effect.param_bounds()
        self._base = []
        for seg in data.segments:
            z_body = seg.states.R_body_to_world[:, :, 2]
            thrust = seg.states.rotor_thrusts.sum(axis=1)
            columns = np.stack([thrust[:, None] * z_body, z_body], axis=2)  # (n, 3, 2): d/d scale, d/d offset
            self._base.append((seg.smooth_force(columns, seg.fit_rows), columns))

    def _theta(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        return theta - np.array([1.0, 0.0]) if theta.ndim == 1 else theta - np.array([[1.0, 0.0]])

    def at_rows(self, segment: int, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        jacobian, _ = self._base[segment]
        return jacobian @ self._theta(theta), jacobian

    def steps(self, segment: int, theta: np.ndarray) -> np.ndarray:
        _, columns = self._base[segment]
        shifted = self._theta(theta)
        return step_average_samples(np.einsum("nap,np->na", columns, np.broadcast_to(shifted, (columns.shape[0], 2))))


def written_effects(effects: list[Effect]) -> tuple[list[Effect], list[str]]:
    """``effects`` as the library can write them: a thrust map becomes ``thrust_scale`` and a vertical
    ``constant_force`` (added to one already there). Returns the effects and notes on what was changed."""
    maps = [e for e in effects if isinstance(e, ThrustMap)]
    if not maps:
        return list(effects), []
    thrust_map = maps[0]
    offset = float(thrust_map.values["offset"][0])
    out: list[Effect] = []
    steady = next((e for e in effects if e.name == "constant_force"), None)
    for effect in effects:
        if effect is thrust_map:
            out.append(make_effect("thrust_scale", scale=float(thrust_map.values["scale"][0])))
        elif effect is not steady:
            out.append(effect)
    force = np.zeros(3) if steady is None else np.asarray(steady.values["F"], dtype=float).copy()
    force[2] += offset
    out.append(make_effect("constant_force", F=force))
    return out, [WRITTEN_NOTE]
