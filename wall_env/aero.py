"""The aerodynamic model: a set of effects from the library, summed into one wrench.

An :class:`AeroModel` packs the parameters of its effects into one vector ``theta``
(in the order of the effects, then of each effect's parameters) so that the
simulator can change them between episodes without rebuilding anything, and the
identification code can differentiate with respect to them.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from wall_env.effects import Effect, FlightContext, Wrench, effects_from_spec, make_effect
from wall_env.scene import Scene, SceneSymbols, scene_symbols
from wall_env.vehicle import GRAVITY

__all__ = ["AeroModel"]


class AeroModel:
    """Sum of effects. ``AeroModel.from_spec({"wall_suction": {"k_s": 4.1}})`` or from instances."""

    def __init__(self, effects: Sequence[Effect] = ()):
        self.effects: tuple[Effect, ...] = tuple(effects)
        names = [e.name for e in self.effects]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"each effect may appear once in a model; repeated: {duplicates}")

    @classmethod
    def from_spec(cls, spec: Any) -> AeroModel:
        return cls(effects_from_spec(spec))

    # ------------------------------------------------------------------ parameters
    @property
    def names(self) -> list[str]:
        return [e.name for e in self.effects]

    @property
    def param_size(self) -> int:
        return sum(e.param_size for e in self.effects)

    def theta(self) -> np.ndarray:
        """Current parameter values, packed."""
        parts = [e.param_vector() for e in self.effects]
        return np.concatenate(parts) if parts else np.zeros(0)

    def slices(self) -> list[slice]:
        out, index = [], 0
        for e in self.effects:
            out.append(slice(index, index + e.param_size))
            index += e.param_size
        return out

    def param_labels(self) -> list[str]:
        return [f"{e.name}.{label}" for e in self.effects for label in e.param_labels()]

    def get(self, name: str) -> Effect | None:
        return next((e for e in self.effects if e.name == name), None)

    def with_effect(self, effect: Effect) -> AeroModel:
        """This model with ``effect`` added, or replacing the effect of the same name."""
        kept = [e for e in self.effects if e.name != effect.name]
        return AeroModel([*kept, effect])

    def without(self, name: str) -> AeroModel:
        return AeroModel([e for e in self.effects if e.name != name])

    def to_list(self) -> list[dict[str, Any]]:
        return [e.to_dict() for e in self.effects]

    def __repr__(self) -> str:
        return f"AeroModel({list(self.effects)!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, AeroModel) and list(self.effects) == list(other.effects)

    __hash__ = None  # type: ignore[assignment]

    # ------------------------------------------------------------------ symbolic
    @property
    def structure_key(self) -> tuple:
        """What the symbolic expression depends on besides the numeric parameters."""
        return tuple((e.name, tuple(sorted(e.option_values.items()))) for e in self.effects)

    def wrench(self, ctx: FlightContext, theta: ca.SX, scene_structure: tuple) -> tuple[Wrench, list[ca.SX]]:
        """Total wrench and each effect's force (zeros where an effect has nothing to act against)."""
        total = Wrench.zero()
        forces = []
        for effect, sl in zip(self.effects, self.slices()):
            if effect.applies_to(scene_structure):
                w = effect.wrench(ctx, effect.unpack(theta[sl]))
            else:
                w = Wrench.zero()
            total = Wrench(total.force_world + w.force_world, total.moment_body + w.moment_body)
            forces.append(w.force_world)
        return total, forces

    def function(self, rotor_positions_body: np.ndarray, scene: Scene, gravity: float = GRAVITY) -> ca.Function:
        """CasADi function of the wrench.

        ``aero_wrench(p_world[3], R_body_to_world[3x3], v_world[3], omega_body[3],
        rotor_thrusts[4], mass, theta[param_size], scene[scene.vector_size])
        -> (force_world[3], moment_body[3], effect_forces_world[3 x n_effects])``
        """
        return self.structure_function(rotor_positions_body, scene.structure, gravity)

    def structure_function(self, rotor_positions_body: np.ndarray, scene_structure: tuple,
                           gravity: float = GRAVITY) -> ca.Function:
        """:meth:`function` for a scene structure (:class:`~wall_env.scene.SceneStructure`) instead of a scene."""
        rotors = tuple(map(tuple, np.asarray(rotor_positions_body, dtype=float)))
        return _wrench_function(self.structure_key, rotors, tuple(scene_structure), float(gravity))


