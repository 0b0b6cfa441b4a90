"""Wind: a steady mean and Dryden turbulence, acting on the vehicle through its air-relative drag.

The air moves at ``w_world(t) = mean + R_heading [u_g(t), v_g(t), w_g(t)]``: the
turbulence components are longitudinal (``u``, along ``heading`` in the horizontal
plane), lateral (``v``, horizontal, 90 degrees to the left of it) and vertical (``w``).
The simulator's drag effects act on the velocity relative to that air (their ``wind``
form, :mod:`wall_env.effects.drag`); the wind is held over each control step (10 ms,
far shorter than the turbulence's correlation times).

Turbulence: the Dryden spectra of MIL-F-8785C (a frozen field carried past the vehicle
at ``airspeed``, with the scale lengths ``L`` and intensities ``sigma`` of each
component), one-sided in rad/s:

    Phi_u(omega) = sigma_u^2 (2 L_u / (pi V)) / (1 + (L_u omega / V)^2)
    Phi_v(omega) = sigma_v^2 (L_v / (pi V)) (1 + 3 (L_v omega / V)^2) / (1 + (L_v omega / V)^2)^2

(``w`` as ``v``), each integrating to ``sigma^2``. They are the outputs of the filters
``sigma sqrt(2 tau) / (1 + tau s)`` and ``sigma sqrt(tau) (1 + sqrt(3) tau s) / (1 + tau s)^2``
(``tau = L / V``) driven by unit white noise; :meth:`DrydenTurbulence.discrete` samples
those filters exactly at the control rate (the state transition ``expm(A h)`` and the
noise covariance by Van Loan's method), so the sampled turbulence has exactly the
sampled Dryden spectrum, with no discretisation error, and starts from its stationary
distribution. :meth:`DrydenTurbulence.low_altitude` sets the intensities and scale lengths
by MIL-F-8785C's rules below 1000 ft from the height and the wind speed at 20 ft (6.1 m).

A vehicle hovering in a steady wind sees the field carried past it at the wind speed;
in still air (a sheltered facade) the field still moves, and ``airspeed`` is the speed
it passes at (default: the mean wind's, at least 1 m/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from wall_env.validation import check_range, check_vector

__all__ = ["DrydenTurbulence", "Wind", "TURBULENCE_PRESETS", "TurbulenceState"]

_FT = 0.3048  # m per foot


@dataclass(frozen=True)
class DrydenTurbulence:
    """Dryden turbulence: intensities (m/s), scale lengths (m) of the ``u, v, w`` components and the
    speed (m/s) at which the frozen field passes the vehicle; ``heading`` (rad) of ``u`` in the world x-y plane."""

    intensity: tuple[float, float, float] = (0.4, 0.4, 0.2)
    length_scale: tuple[float, float, float] = (23.0, 23.0, 3.0)
    airspeed: float = 2.0
    heading: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "intensity",
                           check_vector("turbulence.intensity (m/s)", self.intensity, 3, low=0.0, high=20.0))
        object.__setattr__(self, "length_scale",
                           check_vector("turbulence.length_scale (m)", self.length_scale, 3, low=0.1, high=2000.0))
        object.__setattr__(self, "airspeed", check_range("turbulence.airspeed (m/s)", self.airspeed, 0.1, 100.0))
        object.__setattr__(self, "heading", check_range("turbulence.heading (rad)", self.heading, -10.0, 10.0))

    @classmethod
    def low_altitude(cls, height: float, wind_speed_20ft: float, airspeed: float | None = None,
                     heading: float = 0.0) -> DrydenTurbulence:
        """MIL-F-8785C below 1000 ft: ``sigma_w = 0.1 W20``, ``sigma_u = sigma_v = sigma_w / (0.177 +
        0.000823 h)^0.4``, ``L_w = h``, ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2`` (h in ft, taken
        at least 10 ft, the lowest height the rules hold for). ``airspeed`` defaults to ``W20``."""
        check_range("height (m)", height, 0.0, 304.8)
        w20 = check_range("wind_speed_20ft (m/s)", wind_speed_20ft, 0.0, 50.0)
        h = max(height / _FT, 10.0)
        factor = 0.177 + 0.000823 * h
        sigma_w = 0.1 * w20
        sigma_u = sigma_w / factor**0.4
        length_u = h / factor**1.2 * _FT
        return cls((sigma_u, sigma_u, sigma_w), (length_u, length_u, h * _FT),
                   max(w20, 1.0) if airspeed is None else airspeed, heading)

    # ------------------------------------------------------------------ spectra and filters
    def time_constants(self) -> np.ndarray:
        return np.asarray(self.length_scale) / self.airspeed

    def psd(self, omega: np.ndarray) -> np.ndarray:
        """One-sided power spectral densities ``(3, len(omega))`` ((m/s)^2 per rad/s) of ``u, v, w``."""
        omega = np.asarray(omega, dtype=float)
        sigma = np.asarray(self.intensity)[:, None]
        tau = self.time_constants()[:, None]
        x2 = (tau * omega[None, :]) ** 2
        out = sigma**2 * tau / np.pi * (1 + 3 * x2) / (1 + x2) ** 2
        out[0] = (sigma[0] ** 2 * 2 * tau[0] / np.pi / (1 + x2[0]))
        return out

    def continuous(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(A, B, C)`` of the three filters stacked (5 states: ``u``, then two each for ``v`` and ``w``),
        driven by five independent unit white noises (``B`` is 5x5), with unit intensity: ``C`` gives
        the components for intensities of 1 m/s (scale each row by ``intensity``)."""
        tau_u, tau_v, tau_w = self.time_constants()
        A = np.zeros((5, 5))
        B = np.zeros((5, 5))
        C = np.zeros((3, 5))
        A[0, 0] = -1.0 / tau_u
        B[0, 0] = math.sqrt(2.0 / tau_u)  # stationary variance b^2 tau / 2 = 1
        C[0, 0] = 1.0
        for row, (k, tau) in enumerate(((1, tau_v), (3, tau_w)), start=1):
            # sqrt(tau) (1 + sqrt(3) tau s) / (1 + tau s)^2 in controllable canonical form
            A[k, k + 1] = 1.0
            A[k + 1, k] = -1.0 / tau**2
            A[k + 1, k + 1] = -2.0 / tau
            B[k + 1, k + 1] = 1.0
            gain = math.sqrt(tau) / tau**2
            C[row, k] = gain
            C[row, k + 1] = gain * math.sqrt(3.0) * tau
        return A, B, C

    def discrete(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Exact sampling at ``dt``: ``(Ad, L_noise, C, L_stationary)`` with ``x_{k+1} = Ad x_k + L_noise n_k``
        (``n_k`` five standard normals) and the stationary state ``L_stationary n``."""
        from scipy.linalg import cholesky, expm, solve_discrete_lyapunov

        A, B, C = self.continuous()
        Q = B @ B.T
        van_loan = expm(np.block([[-A, Q], [np.zeros_like(A), A.T]]) * dt)
        Ad = van_loan[5:, 5:].T
        Qd = Ad @ van_loan[:5, 5:]
        Qd = 0.5 * (Qd + Qd.T)
        P = solve_discrete_lyapunov(Ad, Qd)
        P = 0.5 * (P + P.T)
        return Ad, _psd_factor(Qd, cholesky), C, _psd_factor(P, cholesky)

    def to_dict(self) -> dict[str, Any]:
        return {"intensity": list(self.intensity), "length_scale": list(self.length_scale),
                "airspeed": self.airspeed, "heading": self.heading}


def _psd_factor(M: np.ndarray, cholesky: Any) -> np.ndarray:
    """A lower factor ``L`` with ``L L^T = M`` for a positive semi-definite ``M`` (zero rows where it is singular)."""
    scale = np.sqrt(np.maximum(np.diag(M), 0.0))
    scale[scale == 0] = 1.0
    normed = M / np.outer(scale, scale)
    return scale[:, None] * cholesky(normed + 1e-14 * np.eye(len(M)), lower=True)


# Presets at a facade: 1.5 m up, intensities from MIL-F-8785C's low-altitude rules for a wind of
# 2 m/s (light breeze) and 5 m/s (moderate breeze) at 20 ft, the field passing at those speeds.
TURBULENCE_PRESETS: dict[str, DrydenTurbulence] = {
    "light": DrydenTurbulence.low_altitude(1.5, 2.0),
    "moderate": DrydenTurbulence.low_altitude(1.5, 5.0),
}


@dataclass(frozen=True)
class Wind:
    """A steady ``mean`` wind (m/s, world frame) and optional Dryden ``turbulence`` on top of it."""

    mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    turbulence: DrydenTurbulence | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "mean", check_vector("wind.mean (m/s)", self.mean, 3, low=-30.0, high=30.0))
        object.__setattr__(self, "turbulence", _turbulence_from_spec(self.turbulence))

    @classmethod
    def from_spec(cls, spec: Any) -> Wind:
        """``None`` (still air), a turbulence preset name (``"light"``: that turbulence in still air), a dict of
        ``mean`` and ``turbulence``, or an instance."""
        if spec is None:
            return cls()
        if isinstance(spec, Wind):
            return spec
        if isinstance(spec, str):
            return cls(turbulence=_turbulence_from_spec(spec))
        if isinstance(spec, dict):
            unknown = sorted(set(spec) - {"mean", "turbulence"})
            if unknown:
                raise ValueError(f"wind takes 'mean' (m/s) and 'turbulence'; unknown {unknown}")
            return cls(**spec)
        raise ValueError(f"wind must be None, a turbulence preset name, a dict or a Wind, got {spec!r}")

    @property
    def is_still(self) -> bool:
        return not any(self.mean) and self.turbulence is None

    def to_dict(self) -> dict[str, Any]:
        return {"mean": list(self.mean), "turbulence": None if self.turbulence is None else self.turbulence.to_dict()}


def _turbulence_from_spec(spec: Any) -> DrydenTurbulence | None:
    """``None``, a preset name (:data:`TURBULENCE_PRESETS`), a dict of :class:`DrydenTurbulence`'s fields or an instance."""
    if spec is None or isinstance(spec, DrydenTurbulence):
        return spec
    if isinstance(spec, str):
        if spec not in TURBULENCE_PRESETS:
            raise ValueError(f"wind.turbulence must be one of {sorted(TURBULENCE_PRESETS)}, a dict or None, got {spec!r}")
        return TURBULENCE_PRESETS[spec]
    if isinstance(spec, dict):
        unknown = sorted(set(spec) - {"intensity", "length_scale", "airspeed", "heading"})
        if unknown:
            raise ValueError(f"wind.turbulence takes intensity, length_scale, airspeed and heading; unknown {unknown}")
        return DrydenTurbulence(**spec)
    raise ValueError(f"wind.turbulence must be a preset name, a dict or a DrydenTurbulence, got {spec!r}")


class TurbulenceState:
    """The turbulence of ``n`` episodes sampled at ``dt``: five filter states per row, each row's intensity
    multiplied by ``scale`` (domain randomisation). Random numbers come from the caller: 6 normals per row
    at reset (the stationary start) and 6 per step."""

    NORMALS = 6

    def __init__(self, turbulence: DrydenTurbulence, n: int, dt: float):
        self.turbulence = turbulence
        self._Ad, self._L_noise, C, self._L_start = turbulence.discrete(dt)
        self._C = C * np.asarray(turbulence.intensity)[:, None]
        c, s = math.cos(turbulence.heading), math.sin(turbulence.heading)
        self._to_world = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        self._output = (self._to_world @ self._C).T  # (5, 3): state row -> world gust
        self.state = np.zeros((n, 5))
        self.scale = np.ones(n)

    def reset(self, rows: np.ndarray | slice, normals: np.ndarray, scale: np.ndarray | float = 1.0) -> None:
        self.state[rows] = normals[:, :5] @ self._L_start.T
        self.scale[rows] = scale

    def step(self, normals: np.ndarray) -> None:
        self.state = self.state @ self._Ad.T + normals[:, :5] @ self._L_noise.T

    def gust_world(self) -> np.ndarray:
        """``(n, 3)`` gust velocity (m/s, world frame) of every row now."""
        return (self.state @ self._output) * self.scale[:, None]
