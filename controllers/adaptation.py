"""Learning the wall in flight: an online estimate of the suction's ``k_s`` and ``d_thr`` and of a residual force.

SC-MPC is told a suction model (the paper's identified ``k_s`` = 4.1 N/m, ``d_thr`` =
0.132 m) that a real wall need not follow, and a real flight adds forces no model has
(a push, a mass or thrust error, wind). ``SCMPC(..., adapt=True)`` predicts with
``wall_suction(k_s, d_thr) + constant_force(F)`` on top of its nominal model and
re-estimates ``theta = (k_s, d_thr, F_x, F_y, F_z)`` at every control step from what the
flight shows: the force residual of the paper's Eq. 28 at each step,

    y_k = m (v_k - v_{k-1}) / dt + m g e3 - R e3 T_{k-1} - F_known

(``R`` at the midpoint of the step, ``T_{k-1}`` the thrust the controller commanded over
it, ``F_known`` the rest of the prediction model, e.g. the vehicle's drag; all from the
observations and the controller's own commands, nothing from the simulator), fitted by

    y_k ~ k_s S(p_k, R_k; d_thr) + F

where ``S(.; d_thr)`` is the ``wall_suction`` effect's force at ``k_s = 1`` -- the effect's
CasADi definition, the simulator's and the MPC's, compiled for the batch -- which is linear
in ``k_s`` and piecewise linear in ``d_thr``. The fit is recursive least squares with
exponential forgetting over ``window`` seconds, solved exactly for ``k_s`` and ``F`` at each
threshold of a grid (``threshold_grid``), and the threshold whose fit leaves the least
residual wins: a global search in ``d_thr``, so a wall that pulls from further out than
told is found as soon as the vehicle crosses that distance (a gradient method sees no
slope in ``d_thr`` while every rotor is outside the current estimate). The running sums
make each step's cost a few operations per threshold.

Weak priors toward the told model (``prior_std``, scaled by the fit's own residual
variance, so that they weigh the same whatever the sensing noise) keep ``k_s`` and
``d_thr`` where the flight says nothing (far from the wall, or always inside the
threshold, where ``d_thr`` and a residual force along the wall normal cannot be told
apart: only their sum is). The estimate that the controller predicts with moves toward
each step's fit at most ``max_rate`` per second and stays within the bounds: bounded
and smooth. What it estimates is in :attr:`OnlineSuctionEstimator.theta` and, step by step,
in the policy's ``estimate_history``.

Among bodies (boxes, cylinders, meshes) ``S`` reads each rotor's local surfaces at the step's
midpoint, from the policy's PyBullet query (:class:`~wall_env.surfaces.SurfaceQuery`), so a
facade's window or a pier's curve is not mistaken for a change of the wall's parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from wall_env.aero import AeroModel, symbolic_scene
from wall_env.codegen import BatchedFunction
from wall_env.effects import FlightContext
from wall_env.observation import OBSERVATION_FIELDS
from wall_env.scene import Scene
from wall_env.validation import check_positive, check_range, check_vector
from wall_env.vehicle import GRAVITY, VehicleParams

__all__ = ["AdaptationSettings", "OnlineSuctionEstimator", "ESTIMATED", "RESIDUAL_EFFECT"]

ESTIMATED = ("k_s", "d_thr", "F_x", "F_y", "F_z")  # the estimated parameters, in order (N/m, m, N, N, N)
RESIDUAL_EFFECT = "constant_force"  # the effect that carries the residual force in the prediction model

_OBS_P, _OBS_V = OBSERVATION_FIELDS["p_world"], OBSERVATION_FIELDS["v_world"]
_OBS_R = OBSERVATION_FIELDS["R_body_to_world"]
_OBS_W = OBSERVATION_FIELDS["omega_body"]
_OBS_TIME = OBSERVATION_FIELDS["time"].start


@dataclass(frozen=True)
class AdaptationSettings:
    """Settings of :class:`OnlineSuctionEstimator` (SI units)."""

    window: float = 4.0  # s, the time constant of the least squares' exponential forgetting
    threshold_grid: tuple[float, float, float] = (0.04, 0.30, 0.0025)  # m: first, last, step of the d_thr grid
    k_s_bounds: tuple[float, float] = (0.0, 40.0)  # N/m
    force_bound: float = 5.0  # N, largest residual force per axis
    prior_std: tuple[float, float, float] = (4.0, 0.03, 2.0)  # k_s (N/m), d_thr (m), force (N) around the told model
    max_rate: tuple[float, float, float] = (20.0, 0.1, 5.0)  # k_s (N/m/s), d_thr (m/s), force (N/s)

    def __post_init__(self) -> None:
        check_positive("adaptation.window (s)", self.window, 1000.0)
        first, last, step = check_vector("adaptation.threshold_grid (m)", self.threshold_grid, 3, low=0.0, high=1.0)
        if not (0 < first < last and 0 < step <= last - first):
            raise ValueError(f"adaptation.threshold_grid must be (first, last, step) with 0 < first < last and "
                             f"0 < step <= last - first, got {self.threshold_grid}")
        low, high = check_vector("adaptation.k_s_bounds (N/m)", self.k_s_bounds, 2, low=0.0, high=1000.0)
        if low >= high:
            raise ValueError(f"adaptation.k_s_bounds must be (low, high) with low < high, got {self.k_s_bounds}")
        check_positive("adaptation.force_bound (N)", self.force_bound, 1000.0)
        check_vector("adaptation.prior_std", self.prior_std, 3, low=1e-9, high=1e6)
        check_vector("adaptation.max_rate", self.max_rate, 3, low=1e-9, high=1e6)

    @classmethod
    def from_spec(cls, spec: Any) -> AdaptationSettings:
        """``True`` or ``None`` (the defaults), a dict of this class's fields, or an instance."""
        if spec is None or spec is True:
            return cls()
        if isinstance(spec, AdaptationSettings):
            return spec
        if isinstance(spec, dict):
            known = set(cls.__dataclass_fields__)
            unknown = sorted(map(str, set(spec) - known))
            if unknown:
                raise ValueError(f"adapt settings take {sorted(known)}; unknown {unknown}")
            return cls(**spec)
        raise ValueError(f"adapt must be True, False, a dict of AdaptationSettings fields or an instance, got {spec!r}")

    def thresholds(self) -> np.ndarray:
        first, last, step = self.threshold_grid
        return np.arange(first, last + 0.5 * step, step)


