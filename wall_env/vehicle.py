"""Vehicle parameters: the ducted quadrotor of the paper, as a dataclass that loads from JSON or YAML.

Frames: the body frame has x forward, y left, z up (thrust along +z_body). Rotors sit
in an X configuration, numbered counter-clockwise from front-left when seen from above:

    rotor 0: (+a, +a, 0)  front-left,  spins +1 (counter-clockwise, yaw torque -kappa*f)
    rotor 1: (-a, +a, 0)  rear-left,   spins -1
    rotor 2: (-a, -a, 0)  rear-right,  spins +1
    rotor 3: (+a, -a, 0)  front-right, spins -1

with a = arm_length / sqrt(2). Facing a wall (body x along the wall's inward normal),
rotors 0 and 3 are the near pair that the suction pulls on.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from wall_env.motor_lag import MAX_TIME_CONSTANT
from wall_env.validation import check_positive, check_range, check_vector, read_mapping

__all__ = ["GRAVITY", "VehicleParams"]

GRAVITY = 9.81  # m/s^2, world z points up


def _x_configuration(arm_length: float) -> tuple[tuple[float, float, float], ...]:
    a = arm_length / math.sqrt(2.0)
    return ((a, a, 0.0), (-a, a, 0.0), (-a, -a, 0.0), (a, -a, 0.0))


@dataclass(frozen=True)
class VehicleParams:
    """Physical parameters of the quadrotor (SI units).

    Defaults describe the paper's ducted platform: 1.0 kg, four rotors 0.10 m from the
    centre of mass in an X, ducts of 0.04 m outer radius, inertia
    diag(2.64e-3, 2.64e-3, 4.96e-3) kg m^2, body drag D = diag(0.3, 0.3, 0.2) N s/m
    (paper Eq. 4), collective thrust 0 to 27 N and body rates within +-3 rad/s.
    """

    mass: float = 1.0  # kg
    arm_length: float = 0.10  # m, rotor centre to centre of mass
    rotor_positions: tuple[tuple[float, float, float], ...] = field(default=())  # m, body frame
    rotor_directions: tuple[int, int, int, int] = (1, -1, 1, -1)  # +1 counter-clockwise seen from above
    duct_radius: float = 0.04  # m, outer radius of each duct (collision geometry)
    duct_height: float = 0.035  # m
    inertia: tuple[float, float, float] = (2.64e-3, 2.64e-3, 4.96e-3)  # kg m^2, principal axes
    drag: tuple[float, float, float] = (0.3, 0.3, 0.2)  # N s/m, body-frame linear drag (Eq. 4)
    thrust_min: float = 0.0  # N, collective
    thrust_max: float = 27.0  # N, collective
    body_rate_max: float = 3.0  # rad/s, per axis
    yaw_moment_coefficient: float = 0.016  # m, rotor drag torque per newton of thrust
    rate_gains: tuple[float, float, float] = (50.0, 50.0, 25.0)  # 1/s, inner body-rate loop
    motor_time_constant: float = 0.0  # s, first-order rotor thrust lag; 0 = instantaneous

    def __post_init__(self) -> None:
        check_positive("mass", self.mass, high=100.0)
        check_positive("arm_length", self.arm_length, high=5.0)
        if not self.rotor_positions:
            object.__setattr__(self, "rotor_positions", _x_configuration(self.arm_length))
        positions = np.asarray(self.rotor_positions, dtype=float)
        if positions.shape != (4, 3) or not np.all(np.isfinite(positions)):
            raise ValueError(f"rotor_positions must be four finite [x, y, z] points in metres, got {self.rotor_positions!r}")
        object.__setattr__(self, "rotor_positions", tuple(tuple(float(c) for c in row) for row in positions))
        if sorted(self.rotor_directions) != [-1, -1, 1, 1]:
            raise ValueError(f"rotor_directions must hold two +1 and two -1, got {self.rotor_directions!r}")
        check_positive("duct_radius", self.duct_radius, high=1.0)
        check_positive("duct_height", self.duct_height, high=1.0)
        object.__setattr__(self, "inertia", check_vector("inertia", self.inertia, 3, low=1e-6, high=10.0))
        object.__setattr__(self, "drag", check_vector("drag", self.drag, 3, low=0.0, high=20.0))
        check_range("thrust_min", self.thrust_min, 0.0, 1000.0)
        check_range("thrust_max", self.thrust_max, self.thrust_min + 1e-6, 1000.0)
        if self.thrust_max <= self.mass * GRAVITY:
            raise ValueError(
                f"thrust_max must exceed the weight mass*g = {self.mass * GRAVITY:.2f} N, got {self.thrust_max}"
            )
        check_positive("body_rate_max", self.body_rate_max, high=50.0)
        check_range("yaw_moment_coefficient", self.yaw_moment_coefficient, 1e-5, 1.0)
        object.__setattr__(self, "rate_gains", check_vector("rate_gains", self.rate_gains, 3, low=0.1, high=1000.0))
        check_range("motor_time_constant", self.motor_time_constant, 0.0, MAX_TIME_CONSTANT)

    # ------------------------------------------------------------------ derived
    @property
    def hover_thrust(self) -> float:
        """Collective thrust that balances gravity, N."""
        return self.mass * GRAVITY

    @property
    def rotor_thrust_max(self) -> float:
        """Upper limit of one rotor's thrust, N (a quarter of the collective limit)."""
        return self.thrust_max / 4.0

    @property
    def rotor_positions_array(self) -> np.ndarray:
        """Rotor centres in the body frame, shape (4, 3), m."""
        return np.asarray(self.rotor_positions, dtype=float)

    @property
    def allocation_matrix(self) -> np.ndarray:
        """Map from the four rotor thrusts to [collective thrust, roll, pitch, yaw moment] (N, N m).

        Row 0 sums the thrusts; rows 1-3 are the body moments of the thrusts acting at
        the rotor centres along +z_body plus each rotor's drag torque
        ``-direction * yaw_moment_coefficient * thrust``.
        """
        r = self.rotor_positions_array
        directions = np.asarray(self.rotor_directions, dtype=float)
        return np.vstack([
            np.ones(4),
            r[:, 1],
            -r[:, 0],
            -directions * self.yaw_moment_coefficient,
        ])

    @property
    def mixer_matrix(self) -> np.ndarray:
        """Inverse of :attr:`allocation_matrix`: [T, moments] -> rotor thrusts."""
        return np.linalg.inv(self.allocation_matrix)

    # ------------------------------------------------------------------ I/O
    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["rotor_positions"] = [list(p) for p in self.rotor_positions]
        for key in ("rotor_directions", "inertia", "drag", "rate_gains"):
            data[key] = list(data[key])
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> VehicleParams:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown vehicle parameter(s) {unknown}; allowed: {sorted(known)}")
        values = {}
        for key, value in data.items():
            if key == "rotor_positions":
                value = tuple(tuple(float(c) for c in row) for row in value)
            elif key == "rotor_directions":
                value = tuple(int(v) for v in value)
            elif isinstance(value, (list, tuple)):
                value = tuple(float(v) for v in value)
            values[key] = value
        return cls(**values)

    @classmethod
    def from_file(cls, path: str | Path) -> VehicleParams:
        """Load from a ``.json`` or ``.yaml``/``.yml`` file holding the fields of this class."""
        data = read_mapping(path, "vehicle file")
        try:
            return cls.from_dict(data)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: {exc}") from exc

    def save(self, path: str | Path) -> None:
        path = Path(path)
        if path.suffix.lower() in (".yaml", ".yml"):
            import yaml

            path.write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))
        else:
            path.write_text(json.dumps(self.to_dict(), indent=2))

    def replace(self, **changes: Any) -> VehicleParams:
        """A copy with some fields changed (rotor positions follow a changed arm length)."""
        if "arm_length" in changes and "rotor_positions" not in changes:
            changes["rotor_positions"] = ()
        return replace(self, **changes)
