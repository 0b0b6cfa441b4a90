"""Cascaded PID in the paper's differential-flatness form (the baseline of Tables I and II).

Per control step, from the observation and the reference:

1. errors ``e_p = clip(p - p_ref, +-0.5 m)`` and ``e_v = clip(v - v_ref, +-1.0 m/s)``
   per axis (``p_ref = p_world - p_error`` and ``v_ref = v_world - v_error`` come from
   the observation, so a translated reference is followed exactly);
2. desired acceleration ``a_des = a_ref - Kp e_p - Kv e_v - Ki I`` with the reference's
   feed-forward acceleration ``a_ref(t)`` and, when ``ki`` is not zero, the integral
   ``I = int e_p dt`` over the episode (each axis' ``Ki I`` held within
   ``+-integral_limit`` m/s^2, so a long stretch of large error cannot wind it up);
3. thrust vector ``f = m (a_des + g e3)`` to the desired attitude ``R_des`` with the
   reference yaw (:mod:`controllers.flatness`, tilt at most 80 deg);
4. collective thrust ``T = f . (R e3)`` (the part of ``f`` along the current body z);
5. body rates ``omega = K_R * Log(R^T R_des) + omega_des``, where ``omega_des`` is the
   flatness feed-forward from the reference jerk (central difference of ``a_ref``).

Defaults are the authors' released gains (the ``paper`` preset of :mod:`controllers.presets`):
Kp = (8, 8, 10) 1/s^2, Kv = (4, 4, 6) 1/s, K_R = (6, 6, 4) 1/s, no integral. The
commands are clipped to the vehicle's limits by the action mapping. Without integral
there is no memory between steps; with it, each env of a batch keeps its own integral,
cleared at its episode start, so the controller is exact under batching either way.

Integral action is what a real position controller (PX4's, say) has to hold a reference
against a steady force it does not model: without it, a force ``F`` shifts the vehicle by
``F / (m Kp)`` (a thrust 10 % short of the weight sags it 10 cm at ``Kp = 10``). The
discovery flights near a ground or a ceiling use it to fly the distances they plan.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from controllers.flatness import attitude_error, attitude_from_thrust, feedforward_body_rates, thrust_vector
from controllers.policy import ControllerPolicy
from wall_env.validation import check_range, check_vector
from wall_env.vehicle import GRAVITY

__all__ = ["PID"]

_JERK_STEP = 1e-3  # s, half-width of the central difference of the reference acceleration


class PID(ControllerPolicy):
    """Cascaded position-velocity-attitude controller with body-rate output."""

    name = "PID"

    def __init__(self, description, *, kp=(8.0, 8.0, 10.0), kv=(4.0, 4.0, 6.0), k_attitude=(6.0, 6.0, 4.0),
                 position_error_limit: float = 0.5, velocity_error_limit: float = 1.0,
                 max_tilt_deg: float = 80.0, ki=(0.0, 0.0, 0.0), integral_limit: float = 3.0):
        super().__init__(description)
        self.kp = np.array(check_vector("kp", kp, 3, low=0.0, high=1e3))
        self.kv = np.array(check_vector("kv", kv, 3, low=0.0, high=1e3))
        self.k_attitude = np.array(check_vector("k_attitude", k_attitude, 3, low=0.0, high=1e3))
        self.position_error_limit = check_range("position_error_limit", position_error_limit, 1e-3, 100.0)
        self.velocity_error_limit = check_range("velocity_error_limit", velocity_error_limit, 1e-3, 100.0)
        self.max_tilt = math.radians(check_range("max_tilt_deg", max_tilt_deg, 1.0, 89.0))
        self.ki = np.array(check_vector("ki", ki, 3, low=0.0, high=1e3))
        self.integral_limit = check_range("integral_limit", integral_limit, 0.0, 100.0)

    @classmethod
    def from_env(cls, env: Any, *, preset: str | Path | None = "tuned", **kwargs: Any) -> PID:
        """A PID for ``env`` (plain, wrapped or vector env); keywords as in the constructor.

        ``preset``: gains from a preset (:mod:`controllers.presets`): ``"tuned"`` (default: the
        tuned preset of the env's task), ``"paper"`` (the authors' gains), a file, or ``None`` for
        the constructor's defaults (also the authors'). Keywords override the preset.
        """
        description = cls._description(env)
        if preset is not None:
            from controllers.presets import load_preset

            kwargs = {**load_preset(preset, method="pid", task=description.task).controller_kwargs("pid"), **kwargs}
        policy = cls(description, **kwargs)
        policy.follow(env)
        return policy

    def _new_memory(self, scene, reference) -> dict[str, Any]:
        return {**super()._new_memory(scene, reference), "position_integral": np.zeros(3), "time": None}

    def _integral_term(self, e_p: np.ndarray, t: float, memory: dict[str, Any]) -> np.ndarray:
        """``Ki int e_p dt`` (m/s^2), the integral advanced by this step's error over the time since the last."""
        if not self.ki.any():
            return np.zeros(3)
        dt = 0.0 if memory["time"] is None else max(t - memory["time"], 0.0)
        memory["time"] = t
        integral = memory["position_integral"] + e_p * dt
        active = self.ki > 0
        bound = np.full(3, np.inf)
        bound[active] = self.integral_limit / self.ki[active]
        memory["position_integral"] = np.clip(integral, -bound, bound)
        return self.ki * memory["position_integral"]

    def _command(self, fields: dict[str, np.ndarray], memory: Any, index: int) -> np.ndarray:
        t = float(fields["time"])
        e_p = np.clip(fields["p_error"], -self.position_error_limit, self.position_error_limit)
        e_v = np.clip(fields["v_error"], -self.velocity_error_limit, self.velocity_error_limit)
        reference = memory["reference"]
        accelerations = reference.acceleration([t, t - _JERK_STEP, t + _JERK_STEP])
        a_ref = accelerations[0]
        jerk = (accelerations[2] - accelerations[1]) / (2 * _JERK_STEP)
        a_des = a_ref - self.kp * e_p - self.kv * e_v - self._integral_term(e_p, t, memory)
        mass = self.vehicle.mass
        f = thrust_vector(a_des, mass, GRAVITY)
        R_des, z_des = attitude_from_thrust(f[None], reference.yaw, self.max_tilt)
        R = fields["R_body_to_world"]
        thrust = float(f @ R[:, 2])
        omega_ff = feedforward_body_rates(R_des, np.linalg.norm(f) / mass, jerk[None])[0]
        omega = self.k_attitude * attitude_error(R, R_des)[0] + omega_ff
        return np.array([thrust, *omega])