def _force_function(model: AeroModel, vehicle: VehicleParams, scene_structure: tuple, thresholds: np.ndarray
                    ) -> ca.Function:
    """``estimator_forces(p, R[9], v, omega, T, mass, theta, scene) -> (F_known[3], S[3 x C])``: the prediction
    model's force without the suction and the residual, and the ``wall_suction`` effect's force at ``k_s = 1``
    for each threshold of ``thresholds`` (each rotor carrying ``T / 4``)."""
    p, v, omega = ca.SX.sym("p_world", 3), ca.SX.sym("v_world", 3), ca.SX.sym("omega_body", 3)
    R_flat = ca.SX.sym("R_body_to_world", 9)
    R = ca.reshape(R_flat, 3, 3)
    thrust, mass = ca.SX.sym("T"), ca.SX.sym("mass")
    theta = ca.SX.sym("theta", model.param_size)
    scene_symbols, scene_vector = symbolic_scene(scene_structure)
    ctx = FlightContext(p, R, v, omega, ca.repmat(thrust / 4, 4, 1), vehicle.rotor_positions_array, mass, GRAVITY,
                        scene_symbols)
    known = ca.SX.zeros(3)
    basis = ca.SX.zeros(3, len(thresholds))
    for effect, sl in zip(model.effects, model.slices()):
        if not effect.applies_to(scene_structure):
            continue
        values = effect.unpack(theta[sl])
        if effect.name == "wall_suction":
            basis = ca.horzcat(*[effect.wrench(ctx, {**values, "k_s": 1.0, "d_thr": float(d)}).force_world
                                 for d in thresholds])
        elif effect.name != RESIDUAL_EFFECT:
            known += effect.wrench(ctx, values).force_world
    return ca.Function("estimator_forces", [p, R_flat, v, omega, thrust, mass, theta, scene_vector], [known, basis])


