"""Model files: a vehicle plus the effects it meets, with parameter uncertainties.

The JSON form, written by model discovery and read by the environments and SC-MPC::

    {
      "vehicle": {"mass": 1.0, "drag": [0.3, 0.3, 0.2], ...},      # VehicleParams fields
      "effects": [
        {"name": "wall_suction", "params": {"k_s": 4.1, "d_thr": 0.132},
         "param_std": {"k_s": 0.05, "d_thr": 0.002}, "options": {"thrust_scaling": false}}
      ]
    }

The vehicle's ``drag`` is the nominal ``linear_drag``; a ``linear_drag`` entry in
``effects`` is drag found on top of it, and :meth:`FlightModel.aero_model` adds the two.

An optional ``vehicle_fields`` maps vehicle fields to where their values came from
(``"given"``, ``"defaulted"``, ``"derived: ..."``, ``"found: ..."``): model discovery writes it,
since a log gives only some of them, and an impossible setting traced to a field names it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wall_env.aero import AeroModel
from wall_env.effects import Effect, effects_from_spec, make_effect
from wall_env.validation import read_json_object
from wall_env.vehicle import VehicleParams

__all__ = ["FlightModel", "nominal_aero_model"]


def nominal_aero_model(vehicle: VehicleParams) -> AeroModel:
    """What a vehicle file alone predicts: its linear body drag (paper Eq. 4)."""
    return AeroModel([make_effect("linear_drag", D=vehicle.drag)])


@dataclass
class FlightModel:
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    effects: list[Effect] = field(default_factory=list)
    param_std: dict[str, dict[str, Any]] = field(default_factory=dict)
    vehicle_fields: dict[str, str] = field(default_factory=dict)  # field -> where its value came from

    def field_source(self, name: str) -> str:
        """``vehicle.<name>`` and where its value came from, for messages."""
        return f"vehicle.{name} ({self.vehicle_fields.get(name, 'as written')})"

    def behind_standoff(self, body_axis: int, closest_approach: float) -> str:
        """The model's vehicle fields that set the lowest stand-off a task allows (``wall_env.tasks.min_standoff``)."""
        reach = float(np.max(np.abs(self.vehicle.rotor_positions_array[:, body_axis])))
        return (f"the lowest stand-off is the model's rotor reach along body {'xyz'[body_axis]}, {reach:.3g} m from "
                f"{self.field_source('rotor_positions')}, plus {self.vehicle.duct_radius:.3g} m of "
                f"{self.field_source('duct_radius')}, 5 mm and the task's closest approach of {closest_approach:.3g} m: "
                "pass a larger standoff, or correct those fields in the model file")

    def aero_model(self) -> AeroModel:
        """The vehicle's nominal drag plus every effect (extra linear drag added to the nominal)."""
        model = nominal_aero_model(self.vehicle)
        for effect in self.effects:
            if effect.name == "linear_drag":
                total = np.asarray(self.vehicle.drag) + effect.values["D"]
                # with a wind, it acts on the whole airframe's drag (nominal and extra alike)
                effect = make_effect("linear_drag", D=total, **{k: v for k, v in effect.params_dict().items()
                                                                if k != "D"}, **effect.option_values)
            model = model.with_effect(effect)
        return model

    def effect(self, name: str) -> Effect | None:
        return next((e for e in self.effects if e.name == name), None)

    # ------------------------------------------------------------------ I/O
    def to_dict(self) -> dict[str, Any]:
        records = []
        for effect in self.effects:
            record = effect.to_dict()
            if effect.name in self.param_std:
                record["param_std"] = self.param_std[effect.name]
            records.append(record)
        data: dict[str, Any] = {"vehicle": self.vehicle.to_dict(), "effects": records}
        if self.vehicle_fields:
            data["vehicle_fields"] = dict(self.vehicle_fields)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "model") -> FlightModel:
        unknown = sorted(set(data) - {"vehicle", "effects", "vehicle_fields"})
        if unknown:
            raise ValueError(f"{source}: unknown key(s) {unknown}; a model file has 'vehicle', 'effects' and "
                             "optionally 'vehicle_fields'")
        fields_given = data.get("vehicle_fields") or {}
        if not isinstance(fields_given, dict) or not all(isinstance(v, str) for v in fields_given.values()):
            raise ValueError(f"{source}: 'vehicle_fields' must map vehicle fields to strings, got {fields_given!r}")
        try:
            vehicle = VehicleParams.from_dict(data.get("vehicle") or {})
            records = data.get("effects") or []
            effects = effects_from_spec(records)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: {exc}") from exc
        stds = {r["name"]: r["param_std"] for r in records if isinstance(r, dict) and "param_std" in r}
        return cls(vehicle, effects, stds, {str(k): v for k, v in fields_given.items()})

    @classmethod
    def load(cls, path: str | Path) -> FlightModel:
        return cls.from_dict(read_json_object(path, "model file"), source=str(path))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2))
