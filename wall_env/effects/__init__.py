"""The effects library: every aerodynamic effect the simulator, the MPC and identification share.

=================  ======================================  ====================
name               what                                    parameters
=================  ======================================  ====================
``wall_suction``   per-rotor pull toward wall planes       k_s (N/m), d_thr (m)
``linear_drag``    body drag proportional to velocity      D (N s/m, x3)
``quadratic_drag`` body drag proportional to velocity^2    C (N s^2/m^2, x3)
``ground_effect``  per-rotor thrust gain near the ground   radius (m)
``ceiling_effect`` per-rotor thrust gain under a ceiling   radius (m)
``thrust_scale``   actual thrust = scale x command         scale (-)
``constant_force`` steady world-frame force (wind, bias)   F (N, x3)
=================  ======================================  ====================

Fuller forms from the literature, switched on by an option (or by giving their
parameter): ``ground_effect`` and ``ceiling_effect`` with ``distance_offset`` (parameter
``offset``, m: Sanchez-Cuevas et al.'s ``k2``), ``linear_drag`` and ``quadratic_drag``
with ``wind`` (parameter ``w``, m/s, world frame: drag on the air-relative velocity),
``wall_suction`` with ``thrust_scaling`` (no extra parameter). Without the option
each effect is exactly its one-line form above.

Make one with :func:`make_effect` (``make_effect("wall_suction", k_s=10.0)``) or from
a specification with :func:`effects_from_spec`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from wall_env.effects.base import Effect, FlightContext, Parameter, Wrench
from wall_env.effects.ceiling import CeilingEffect
from wall_env.effects.constant_force import ConstantForce
from wall_env.effects.drag import LinearDrag, QuadraticDrag
from wall_env.effects.ground import GroundEffect
from wall_env.effects.suction import WallSuction
from wall_env.effects.thrust_scale import ThrustScale

__all__ = [
    "EFFECTS",
    "Effect",
    "FlightContext",
    "Parameter",
    "Wrench",
    "make_effect",
    "effects_from_spec",
    "WallSuction",
    "LinearDrag",
    "QuadraticDrag",
    "GroundEffect",
    "CeilingEffect",
    "ThrustScale",
    "ConstantForce",
]

EFFECTS: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (WallSuction, LinearDrag, QuadraticDrag, GroundEffect, CeilingEffect, ThrustScale, ConstantForce)
}


def make_effect(name: str, **values: Any) -> Effect:
    """An effect from the library by name, with parameter values and options as keywords."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; known effects: {sorted(EFFECTS)}")
    return EFFECTS[name](**values)


def effects_from_spec(spec: Any) -> list[Effect]:
    """Effects from any of the accepted specifications.

    - a mapping ``{"wall_suction": {"k_s": 4.1}, "linear_drag": {}}``;
    - a list of ``{"name": ..., "params": {...}, "options": {...}}`` records (the model-file form);
    - a list of :class:`Effect` instances or effect names;
    - a string ``"wall_suction:k_s=4.1,d_thr=0.13;constant_force:F=0.2/0/0"`` (the command-line form).
    """
    if spec is None:
        return []
    if isinstance(spec, str):
        return _effects_from_string(spec)
    if isinstance(spec, Effect):
        return [spec]
    if isinstance(spec, Mapping):
        return [make_effect(name, **dict(values or {})) for name, values in spec.items()]
    if isinstance(spec, Iterable):
        effects: list[Effect] = []
        for item in spec:
            if isinstance(item, Effect):
                effects.append(item)
            elif isinstance(item, str):
                effects.append(make_effect(item))
            elif isinstance(item, Mapping):
                unknown = sorted(set(item) - {"name", "params", "options", "param_std"})
                if unknown or "name" not in item:
                    raise ValueError(f"an effect record has 'name', 'params' and 'options'; got keys {sorted(item)}")
                effects.append(make_effect(item["name"], **dict(item.get("params") or {}), **dict(item.get("options") or {})))
            else:
                raise ValueError(f"cannot read an effect from {item!r}")
        return effects
    raise ValueError(f"cannot read effects from {spec!r}")


def _parse_value(text: str) -> Any:
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    if "/" in text:
        return [float(v) for v in text.split("/")]
    return float(text)


def _effects_from_string(text: str) -> list[Effect]:
    effects = []
    for chunk in filter(None, (c.strip() for c in text.split(";"))):
        name, _, args = chunk.partition(":")
        values = {}
        for pair in filter(None, (a.strip() for a in args.split(","))):
            key, eq, value = pair.partition("=")
            if not eq:
                raise ValueError(f"effect argument {pair!r} in {chunk!r} must look like name=value")
            try:
                values[key.strip()] = _parse_value(value)
            except ValueError:
                raise ValueError(f"effect argument {key.strip()!r} in {chunk!r} has a non-numeric value {value!r}") from None
        effects.append(make_effect(name.strip(), **values))
    return effects
