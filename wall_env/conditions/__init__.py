"""Flight conditions: what a real vehicle meets besides aerodynamics, each written once.

============================  ==========================================  ======================================
condition                     module                                      what
============================  ==========================================  ======================================
state-estimate error          :mod:`wall_env.conditions.sensing`          noise, bias and drift on position,
                                                                          velocity, attitude and body rates;
                                                                          presets ``motion_capture``,
                                                                          ``visual_inertial``
latency                       :mod:`wall_env.conditions.latency`          commands act late, the estimate
                                                                          arrives late (whole physics steps)
motor lag                     :mod:`wall_env.motor_lag`                   first-order rotor thrust lag (the
                                                                          model discovery fits)
wind                          :mod:`wall_env.conditions.wind`             steady wind and Dryden turbulence
                                                                          through the air-relative drag
============================  ==========================================  ======================================

A steady push (a tether, a wind on a part the drag model lacks) is the ``constant_force``
effect (:mod:`wall_env.effects`); the envs' ``randomize`` draws one per episode.

:class:`FlightConditions` holds one of each; :data:`PROFILES` names documented sets:
``"ideal"`` (none of them, the paper tables' conditions) and ``"realistic"``. The envs take
``conditions="realistic"`` (or a dict, or an instance) and apply every condition on every
row of the batched env, the single env being its row of one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from wall_env.conditions.latency import MAX_LATENCY, DelayLine, Latency
from wall_env.conditions.sensing import SENSING_PRESETS, ErrorModel, SensingErrors, StateEstimateError
from wall_env.conditions.wind import TURBULENCE_PRESETS, DrydenTurbulence, TurbulenceState, Wind
from wall_env.motor_lag import MAX_TIME_CONSTANT
from wall_env.validation import check_range

__all__ = ["FlightConditions", "PROFILES", "StateEstimateError", "ErrorModel", "SENSING_PRESETS", "Latency",
           "MAX_LATENCY", "Wind", "DrydenTurbulence", "TURBULENCE_PRESETS", "SensingErrors", "TurbulenceState",
           "DelayLine"]


@dataclass(frozen=True)
class FlightConditions:
    """Sensing error, latency, motor lag (s; ``None``: the vehicle's own) and wind of a flight."""

    sensing: StateEstimateError = SENSING_PRESETS["none"]
    latency: Latency = Latency()
    motor_time_constant: float | None = None
    wind: Wind = Wind()
    name: str = "custom"

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensing", StateEstimateError.from_spec(self.sensing))
        object.__setattr__(self, "latency", Latency.from_spec(self.latency))
        object.__setattr__(self, "wind", Wind.from_spec(self.wind))
        if self.motor_time_constant is not None:
            object.__setattr__(self, "motor_time_constant", check_range(
                "conditions.motor_time_constant (s)", self.motor_time_constant, 0.0, MAX_TIME_CONSTANT))

    @classmethod
    def from_spec(cls, spec: Any) -> FlightConditions:
        """``None`` (ideal), a profile name (:data:`PROFILES`), a dict of this class's fields (a ``"profile"``
        key starts from that profile), or an instance."""
        if spec is None:
            return PROFILES["ideal"]
        if isinstance(spec, FlightConditions):
            return spec
        if isinstance(spec, str):
            if spec not in PROFILES:
                raise ValueError(f"conditions must be one of {sorted(PROFILES)}, a dict or a FlightConditions, "
                                 f"got {spec!r}")
            return PROFILES[spec]
        if isinstance(spec, dict):
            fields = {"sensing", "latency", "motor_time_constant", "wind", "name", "profile"}
            unknown = sorted(map(str, set(spec) - fields))
            if unknown:
                raise ValueError(f"conditions takes {sorted(fields)}; unknown {unknown}")
            values = dict(spec)
            base = cls.from_spec(values.pop("profile", "ideal"))
            values.setdefault("name", "custom")
            return replace(base, **values)
        raise ValueError(f"conditions must be a profile name, a dict or a FlightConditions, got {spec!r}")

    @property
    def is_ideal(self) -> bool:
        return (self.sensing.is_zero and self.latency.seconds == 0 and not self.motor_time_constant
                and self.wind.is_still)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "sensing": self.sensing.to_dict(),
                "latency": {"command": self.latency.command, "observation": self.latency.observation},
                "motor_time_constant": self.motor_time_constant, "wind": self.wind.to_dict()}


PROFILES: dict[str, FlightConditions] = {
    "ideal": FlightConditions(name="ideal"),
    # A wall inspection flown under a motion-capture system, as the paper's flights were: the pose from
    # the cameras, the body rates from the flight controller's gyroscope; 20 ms from the state being true
    # to the rotors acting on a command computed from it (10 ms of estimation and transport, 10 ms from
    # the command to the ESCs); rotors of a 1 kg ducted quadrotor reaching 63 % of a thrust step in
    # 30 ms; light turbulence of a sheltered facade in still mean air.
    "realistic": FlightConditions(sensing=SENSING_PRESETS["motion_capture"], latency=Latency(command=0.01, observation=0.01),
                                  motor_time_constant=0.03, wind=Wind(turbulence=TURBULENCE_PRESETS["light"]),
                                  name="realistic"),
}