class OnlineSuctionEstimator:
    """The least-squares estimate of the module docstring for a batch of ``n`` vehicles.

    ``model`` is the prediction model (with ``wall_suction`` and :data:`RESIDUAL_EFFECT`);
    :attr:`theta` ``(n, 5)`` holds each row's estimate of :data:`ESTIMATED` (the one the controller
    predicts with), :meth:`model_theta` the whole model parameter vector of each row with it written in.
    """

    def __init__(self, model: AeroModel, vehicle: VehicleParams, scene: Scene, control_dt: float,
                 settings: AdaptationSettings | None = None, surfaces: Any = None):
        if model.get("wall_suction") is None or model.get(RESIDUAL_EFFECT) is None:
            raise ValueError(f"the adaptive model needs wall_suction and {RESIDUAL_EFFECT}")
        self.model = model
        self.vehicle = vehicle
        self.settings = settings or AdaptationSettings()
        if scene.has_bodies and surfaces is None:
            raise ValueError("a scene with bodies needs the policy's SurfaceQuery (surfaces=...)")
        self.surfaces = surfaces if scene.has_bodies else None  # wall_env.surfaces.SurfaceQuery
        self._plane_size = scene.structure.plane_size
        self.dt = check_range("control_dt", control_dt, 1e-4, 1.0)
        labels = model.param_labels()
        self.columns = np.array([labels.index("wall_suction.k_s"), labels.index("wall_suction.d_thr"),
                                 *[labels.index(f"{RESIDUAL_EFFECT}.F[{i}]") for i in range(3)]])
        self.theta0 = model.theta()[self.columns]
        # the grid, with the told threshold on it (so that a flight that says nothing keeps it exactly)
        self.thresholds = np.union1d(self.settings.thresholds(), [self.theta0[1]])
        self._function = BatchedFunction(_force_function(model, vehicle, scene.structure, self.thresholds))
        s = self.settings
        self._forget = math.exp(-self.dt / s.window)
        self._step_limit = np.array([s.max_rate[0], s.max_rate[1], *[s.max_rate[2]] * 3]) * self.dt
        self._low = np.array([s.k_s_bounds[0], self.thresholds[0], *[-s.force_bound] * 3])
        self._high = np.array([s.k_s_bounds[1], self.thresholds[-1], *[s.force_bound] * 3])
        self.resize(0)

    def resize(self, n: int) -> None:
        self.n = n
        C = len(self.thresholds)
        self.theta = np.tile(self.theta0, (n, 1))
        self.fit = self.theta.copy()  # each row's latest least-squares optimum
        # running sums with forgetting: the sample count, sum y, sum |y|^2, and per threshold
        # sum S.S, sum S (3), sum S.y
        self._count = np.zeros(n)
        self._y = np.zeros((n, 3))
        self._yy = np.zeros(n)
        self._SS = np.zeros((n, C))
        self._S = np.zeros((n, C, 3))
        self._Sy = np.zeros((n, C))
        self._previous: np.ndarray | None = None
        self._has_previous = np.zeros(n, dtype=bool)
        self._inputs = [np.zeros((n, k)) for k in self._function.nnz_in]
        self._outputs = self._function.outputs(n)
        self._function.bind(self._inputs, self._outputs)

    def start(self, rows: np.ndarray) -> None:
        """New episodes in the bool mask ``rows``: back to the told model, no data."""
        self.theta[rows] = self.theta0
        self.fit[rows] = self.theta0
        for array in (self._count, self._y, self._yy, self._SS, self._S, self._Sy):
            array[rows] = 0.0
        self._has_previous[rows] = False

    def model_theta(self, base: np.ndarray) -> np.ndarray:
        """``base`` (the model's parameter vector) per row with each row's estimate written in: ``(n, P)``."""
        out = np.tile(base, (self.n, 1))
        out[:, self.columns] = self.theta
        return out

    def update(self, observations: np.ndarray, thrust: np.ndarray, mass: float, scene_vectors: np.ndarray) -> None:
        """One step per row from the new ``observations`` ``(n, 48)``, the collective thrust ``(n,)`` (N)
        commanded since the previous ones (NaN: unknown), the model ``mass`` and each row's scene ``(n, S)``."""
        obs = np.asarray(observations, dtype=float)
        finite = np.all(np.isfinite(obs), axis=1)
        if self._previous is not None:
            usable = self._has_previous & finite & np.isfinite(thrust)
            usable &= np.abs(obs[:, _OBS_TIME] - self._previous[:, _OBS_TIME] - self.dt) < 0.5 * self.dt
            if usable.any():
                self._accumulate(self._previous, obs, thrust, mass, scene_vectors, usable)
        self._previous = obs.copy()
        self._has_previous = finite
        self._solve()

    # ------------------------------------------------------------------ least squares
    def _accumulate(self, prev: np.ndarray, obs: np.ndarray, thrust: np.ndarray, mass: float,
                    scene_vectors: np.ndarray, usable: np.ndarray) -> None:
        n = self.n
        R_mid = 0.5 * (prev[:, _OBS_R] + obs[:, _OBS_R]).reshape(n, 3, 3)
        T = np.where(np.isfinite(thrust), thrust, 0.0)
        inputs = self._inputs
        inputs[0][:] = 0.5 * (prev[:, _OBS_P] + obs[:, _OBS_P])
        inputs[1][:] = R_mid.transpose(0, 2, 1).reshape(n, 9)  # column-major
        inputs[2][:] = 0.5 * (prev[:, _OBS_V] + obs[:, _OBS_V])
        inputs[3][:] = 0.5 * (prev[:, _OBS_W] + obs[:, _OBS_W])
        inputs[4][:, 0] = T
        inputs[5][:, 0] = mass
        inputs[6][:] = self.model_theta(self.model.theta())
        inputs[7][:] = scene_vectors
        if self.surfaces is not None:  # the rotors' local surfaces at the midpoint
            inputs[7][:, self._plane_size:] = self.surfaces.rotor_surfaces_at(inputs[0], R_mid)
        self._function()
        known, basis = self._outputs
        S = basis.reshape(n, len(self.thresholds), 3)  # column-major 3 x C per row: [row, threshold, axis]
        y = (mass * (obs[:, _OBS_V] - prev[:, _OBS_V]) / self.dt + mass * np.array([0.0, 0.0, GRAVITY])
             - R_mid[:, :, 2] * T[:, None] - known)
        lam = np.where(usable, self._forget, 1.0)
        add = usable.astype(float)
        self._count = lam * self._count + add
        self._y = lam[:, None] * self._y + add[:, None] * y
        self._yy = lam * self._yy + add * (y * y).sum(axis=1)
        self._SS = lam[:, None] * self._SS + add[:, None] * (S * S).sum(axis=2)
        self._S = lam[:, None, None] * self._S + add[:, None, None] * S
        self._Sy = lam[:, None] * self._Sy + add[:, None] * (S * y[:, None, :]).sum(axis=2)

    def _solve(self) -> None:
        """Each row's best (k_s, F) at every threshold, the threshold with the least cost, and the bounded,
        rate-limited move of :attr:`theta` toward it."""
        s = self.settings
        k0, d0 = self.theta0[0], self.theta0[1]
        N = self._count[:, None]
        # the fit's residual variance per sample scales the priors (a prior weighs as many samples
        # whatever the noise); at the start, before any data, the priors alone decide
        variance = np.maximum(self._noise_estimate(), 1e-6)[:, None]
        w_k = variance / s.prior_std[0] ** 2
        w_F = variance / s.prior_std[2] ** 2
        w_d = variance / s.prior_std[1] ** 2
        denominator = N + w_F
        Sy_sum = (self._S * self._y[:, None, :]).sum(axis=2)
        S2 = (self._S * self._S).sum(axis=2)
        k = (self._Sy - Sy_sum / denominator + w_k * k0) / np.maximum(self._SS - S2 / denominator + w_k, 1e-12)
        k = np.clip(k, s.k_s_bounds[0], s.k_s_bounds[1])
        F = (self._y[:, None, :] - k[:, :, None] * self._S) / denominator[:, :, None]
        F = np.clip(F, -s.force_bound, s.force_bound)
        # cost: sum |y - k S - F|^2 + the priors, per threshold
        cost = (self._yy[:, None] - 2 * k * self._Sy - 2 * (F * self._y[:, None, :]).sum(axis=2) + k * k * self._SS
                + 2 * k * (F * self._S).sum(axis=2) + N * (F * F).sum(axis=2)
                + w_k * (k - k0) ** 2 + w_F * (F * F).sum(axis=2) + w_d * (self.thresholds[None, :] - d0) ** 2)
        best = np.argmin(cost, axis=1)
        rows = np.arange(self.n)
        self.fit = np.column_stack([k[rows, best], self.thresholds[best], F[rows, best]])
        step = np.clip(self.fit - self.theta, -self._step_limit, self._step_limit)
        self.theta = np.clip(self.theta + step, self._low, self._high)

    def _noise_estimate(self) -> np.ndarray:
        """Per row, the residual variance per sample of the fit at the current estimate (N^2), from the sums."""
        k = self.theta[:, 0]
        index = np.clip(np.searchsorted(self.thresholds, self.theta[:, 1]), 0, len(self.thresholds) - 1)
        rows = np.arange(self.n)
        S, SS, Sy = self._S[rows, index], self._SS[rows, index], self._Sy[rows, index]
        F = self.theta[:, 2:5]
        cost = (self._yy - 2 * k * Sy - 2 * (F * self._y).sum(axis=1) + k * k * SS + 2 * k * (F * S).sum(axis=1)
                + self._count * (F * F).sum(axis=1))
        return np.maximum(cost, 0.0) / np.maximum(self._count, 1.0)
