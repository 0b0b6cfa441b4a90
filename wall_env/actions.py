"""Action mapping: normalised actions in [-1, 1]^4 to collective thrust and body rates.

    T     = clip(T_hover + a[0] * (T_max - T_hover), T_min, T_max)    N
    omega = a[1:4] * omega_max                                        rad/s, body frame

``a[0] = 0`` is hover for the nominal mass, so an untrained policy's zero action
holds altitude; ``a[0] = 1`` is full thrust; below ``a[0] = (T_min - T_hover) /
(T_max - T_hover)`` (about -0.57 for the default vehicle) the thrust stays at T_min.
Controllers that compute physical commands use :meth:`ActionMapping.to_normalised`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wall_env.vehicle import VehicleParams

__all__ = ["ActionMapping"]


@dataclass(frozen=True)
class ActionMapping:
    thrust_hover: float  # N
    thrust_min: float  # N
    thrust_max: float  # N
    body_rate_max: float  # rad/s

    @classmethod
    def for_vehicle(cls, vehicle: VehicleParams) -> ActionMapping:
        return cls(vehicle.hover_thrust, vehicle.thrust_min, vehicle.thrust_max, vehicle.body_rate_max)

    @property
    def thrust_span(self) -> float:
        return self.thrust_max - self.thrust_hover

    def to_physical(self, action: np.ndarray) -> np.ndarray:
        """``[T (N), wx, wy, wz (rad/s)]`` for normalised actions ``(..., 4)`` (clipped to [-1, 1])."""
        # np.minimum/np.maximum rather than np.clip: this runs every env step
        a = np.minimum(np.maximum(np.asarray(action, dtype=float), -1.0), 1.0)
        out = a * self.body_rate_max
        out[..., 0] = np.minimum(np.maximum(self.thrust_hover + a[..., 0] * self.thrust_span, self.thrust_min),
                                 self.thrust_max)
        return out

    def to_normalised(self, command: np.ndarray) -> np.ndarray:
        """Normalised actions for physical commands ``(..., 4)``; out-of-range commands are clipped."""
        u = np.asarray(command, dtype=float)
        a = np.empty_like(u)
        a[..., 0] = (u[..., 0] - self.thrust_hover) / self.thrust_span
        a[..., 1:] = u[..., 1:] / self.body_rate_max
        return np.clip(a, -1.0, 1.0)