def symbolic_scene(structure: tuple) -> tuple[SceneSymbols, ca.SX]:
    """Scene symbols for a structure (:class:`~wall_env.scene.SceneStructure`: wall count, has ground, has
    ceiling, local surface slots per rotor)."""
    return scene_symbols(structure)


@lru_cache(maxsize=64)
def _wrench_function(structure_key: tuple, rotors: tuple, scene_structure: tuple, gravity: float) -> ca.Function:
    # Built from the structure only: models that differ in parameter values share one function.
    model = AeroModel([make_effect(name, **dict(options)) for name, options in structure_key])
    p = ca.SX.sym("p_world", 3)
    R = ca.SX.sym("R_body_to_world", 3, 3)
    v = ca.SX.sym("v_world", 3)
    omega = ca.SX.sym("omega_body", 3)
    thrusts = ca.SX.sym("rotor_thrusts", 4)
    mass = ca.SX.sym("mass")
    theta = ca.SX.sym("theta", model.param_size)
    scene_symbols, scene_vector = symbolic_scene(scene_structure)
    ctx = FlightContext(p, R, v, omega, thrusts, np.asarray(rotors), mass, gravity, scene_symbols)
    total, forces = model.wrench(ctx, theta, scene_structure)
    effect_forces = ca.horzcat(*forces) if forces else ca.SX.zeros(3, 0)
    return ca.Function(
        "aero_wrench",
        [p, R, v, omega, thrusts, mass, theta, scene_vector],
        [total.force_world, total.moment_body, effect_forces],
        ["p_world", "R_body_to_world", "v_world", "omega_body", "rotor_thrusts", "mass", "theta", "scene"],
        ["force_world", "moment_body", "effect_forces_world"],
    )


def rotor_suction_function(model: AeroModel, rotor_positions_body: np.ndarray, scene_structure: tuple,
                           gravity: float = GRAVITY) -> ca.Function | None:
    """Each rotor's force of the model's ``wall_suction`` (None without one):
    ``rotor_suction(p_world[3], R_body_to_world[3x3], v_world[3], omega_body[3], rotor_thrusts[4], mass, theta,
    scene) -> rotor_forces_world[3x4]``, from the effect's own definition."""
    if model.get("wall_suction") is None:
        return None
    rotors = tuple(map(tuple, np.asarray(rotor_positions_body, dtype=float)))
    return _rotor_suction_function(model.structure_key, rotors, tuple(scene_structure), float(gravity))


@lru_cache(maxsize=16)
def _rotor_suction_function(structure_key: tuple, rotors: tuple, scene_structure: tuple, gravity: float
                            ) -> ca.Function:
    model = AeroModel([make_effect(name, **dict(options)) for name, options in structure_key])
    p, v, omega = ca.SX.sym("p_world", 3), ca.SX.sym("v_world", 3), ca.SX.sym("omega_body", 3)
    R = ca.SX.sym("R_body_to_world", 3, 3)
    thrusts, mass = ca.SX.sym("rotor_thrusts", 4), ca.SX.sym("mass")
    theta = ca.SX.sym("theta", model.param_size)
    symbols, scene_vector = symbolic_scene(scene_structure)
    ctx = FlightContext(p, R, v, omega, thrusts, np.asarray(rotors), mass, gravity, symbols)
    index = model.names.index("wall_suction")
    suction = model.effects[index]
    forces = suction.rotor_forces(ctx, suction.unpack(theta[model.slices()[index]]))  # type: ignore[attr-defined]
    if not suction.applies_to(scene_structure):
        forces = [ca.SX.zeros(3) for _ in forces]
    return ca.Function("rotor_suction", [p, R, v, omega, thrusts, mass, theta, scene_vector], [ca.horzcat(*forces)],
                       ["p_world", "R_body_to_world", "v_world", "omega_body", "rotor_thrusts", "mass", "theta",
                        "scene"], ["rotor_forces_world"])
