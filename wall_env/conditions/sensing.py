"""State-estimate error: what the vehicle believes its state is, against what it is.

Each of the four groups of the state a controller reads (position, velocity, attitude,
body rates) gets, per axis, the sum of three errors:

    e(t) = b + d(t) + n(t)

- ``bias`` ``b``: drawn once per episode, ``N(0, bias^2)``, constant during it (a
  calibration or extrinsic offset: the marker frame against the body frame, a gyro's
  residual zero-rate offset);
- ``drift`` ``d``: a random walk from 0 at the episode's start, ``d(t + h) = d(t) +
  drift sqrt(h) N(0, 1)`` (an odometry estimate wandering away; ``drift`` in unit/sqrt(s),
  so that the spread after ``t`` seconds is ``drift sqrt(t)``);
- ``noise`` ``n``: white, ``N(0, noise^2)`` at every sample.

Position, velocity and body rates are offset by their error; the attitude error is a
small rotation vector in the world frame, ``R_estimated = Exp(e) R_body_to_world``.
The groups are independent of each other: a real estimator's errors are correlated (an
odometry's position drift is the integral of its velocity error), which this model
leaves out on purpose, so that each group's share of a controller's error can be told.

Presets (:data:`SENSING_PRESETS`, values and where they come from beside each):

``motion_capture``
    an optical motion-capture system (Vicon class) for the pose and the flight
    controller's gyroscope for the body rates.
``visual_inertial``
    onboard visual-inertial odometry (VIO) for the pose and velocity, the same gyroscope.
``none``
    no error (the simulator's ideal conditions).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from wall_env.state import StateIndex
from wall_env.validation import check_range

__all__ = ["ErrorModel", "StateEstimateError", "SENSING_PRESETS", "SensingErrors", "GROUPS"]

GROUPS = ("position", "velocity", "attitude", "body_rates")
_UNITS = {"position": "m", "velocity": "m/s", "attitude": "rad", "body_rates": "rad/s"}
_DEG = math.pi / 180.0


@dataclass(frozen=True)
class ErrorModel:
    """The error of one group of the state, per axis: standard deviations of noise and bias, drift intensity."""

    noise: float = 0.0  # std of white noise per sample (the group's unit)
    bias: float = 0.0  # std of the per-episode constant offset (the group's unit)
    drift: float = 0.0  # random-walk intensity (the group's unit per sqrt(s))

    def check(self, group: str) -> ErrorModel:
        unit = _UNITS[group]
        for f in fields(self):
            limit = 10.0 if group != "attitude" else 0.5
            check_range(f"sensing.{group}.{f.name} ({unit}{'/sqrt(s)' if f.name == 'drift' else ''})",
                        getattr(self, f.name), 0.0, limit)
        return self

    def scaled(self, factor: float) -> ErrorModel:
        return ErrorModel(self.noise * factor, self.bias * factor, self.drift * factor)


@dataclass(frozen=True)
class StateEstimateError:
    """Noise, bias and drift of each state group (see the module docstring); SI units."""

    position: ErrorModel = ErrorModel()  # m
    velocity: ErrorModel = ErrorModel()  # m/s
    attitude: ErrorModel = ErrorModel()  # rad, rotation vector in the world frame
    body_rates: ErrorModel = ErrorModel()  # rad/s
    name: str = "custom"
    source: str = ""

    def __post_init__(self) -> None:
        for group in GROUPS:
            value = getattr(self, group)
            if isinstance(value, dict):
                unknown = sorted(set(value) - {"noise", "bias", "drift"})
                if unknown:
                    raise ValueError(f"sensing.{group} takes noise, bias and drift; unknown {unknown}")
                value = ErrorModel(**value)
            if not isinstance(value, ErrorModel):
                raise ValueError(f"sensing.{group} must be an ErrorModel or a dict of noise, bias and drift, "
                                 f"got {value!r}")
            object.__setattr__(self, group, value.check(group))

    @classmethod
    def from_spec(cls, spec: Any) -> StateEstimateError:
        """A preset by name (:data:`SENSING_PRESETS`), a dict of groups, or an instance."""
        if spec is None:
            return SENSING_PRESETS["none"]
        if isinstance(spec, StateEstimateError):
            return spec
        if isinstance(spec, str):
            if spec not in SENSING_PRESETS:
                raise ValueError(f"sensing must be one of {sorted(SENSING_PRESETS)} or a dict, got {spec!r}")
            return SENSING_PRESETS[spec]
        if isinstance(spec, dict):
            unknown = sorted(set(spec) - set(GROUPS) - {"name", "source"})
            if unknown:
                raise ValueError(f"sensing takes the groups {list(GROUPS)}; unknown {unknown}")
            return cls(**spec)
        raise ValueError(f"sensing must be a preset name, a dict or a StateEstimateError, got {spec!r}")

    @property
    def is_zero(self) -> bool:
        return all(getattr(getattr(self, g), f.name) == 0.0 for g in GROUPS for f in fields(ErrorModel))

    def scaled(self, factor: float) -> StateEstimateError:
        """Every standard deviation multiplied by ``factor``."""
        return replace(self, **{g: getattr(self, g).scaled(factor) for g in GROUPS}, name=f"{self.name} x {factor:g}")

    def sigmas(self, kind: str) -> np.ndarray:
        """``(12,)`` standard deviations of ``kind`` (``noise``, ``bias`` or ``drift``), three per group in
        :data:`GROUPS` order."""
        return np.repeat([getattr(getattr(self, g), kind) for g in GROUPS], 3).astype(float)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, **{g: {f.name: getattr(getattr(self, g), f.name) for f in fields(ErrorModel)}
                                      for g in GROUPS}}


# ---------------------------------------------------------------------------------------------- presets
_GYRO_NOTE = ("Body rates from a flight controller's MEMS gyroscope: Bosch BMI088 data sheet (BST-BMI088-DS001, "
              "rev. 1.4, 2018), rate noise density 0.014 deg/s/sqrt(Hz), i.e. 0.1 deg/s (0.0017 rad/s) rms in a "
              "50 Hz band; the zero-rate offset is specified as +-1 deg/s before calibration, of which a "
              "startup calibration leaves about a tenth (0.1 deg/s, 0.0017 rad/s) as the per-flight bias.")

MOTION_CAPTURE = StateEstimateError(
    position=ErrorModel(noise=0.5e-3, bias=1.0e-3),
    velocity=ErrorModel(noise=0.01),
    attitude=ErrorModel(noise=0.1 * _DEG, bias=0.5 * _DEG),
    body_rates=ErrorModel(noise=0.0017, bias=0.0017),
    name="motion_capture",
    source=("Merriaux et al., 'A Study of Vicon System Positioning Performance', Sensors 17(7):1591, 2017: "
            "static mean absolute error 0.15 mm with a variability below 0.025 mm, and below 2 mm in motion. "
            "Position: 0.5 mm noise in flight (markers moving, within their 2 mm bound) and a 1 mm bias (marker "
            "frame to centre of mass). Attitude of a marker constellation about 0.1 m across: 0.5 mm over 0.1 m "
            "gives about 0.3 deg; 0.1 deg noise after the system's rigid-body fit over several markers, 0.5 deg "
            "bias (marker frame against the body axes). Velocity: differentiated and filtered positions at "
            "100 Hz, 0.01 m/s noise (0.5 mm / 0.01 s x sqrt(2) = 0.07 m/s unfiltered, about 7x less after a "
            "first-order filter at 10 Hz). " + _GYRO_NOTE),
)

VISUAL_INERTIAL = StateEstimateError(
    position=ErrorModel(noise=5.0e-3, bias=0.0, drift=7.0e-3),
    velocity=ErrorModel(noise=0.03, bias=0.01),
    attitude=ErrorModel(noise=0.2 * _DEG, bias=0.5 * _DEG, drift=0.05 * _DEG),
    body_rates=ErrorModel(noise=0.0017, bias=0.0017),
    name="visual_inertial",
    source=("Onboard monocular visual-inertial odometry on EuRoC-like flights (Burri et al., 'The EuRoC micro "
            "aerial vehicle datasets', IJRR 35(10), 2016; Delmerico and Scaramuzza, 'A Benchmark Comparison of "
            "Monocular Visual-Inertial Odometry Algorithms for Flying Robots', ICRA 2018): translation errors of "
            "the better pipelines are of the order of 0.1-0.3 m over 30-130 m flights, i.e. 0.2-1 % of the "
            "distance travelled. Position: drift 7 mm/sqrt(s) (3 cm after the 17 s Table II sweep, about 0.5 % of "
            "its 6 m of path), 5 mm jitter between frames. Velocity: 0.03 m/s noise, 0.01 m/s bias. Attitude: "
            "roll and pitch are held by gravity (0.2 deg noise, 0.5 deg bias), yaw drifts (0.05 deg/sqrt(s), "
            "applied to all three axes here). " + _GYRO_NOTE),
)

SENSING_PRESETS: dict[str, StateEstimateError] = {
    "none": StateEstimateError(name="none", source="no estimate error: the simulator's ideal conditions"),
    "motion_capture": MOTION_CAPTURE,
    "visual_inertial": VISUAL_INERTIAL,
}


# ---------------------------------------------------------------------------------------------- per-row state
def _small_rotation_quaternions(phi: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(n, 4)`` [w, x, y, z] of rotation vectors ``(n, 3)`` (exact for any angle)."""
    angle = np.linalg.norm(phi, axis=1)
    half = 0.5 * angle
    # sin(half) / angle, with its limit 1/2 at zero
    scale = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    return np.concatenate([np.cos(half)[:, None], phi * scale[:, None]], axis=1)


