"""What an aerodynamic effect is: named parameters with units and ranges, and one symbolic wrench.

Every effect writes, once and in CasADi, the force (world frame) and moment (body
frame) it puts on the vehicle as a function of the flight state, the rotor thrusts
and the scene. The simulator compiles that expression, the MPC puts it in its
prediction model and the identification code differentiates it; no effect is
written a second time anywhere.

Effects are additive perturbations evaluated at the rotor thrusts that the mixer
produces: the total aerodynamic wrench is the sum of the effects' wrenches.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from wall_env.scene import SceneSymbols

__all__ = ["Parameter", "FlightContext", "Wrench", "Effect"]


@dataclass(frozen=True)
class Parameter:
    """One parameter of an effect: scalar (``size == 1``) or a vector of ``size`` entries."""

    name: str
    unit: str
    default: float | tuple[float, ...]
    low: float
    high: float
    description: str
    #: "world" for a vector along the world axes (a steady force, a wind): its horizontal components turn with the
    #: frame the log is written in, so discovery judges them together; "body" for one coefficient per body axis (a
    #: drag), each its own quantity, whose spread discovery measures against that coefficient
    #: (:mod:`discovery.determination`)
    frame: str = ""

    @property
    def size(self) -> int:
        return len(self.default) if isinstance(self.default, tuple) else 1

    def entry_name(self, index: int) -> str:
        """How reports name entry ``index``: ``D[2]`` of a vector, the bare name of a scalar."""
        return self.name if self.size == 1 else f"{self.name}[{index}]"

    def validate(self, effect: str, value: Any) -> np.ndarray:
        try:
            array = np.asarray(value, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"{effect}.{self.name} must be numeric ({self.unit}), got {value!r}") from None
        if array.size != self.size:
            raise ValueError(f"{effect}.{self.name} must have {self.size} value(s), got {array.size}")
        if not np.all(np.isfinite(array)) or np.any(array < self.low) or np.any(array > self.high):
            raise ValueError(
                f"{effect}.{self.name} must be in [{self.low:g}, {self.high:g}] {self.unit}, got {array.tolist()}"
            )
        return array


@dataclass(frozen=True)
class FlightContext:
    """Symbolic quantities an effect may read. Frames are in the names."""

    p_world: ca.SX  # 3x1, centre of mass, m
    R_body_to_world: ca.SX  # 3x3
    v_world: ca.SX  # 3x1, m/s
    omega_body: ca.SX  # 3x1, rad/s
    rotor_thrusts: ca.SX  # 4x1, N, what the rotors produce before any effect
    rotor_positions_body: np.ndarray  # (4, 3), m
    mass: ca.SX  # kg
    gravity: float  # m/s^2
    scene: SceneSymbols

    def rotor_position_world(self, j: int) -> ca.SX:
        return self.p_world + self.R_body_to_world @ ca.DM(self.rotor_positions_body[j])

    @property
    def hover_rotor_thrust(self) -> ca.SX:
        return self.mass * self.gravity / 4.0


@dataclass(frozen=True)
class Wrench:
    """Force in the world frame (N) and moment about the centre of mass in the body frame (N m)."""

    force_world: ca.SX
    moment_body: ca.SX

    @staticmethod
    def zero() -> Wrench:
        return Wrench(ca.SX.zeros(3), ca.SX.zeros(3))

    @staticmethod
    def from_rotor_forces(ctx: FlightContext, forces_world: list[ca.SX]) -> Wrench:
        """Forces acting at the rotor centres: their sum and their moment about the centre of mass."""
        force = ca.SX.zeros(3)
        moment = ca.SX.zeros(3)
        R_world_to_body = ctx.R_body_to_world.T
        for j, f_world in enumerate(forces_world):
            force += f_world
            moment += ca.cross(ca.DM(ctx.rotor_positions_body[j]), R_world_to_body @ f_world)
        return Wrench(force, moment)

    @staticmethod
    def from_rotor_thrust_changes(ctx: FlightContext, extra_thrusts: list[ca.SX]) -> Wrench:
        """Extra thrust along +z_body at each rotor (ground effect, thrust mismatch, ...)."""
        z_body = ctx.R_body_to_world[:, 2]
        return Wrench.from_rotor_forces(ctx, [z_body * t for t in extra_thrusts])


class Effect(ABC):
    """Base class: subclasses set ``name``, ``description``, ``parameters`` and write :meth:`wrench`.

    Construct with parameter values and options as keyword arguments; omitted
    parameters take their defaults. Values are validated against their ranges.
    """

    name: ClassVar[str]
    description: ClassVar[str]
    reference: ClassVar[str] = ""
    parameters: ClassVar[tuple[Parameter, ...]]
    options: ClassVar[dict[str, Any]] = {}
    #: parameters that exist only when a boolean option is on (the literature's fuller forms);
    #: giving one of them switches its option on
    optional_parameters: ClassVar[dict[str, tuple[Parameter, ...]]] = {}

    def __init__(self, **kwargs: Any) -> None:
        extra = {p.name: option for option, params in self.optional_parameters.items() for p in params}
        self.option_values: dict[str, Any] = {}
        for option, default in self.options.items():
            value = kwargs.get(option, default)
            if option in self.optional_parameters and option not in kwargs:
                value = any(name in kwargs for name, owner in extra.items() if owner == option)
            if type(value) is not type(default):
                raise ValueError(f"{self.name}.{option} must be a {type(default).__name__}, got {value!r}")
            self.option_values[option] = value
        # the parameters of this instance: the base ones plus those of the options switched on
        self.parameters = self.base_parameters() + tuple(  # type: ignore[misc]  # per instance: options add some
            p for option, params in self.optional_parameters.items() if self.option_values[option] for p in params)
        known_params = {p.name: p for p in self.parameters}
        unknown = sorted(set(kwargs) - set(known_params) - set(self.options))
        if unknown:
            allowed = sorted(known_params) + sorted(self.options)
            off = [n for n in unknown if n in extra]
            hint = f" ({', '.join(off)} need(s) option {sorted({extra[n] for n in off})} on)" if off else ""
            raise ValueError(f"unknown argument(s) {unknown} for effect {self.name!r}; allowed: {allowed}{hint}")
        self.values: dict[str, np.ndarray] = {
            name: p.validate(self.name, kwargs.get(name, p.default)) for name, p in known_params.items()
        }

    def base_parameters(self) -> tuple[Parameter, ...]:
        """This instance's parameters before the optional ones: the class's, unless a subclass sizes
        them by its options (:attr:`option_values` is set when this is called)."""
        return type(self).parameters

    # ------------------------------------------------------------------ symbolic
    @abstractmethod
    def wrench(self, ctx: FlightContext, theta: dict[str, ca.SX]) -> Wrench:
        """The force and moment this effect puts on the vehicle, symbolically."""

    def applies_to(self, scene_structure: tuple) -> bool:
        """Whether the scene has what this effect acts against (walls, ground, ceiling)."""
        return True

    # ------------------------------------------------------------------ values
    @property
    def param_size(self) -> int:
        return sum(p.size for p in self.parameters)

    def param_vector(self) -> np.ndarray:
        return np.concatenate([self.values[p.name] for p in self.parameters]) if self.parameters else np.zeros(0)

    def unpack(self, vector: Any) -> dict[str, Any]:
        """Split a flat parameter vector (numeric or symbolic) into named entries."""
        out, index = {}, 0
        for p in self.parameters:
            out[p.name] = vector[index : index + p.size] if p.size > 1 else vector[index]
            index += p.size
        return out

    def params_dict(self, vector: np.ndarray | None = None) -> dict[str, float | list[float]]:
        """Plain Python values of the parameters (for JSON), from ``vector`` or the current values."""
        values = self.unpack(self.param_vector() if vector is None else np.asarray(vector, dtype=float))
        return {k: (float(v) if np.ndim(v) == 0 else [float(x) for x in v]) for k, v in values.items()}

    def with_params(self, vector: np.ndarray) -> Effect:
        """A copy of this effect with parameter values from a flat vector (validated)."""
        return type(self)(**self.params_dict(vector), **self.option_values)

    def param_labels(self) -> list[str]:
        labels = []
        for p in self.parameters:
            labels += [p.name] if p.size == 1 else [f"{p.name}[{i}]" for i in range(p.size)]
        return labels

    def param_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        low = np.concatenate([np.full(p.size, p.low) for p in self.parameters]) if self.parameters else np.zeros(0)
        high = np.concatenate([np.full(p.size, p.high) for p in self.parameters]) if self.parameters else np.zeros(0)
        return low, high

    def to_dict(self) -> dict[str, Any]:
        data: dict[str, Any] = {"name": self.name, "params": self.params_dict()}
        if self.option_values:
            data["options"] = dict(self.option_values)
        return data

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v}" for k, v in {**self.params_dict(), **self.option_values}.items())
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Effect)
            and other.name == self.name
            and other.option_values == self.option_values
            and np.array_equal(other.param_vector(), self.param_vector())
        )

    __hash__ = None  # type: ignore[assignment]
