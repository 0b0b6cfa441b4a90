"""The MPC problem of the paper (Sec. 3.3, Eq. 12-27): residual blocks, weights and model.

The decision variables are the inputs ``u_0 .. u_{N-1}`` (collective thrust T in N,
body rates in rad/s) and the states ``x_1 .. x_N = (p_world, R_body_to_world,
v_world)`` on their manifold; ``x_0`` is the measured state (Eq. 12's constraint
``x_0 = x_init``). They are grouped in blocks ``(u_k, x_{k+1})``
(:mod:`controllers.mpc.manifold`). The authors' release keeps ``x_0`` as a variable
with a prior of sigma 0.001; the paper's Eq. 12 fixes it, which is done here (a
prior that tight would move ``x_0`` by tens of micrometres and only add variables).

The cost is a sum over stages ``k = 0 .. N-1`` of squared weighted residuals, each
stage touching only its own block and the previous one (block ``k - 1`` =
``(u_{k-1}, x_k)``; for ``k = 0`` the fixed ``(-, x_init)``, whose input slot no
residual reads), which makes the normal equations block-tridiagonal:

==========  =====  ===============================================================
block       rows   residual (each multiplied by 1 / sigma)
==========  =====  ===============================================================
dynamics    9      Eq. 15: ``p_{k+1} - p_k - dt v_k - dt^2/2 a_k``,
                   ``Log(R_k^T R_{k+1}) - dt omega_k``, ``v_{k+1} - v_k - dt a_k``
reference   9      Eq. 25 at ``x_{k+1}``: ``p - p_ref``, ``Log(R^T R_ref)``, ``v - v_ref``
terminal    3      ``p_N - p_ref,N`` (only in the last stage)
rate        4      Eq. 27: ``u_{k-1} - u_k`` (stages 1 .. N-1, as in Eq. 12)
limit       4      Eq. 26: ``max(u_k - u_max, 0) + max(u_min - u_k, 0)``
==========  =====  ===============================================================

The acceleration of the dynamics residual is the paper's Eq. 13,

    a_k = -g e3 + (R_k e3 T_k + F_aero(x_k, u_k)) / m

where ``F_aero`` is the force of a :class:`wall_env.aero.AeroModel` -- the same
symbolic effect definitions the simulator integrates -- evaluated with each rotor
carrying ``T_k / 4``. The nominal MPC's model is the vehicle's linear drag; SC-MPC's
adds ``wall_suction`` (and whatever else a model file holds). No force formula is
written here. The paper's Eq. 13 has no moment, and the inputs are body rates, so
the model's moment is not used.

Weights are ``1 / sigma^2``; the defaults are the authors' released standard
deviations (the ``paper`` preset, :mod:`controllers.presets`; the tuned presets
replace them). The control-limit sigma is not in
their notes; 0.01 (in the input's unit) is our choice, which makes a 0.1 N or
0.1 rad/s violation cost as much as a 1.5 m position error at one stage. The
thrust penalty starts ``thrust_margin`` = 1 N inside ``[5, 27] N`` as theirs does.

Numeric values that may change between solves (reference, weights, limits, mass,
model parameters ``theta``, wall geometry, ``dt``) are parameters of the symbolic
functions, so changing them never regenerates code; only the model's structure
(which effects), the rotor layout and the horizon length do.

**Scenes with bodies** (boxes, cylinders, meshes: :mod:`wall_env.bodies`). The suction of
stage ``k`` is the model's force at the predicted state ``x_k`` with each rotor's local
surfaces there (:mod:`wall_env.surfaces`): the stage parameters then end with those
surfaces (:data:`~wall_env.scene.SURFACE_SIZE` numbers per slot and rotor, as in the
scene vector), which the policy fills in from PyBullet's query at the states its warm
start predicts (:class:`~controllers.mpc.policy.MPC`), and the global parameters hold the
scene's planes only. Over a face the prediction is exact; at an edge, in a recess or
around a curve, each stage sees the surfaces where the vehicle is predicted to be.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from controllers.mpc.manifold import POINT_SIZE, unpack_point
from wall_env.aero import AeroModel, symbolic_scene
from wall_env.effects import FlightContext
from wall_env.rotations import so3_log
from wall_env.scene import Scene
from wall_env.validation import check_range, check_vector
from wall_env.vehicle import GRAVITY, VehicleParams

__all__ = ["MPCWeights", "InputLimits", "MPCProblem", "RESIDUAL_SIZE", "STAGE_PARAM_SIZE"]

RESIDUAL_SIZE = 29  # dynamics 9, reference 9, terminal 3, rate 4, limit 4
STAGE_PARAM_SIZE = 17  # p_ref 3, v_ref 3, R_ref 9, terminal flag, rate flag


class StageParamIndex:
    p_ref = slice(0, 3)
    v_ref = slice(3, 6)
    R_ref = slice(6, 15)
    terminal = 15
    rate = 16


@dataclass(frozen=True)
class MPCWeights:
    """Standard deviations of the residual blocks (weight = 1 / sigma^2), SI units.

    Defaults: the authors' release (position 0.15/0.15/0.20 m, terminal position
    0.05 m, rotation 0.3/0.3/0.03 rad, velocity 2.3 m/s, dynamics 1e-4, control rate
    0.2 N / 0.1 / 0.1 / 0.01 rad/s) and our control-limit sigma 0.01.
    """

    position: tuple[float, float, float] = (0.15, 0.15, 0.20)
    rotation: tuple[float, float, float] = (0.3, 0.3, 0.03)
    velocity: tuple[float, float, float] = (2.3, 2.3, 2.3)
    terminal_position: tuple[float, float, float] = (0.05, 0.05, 0.05)
    dynamics: tuple[float, ...] = (1e-4,) * 9
    control_rate: tuple[float, float, float, float] = (0.2, 0.1, 0.1, 0.01)
    control_limit: tuple[float, float, float, float] = (0.01, 0.01, 0.01, 0.01)

    def __post_init__(self) -> None:
        sizes = {"position": 3, "rotation": 3, "velocity": 3, "terminal_position": 3, "dynamics": 9,
                 "control_rate": 4, "control_limit": 4}
        for name, size in sizes.items():
            value: Any = getattr(self, name)
            if isinstance(value, (int, float, np.floating, np.integer)):
                value = (float(value),) * size
            object.__setattr__(self, name, check_vector(f"weights.{name}", value, size, low=1e-9, high=1e9))

    def inverse_sigmas(self) -> np.ndarray:
        """``1 / sigma`` for the 29 residual rows, in the order of the residual vector."""
        sigmas = np.concatenate([
            self.dynamics,  # p, theta, v
            self.position, self.rotation, self.velocity,
            self.terminal_position,
            self.control_rate,
            self.control_limit,
        ])
        return 1.0 / sigmas


@dataclass(frozen=True)
class InputLimits:
    """Input bounds of the limit residual (Eq. 26). Defaults: the authors' release."""

    thrust_min: float = 5.0  # N
    thrust_max: float = 27.0  # N
    thrust_margin: float = 1.0  # N, the penalty starts this far inside the bounds
    body_rate_max: float = 3.0  # rad/s, per axis

    def __post_init__(self) -> None:
        check_range("limits.thrust_min", self.thrust_min, 0.0, 1e3)
        check_range("limits.thrust_max", self.thrust_max, self.thrust_min, 1e3)
        check_range("limits.thrust_margin", self.thrust_margin, 0.0, (self.thrust_max - self.thrust_min) / 2)
        check_range("limits.body_rate_max", self.body_rate_max, 1e-3, 100.0)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the penalty starts: ``(u_low, u_high)`` for ``[T, wx, wy, wz]``."""
        w = self.body_rate_max
        low = np.array([self.thrust_min + self.thrust_margin, -w, -w, -w])
        high = np.array([self.thrust_max - self.thrust_margin, w, w, w])
        return low, high


class MPCProblem:
    """Symbolic residuals and numeric parameters of one MPC configuration.

    ``global parameters`` (one vector, see :meth:`global_params`):
    ``[dt, mass, 1/sigma (29), u_low (4), u_high (4), theta (model), scene (walls, ground, ceiling)]``.
    ``stage parameters`` (:attr:`stage_size` per stage, see :meth:`stage_params`):
    ``[p_ref (3), v_ref (3), R_ref (9, column-major), terminal flag, rate flag]`` of the
    state ``x_{k+1}`` the stage ends in, then, for a scene with bodies, the local surfaces
    of the rotors at the state ``x_k`` the stage starts from (:attr:`surface_size` numbers).
    """

    def __init__(self, vehicle: VehicleParams, model: AeroModel, scene: Scene, horizon: int = 20,
                 dt: float = 0.01, weights: MPCWeights | None = None, limits: InputLimits | None = None):
        if not isinstance(horizon, (int, np.integer)) or not 2 <= horizon <= 200:
            raise ValueError(f"horizon must be an integer in [2, 200], got {horizon!r}")
        self.horizon = int(horizon)
        self.dt = check_range("dt", dt, 1e-4, 1.0)
        self.vehicle = vehicle
        self.model = model
        self.scene = scene
        self.weights = weights if weights is not None else MPCWeights()
        self.limits = limits if limits is not None else InputLimits()
        self.rotor_positions_body = vehicle.rotor_positions_array
        self.scene_structure = scene.structure
        self.plane_size = scene.structure.plane_size
        self.surface_size = scene.vector_size - self.plane_size  # per stage: the rotors' local surfaces
        self.stage_size = STAGE_PARAM_SIZE + self.surface_size
        self.global_size = 2 + RESIDUAL_SIZE + 8 + model.param_size + self.plane_size
        self._residual: ca.Function | None = None
        self._aero_force: ca.Function | None = None

    @property
    def structure_key(self) -> tuple:
        """What the generated code depends on: model structure, rotor layout, scene structure, horizon."""
        return (self.model.structure_key, tuple(map(tuple, self.rotor_positions_body)), self.scene_structure,
                self.horizon)

    # ------------------------------------------------------------------ numeric parameters
    def global_params(self, mass: float | None = None, scene: Scene | None = None) -> np.ndarray:
        """The global parameter vector; ``scene`` replaces the problem's walls (same structure)."""
        scene = self.scene if scene is None else scene
        if scene.structure != self.scene_structure:
            raise ValueError(f"scene must have the structure the problem was built for, {self.scene_structure}, "
                             f"got {scene.structure}")
        low, high = self.limits.bounds()
        return np.concatenate([
            [self.dt, self.vehicle.mass if mass is None else mass],
            self.weights.inverse_sigmas(), low, high,
            self.model.theta(), scene.to_vector()[: self.plane_size],
        ])

    @property
    def theta_slice(self) -> slice:
        """Where the model's parameters ``theta`` sit in the global parameter vector."""
        start = 2 + RESIDUAL_SIZE + 8
        return slice(start, start + self.model.param_size)

    def stage_params(self, p_ref: np.ndarray, v_ref: np.ndarray, R_ref: np.ndarray,
                     surfaces: np.ndarray | None = None) -> np.ndarray:
        """Stage parameters ``(stage_size, N)`` for references of ``x_1 .. x_N`` (``(N, 3)``, ``(N, 3)``,
        ``(N, 3, 3)``) and, with bodies, the rotors' local surfaces at ``x_0 .. x_{N-1}``
        (``(surface_size, N)``; default: none felt)."""
        N = self.horizon
        S = np.zeros((self.stage_size, N))
        if self.surface_size:
            S[STAGE_PARAM_SIZE:] = (np.asarray(surfaces) if surfaces is not None
                                    else self.scene.to_vector()[self.plane_size:, None])
        S[StageParamIndex.p_ref] = np.asarray(p_ref).T
        S[StageParamIndex.v_ref] = np.asarray(v_ref).T
        # column-major flattening of each R, as CasADi's reshape reads it
        S[StageParamIndex.R_ref] = np.asarray(R_ref).transpose(0, 2, 1).reshape(N, 9).T
        S[StageParamIndex.terminal:] = self.stage_flags()
        return S

    def stage_flags(self) -> np.ndarray:
        """The last rows of the stage parameters, ``(2, N)``: the terminal flag (last stage only) and
        the rate flag (every stage but the first, which has no previous input in the horizon)."""
        flags = np.zeros((STAGE_PARAM_SIZE - StageParamIndex.terminal, self.horizon))
        flags[StageParamIndex.terminal - StageParamIndex.terminal, -1] = 1.0
        flags[StageParamIndex.rate - StageParamIndex.terminal, 1:] = 1.0
        return flags

    # ------------------------------------------------------------------ symbolic
    def _split_global(self, g):
        i = 0
        dt, mass = g[0], g[1]
        i = 2
        inv_sigma = g[i:i + RESIDUAL_SIZE]
        i += RESIDUAL_SIZE
        u_low, u_high = g[i:i + 4], g[i + 4:i + 8]
        i += 8
        theta = g[i:i + self.model.param_size]
        i += self.model.param_size
        scene = g[i:i + self.plane_size]
        return dt, mass, inv_sigma, u_low, u_high, theta, scene

    def aero_force(self, p, R, v, u, mass, theta, scene_vector) -> ca.SX:
        """``F_aero`` (N, world frame) of the model, each rotor carrying ``T / 4``, body rates ``u[1:4]``."""
        scene_symbols, scene_placeholder = symbolic_scene(self.scene_structure)
        ctx = FlightContext(p, R, v, u[1:4], ca.repmat(u[0] / 4, 4, 1), self.rotor_positions_body, mass,
                            GRAVITY, scene_symbols)
        wrench, _ = self.model.wrench(ctx, theta, self.scene_structure)
        return ca.substitute(wrench.force_world, scene_placeholder, scene_vector)

    def acceleration(self, p, R, v, u, mass, theta, scene_vector) -> ca.SX:
        """Eq. 13: ``-g e3 + (R e3 T + F_aero) / m``."""
        force = self.aero_force(p, R, v, u, mass, theta, scene_vector)
        return (R[:, 2] * u[0] + force) / mass - ca.DM([0.0, 0.0, GRAVITY])

    def residual_function(self) -> ca.Function:
        """``mpc_stage_residual(prev_point[19], point[19], stage[stage_size], global) -> r[29]`` (weighted, SX)."""
        if self._residual is None:
            prev = ca.SX.sym("prev_point", POINT_SIZE)
            cur = ca.SX.sym("point", POINT_SIZE)
            s = ca.SX.sym("stage", self.stage_size)
            g = ca.SX.sym("global", self.global_size)
            self._residual = ca.Function("mpc_stage_residual", [prev, cur, s, g], [self.residual(prev, cur, s, g)],
                                         ["prev_point", "point", "stage", "global"], ["r"])
        return self._residual

    def residual(self, prev, cur, s, g) -> ca.SX:
        dt, mass, inv_sigma, u_low, u_high, theta, scene = self._split_global(g)
        if self.surface_size:  # the rotors' local surfaces at x_k, where the stage's force is taken
            scene = ca.vertcat(scene, s[STAGE_PARAM_SIZE:])
        u_prev, p_k, R_k, v_k = unpack_point(prev)
        u_k, p_n, R_n, v_n = unpack_point(cur)
        # the state x_k and input u_k drive the dynamics to x_{k+1} = (p_n, R_n, v_n)
        a_k = self.acceleration(p_k, R_k, v_k, u_k, mass, theta, scene)
        r_dyn = ca.vertcat(
            p_n - p_k - dt * v_k - 0.5 * dt**2 * a_k,
            so3_log(R_k.T @ R_n) - dt * u_k[1:4],
            v_n - v_k - dt * a_k,
        )
        R_ref = ca.reshape(s[StageParamIndex.R_ref], 3, 3)
        r_ref = ca.vertcat(p_n - s[StageParamIndex.p_ref], so3_log(R_n.T @ R_ref), v_n - s[StageParamIndex.v_ref])
        r_term = s[StageParamIndex.terminal] * (p_n - s[StageParamIndex.p_ref])
        r_rate = s[StageParamIndex.rate] * (u_prev - u_k)
        r_lim = ca.fmax(u_k - u_high, 0) + ca.fmax(u_low - u_k, 0)
        return inv_sigma * ca.vertcat(r_dyn, r_ref, r_term, r_rate, r_lim)

    def aero_force_function(self) -> ca.Function:
        """``mpc_aero_force(p[3], R[9, column-major], v[3], u[4], global, surfaces[surface_size]) -> F_aero[3]``
        (N, world); ``surfaces``: the rotors' local surfaces at ``p`` (empty for a scene of planes only)."""
        if self._aero_force is None:
            p, v = ca.SX.sym("p_world", 3), ca.SX.sym("v_world", 3)
            R = ca.SX.sym("R_body_to_world", 9)
            u = ca.SX.sym("u", 4)
            g = ca.SX.sym("global", self.global_size)
            surfaces = ca.SX.sym("surfaces", self.surface_size)
            _, mass, _, _, _, theta, scene = self._split_global(g)
            force = self.aero_force(p, ca.reshape(R, 3, 3), v, u, mass, theta, ca.vertcat(scene, surfaces))
            self._aero_force = ca.Function("mpc_aero_force", [p, R, v, u, g, surfaces], [force])
        return self._aero_force