def _quat_multiply_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products ``a * b`` of quaternion rows ``(n, 4)``."""
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=1)


class SensingErrors:
    """The estimate errors of ``n`` episodes: biases drawn at reset, drifts carried from step to step.

    ``scale`` (per row, set at reset) multiplies every standard deviation of ``model`` (domain
    randomisation of the sensing quality). Random numbers are given by the caller (the env's
    per-row streams), 12 normals per row at reset and 24 per step, so that a row flies the same
    in any batch.
    """

    RESET_NORMALS = 12
    STEP_NORMALS = 24

    def __init__(self, model: StateEstimateError, n: int, dt: float):
        self.model = model
        self.dt = float(dt)
        self._noise = model.sigmas("noise")
        self._bias = model.sigmas("bias")
        self._drift = model.sigmas("drift") * math.sqrt(self.dt)
        self.scale = np.ones(n)
        self.bias = np.zeros((n, 12))
        self.drift = np.zeros((n, 12))
        self.error = np.zeros((n, 12))  # the latest error: position, velocity, attitude, body rates

    def reset(self, rows: np.ndarray | slice, normals: np.ndarray, scale: np.ndarray | float = 1.0) -> None:
        """New episodes in ``rows``: biases from ``normals`` ``(k, 12)``, drifts from zero."""
        self.scale[rows] = scale
        self.bias[rows] = normals * self._bias * np.reshape(self.scale[rows], (-1, 1))
        self.drift[rows] = 0.0
        self.error[rows] = self.bias[rows]

    def step(self, normals: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """Advance every row's drift one step and draw its noise (``normals`` ``(n, 24)``); rows outside the
        bool mask ``active`` keep their drift. Returns the errors ``(n, 12)``."""
        scale = self.scale[:, None]
        step = normals[:, :12] * self._drift * scale
        if active is not None:
            step[~active] = 0.0
        self.drift += step
        self.error = self.bias + self.drift + normals[:, 12:] * self._noise * scale
        return self.error

    @staticmethod
    def apply(x: np.ndarray, error: np.ndarray) -> np.ndarray:
        """The estimated states ``(n, 17)`` of true states ``x`` ``(n, 17)`` (layout of
        :class:`wall_env.dynamics.StateIndex`) under ``error`` ``(n, 12)``."""
        estimate = x.copy()
        estimate[:, StateIndex.p_world] += error[:, 0:3]
        estimate[:, StateIndex.v_world] += error[:, 3:6]
        estimate[:, StateIndex.q_body_to_world] = _quat_multiply_rows(_small_rotation_quaternions(error[:, 6:9]),
                                                                      x[:, StateIndex.q_body_to_world])
        estimate[:, StateIndex.omega_body] += error[:, 9:12]
        return estimate
