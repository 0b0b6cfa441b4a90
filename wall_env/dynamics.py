"""The simulator's flight dynamics, one control step as one compiled CasADi function.

State ``x`` (17 numbers, :mod:`wall_env.state`): ``p_world`` (3, m), ``q_body_to_world``
(4, [w, x, y, z]), ``v_world`` (3, m/s), ``omega_body`` (3, rad/s), ``rotor_thrusts`` (4, N).

Input ``u`` (4 numbers): collective thrust command ``T`` (N) and body-rate command
``omega_cmd`` (3, rad/s), command noise already added, held over the control step.
Per-vehicle conditions (:class:`Timing`, :mod:`wall_env.conditions`): a command that
arrives late flies ``u_previous`` for the first ``command_switch`` substeps; the state
after ``observe_after`` substeps is returned beside the final one (what a late estimate
shows); ``motor_time_constant`` is each vehicle's rotor lag when the step is built with
lag.

At the physics rate (``substeps`` per control step, RK4 each) the vehicle's inner loop
does what a flight controller's rate loop does:

1. body-rate controller: ``tau_des = J K (omega_cmd - omega) + omega x J omega``;
2. mixer: rotor thrusts ``f_des = mixer [T; tau_des]``, clipped to ``[0, thrust_max / 4]``;
3. optional first-order motor lag ``df/dt = (f_des - f) / tau_m`` (:mod:`wall_env.motor_lag`; otherwise,
   and for a vehicle whose ``tau_m`` is 0, ``f = f_des``);
4. rigid body (paper Eq. 3 with Eq. 5's extra force):
   ``dp/dt = v``, ``dv/dt = -g e3 + (R e3 sum(f) + F_aero) / m``,
   ``dq/dt = q * [0, omega] / 2``, ``J domega/dt = tau(f) + M_aero - omega x J omega``

where ``F_aero, M_aero`` is the :class:`~wall_env.aero.AeroModel` wrench (drag, wall
suction and any other effects), the same symbolic definition the MPC and the
identification code use.

Why 1 kHz physics under 100 Hz control: the rate loop has a 20 ms time constant and
motor lag can be a few ms; ten RK4 substeps keep the integration error of those fast
modes far below the command noise, and because the whole control step is one native
call the substeps cost microseconds. RK4 needs ``tau_m`` of at least a physics step to
follow a lag (:data:`wall_env.motor_lag.MIN_LAG_STEPS`).
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import casadi as ca
import numpy as np

from wall_env.aero import AeroModel, symbolic_scene
from wall_env.codegen import NATIVE_FLAGS, BatchedFunction, CompiledFunction
from wall_env.contact import collision_shapes, contact_response, plane_clearances, scene_planes
from wall_env.effects import FlightContext
from wall_env.motor_lag import thrust_rate
from wall_env.rotations import quat_multiply, quat_to_rotation
from wall_env.scene import Scene
from wall_env.state import STATE_SIZE, StateIndex
from wall_env.vehicle import GRAVITY, VehicleParams

__all__ = ["STATE_SIZE", "StateIndex", "Timing", "build_step_function", "build_env_step_function",
           "Simulator", "BatchSimulator"]

def _commanded_rotor_thrusts(vehicle: VehicleParams, omega: ca.SX, u: ca.SX) -> ca.SX:
    """Rate loop and mixer: rotor thrusts for command ``u`` at body rates ``omega``, clipped to the rotor limits."""
    J = ca.DM(vehicle.inertia)
    gyro = ca.cross(omega, J * omega)
    tau_des = J * ca.DM(vehicle.rate_gains) * (u[1:4] - omega) + gyro
    f_des = ca.DM(vehicle.mixer_matrix) @ ca.vertcat(u[0], tau_des)
    return ca.fmin(ca.fmax(f_des, 0.0), vehicle.rotor_thrust_max)


class Timing:
    """Entries of the per-vehicle ``timing`` input of the control step."""

    command_switch = 0  # substeps (0..substeps) that still fly u_previous
    observe_after = 1  # substeps (0..substeps) after which the state is sampled into x_observed
    motor_time_constant = 2  # s, the rotor lag (used when the step is built with lag)
    size = 3


def _continuous_dynamics(vehicle: VehicleParams, model: AeroModel, scene_structure: tuple, lagged: bool) -> ca.Function:
    x = ca.SX.sym("x", STATE_SIZE)
    u = ca.SX.sym("u", 4)
    tau_m = ca.SX.sym("motor_time_constant")
    mass = ca.SX.sym("mass")
    theta = ca.SX.sym("theta", model.param_size)
    scene_symbols, scene_vector = symbolic_scene(scene_structure)

    p, q, v, omega, f = (x[s] for s in (StateIndex.p_world, StateIndex.q_body_to_world, StateIndex.v_world,
                                        StateIndex.omega_body, StateIndex.rotor_thrusts))
    q_unit = q / ca.norm_2(q)
    R = quat_to_rotation(q_unit)
    J = ca.DM(vehicle.inertia)
    gyro = ca.cross(omega, J * omega)

    f_des = _commanded_rotor_thrusts(vehicle, omega, u)
    if lagged:  # a vehicle whose time constant is 0 still follows its command at once
        has_lag = tau_m > 0
        f_act = ca.if_else(has_lag, f, f_des)
        f_dot = ca.if_else(has_lag, thrust_rate(f_des, f, ca.fmax(tau_m, 1e-9)), ca.SX.zeros(4))
    else:
        f_act = f_des
        f_dot = ca.SX.zeros(4)

    ctx = FlightContext(p, R, v, omega, f_act, vehicle.rotor_positions_array, mass, GRAVITY, scene_symbols)
    aero, effect_forces = model.wrench(ctx, theta, scene_structure)
    suction = model.get("wall_suction")
    if suction is not None and suction.applies_to(scene_structure):
        index = model.names.index("wall_suction")
        rotor_suction = ca.horzcat(*suction.rotor_forces(  # type: ignore[attr-defined]
            ctx, suction.unpack(theta[model.slices()[index]])))
    else:
        rotor_suction = ca.SX.zeros(3, 4)
    allocation = ca.DM(vehicle.allocation_matrix)
    thrust = ca.sum1(f_act)
    moments = allocation[1:4, :] @ f_act

    p_dot = v
    v_dot = (R[:, 2] * thrust + aero.force_world) / mass - ca.DM([0.0, 0.0, GRAVITY])
    q_dot = 0.5 * quat_multiply(q_unit, ca.vertcat(0, omega))
    omega_dot = (moments + aero.moment_body - gyro) / J
    x_dot = ca.vertcat(p_dot, q_dot, v_dot, omega_dot, f_dot)
    forces = ca.horzcat(*effect_forces) if effect_forces else ca.SX.zeros(3, 0)
    return ca.Function("flight_dynamics", [x, u, tau_m, mass, theta, scene_vector],
                       [x_dot, forces, f_act, rotor_suction])


def _rk4_substep(dynamics: ca.Function, h: float, vehicle: VehicleParams, lagged: bool) -> ca.Function:
    x = ca.SX.sym("x", STATE_SIZE)
    u = ca.SX.sym("u", 4)
    args = [ca.SX.sym(dynamics.name_in(i), dynamics.sparsity_in(i)) for i in range(2, dynamics.n_in())]
    tau_m = args[0]
    k1, forces, _, rotor_suction = dynamics(x, u, *args)
    k2 = dynamics(x + h / 2 * k1, u, *args)[0]
    k3 = dynamics(x + h / 2 * k2, u, *args)[0]
    k4 = dynamics(x + h * k3, u, *args)[0]
    x_next = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    q = x_next[StateIndex.q_body_to_world]
    x_next[StateIndex.q_body_to_world] = q / ca.norm_2(q)
    # rotor thrusts without lag are algebraic: report those of the new state (rate loop and mixer only)
    algebraic = _commanded_rotor_thrusts(vehicle, x_next[StateIndex.omega_body], u)
    if lagged:
        x_next[StateIndex.rotor_thrusts] = ca.if_else(tau_m > 0, x_next[StateIndex.rotor_thrusts], algebraic)
    else:
        x_next[StateIndex.rotor_thrusts] = algebraic
    return ca.Function("rk4_substep", [x, u, *args], [x_next, forces, rotor_suction])


@lru_cache(maxsize=32)
def build_step_function(
    vehicle: VehicleParams, structure_key: tuple, scene_structure: tuple, control_dt: float, substeps: int,
    lagged: bool = False,
) -> ca.Function:
    """CasADi function of one control step.

    ``control_step(x[17], u[4], u_previous[4], timing[3], mass, theta, scene) -> (x_next[17],
    effect_forces_mean[3 x n_effects], rotor_wall_distances[n_walls x 4], R_body_to_world[3x3], x_observed[17],
    rotor_suction_mean[3 x 4])``

    ``timing`` as :class:`Timing`: substeps ``i < command_switch`` fly ``u_previous``, the others
    ``u``; ``x_observed`` is the state after ``observe_after`` substeps (0: the step's start);
    ``motor_time_constant`` is the rotor lag when ``lagged`` (built in: rotor thrusts are state).
    The effect forces and each rotor's wall suction are averaged over the substeps; the rotor-wall distances are
    the signed distances of the rotor centres of ``x_next`` to each wall, and the
    rotation matrix is that of ``x_next``.
    ``vehicle`` enters with its mass and motor time constant ignored (both are inputs, so they
    can be randomised without rebuilding).
    """
    from wall_env.effects import make_effect

    model = AeroModel([make_effect(name, **dict(options)) for name, options in structure_key])
    dynamics = _continuous_dynamics(vehicle, model, scene_structure, lagged)
    substep = _rk4_substep(dynamics, control_dt / substeps, vehicle, lagged)

    x = ca.MX.sym("x", STATE_SIZE)
    u = ca.MX.sym("u", 4)
    u_previous = ca.MX.sym("u_previous", 4)
    timing = ca.MX.sym("timing", Timing.size)
    mass = ca.MX.sym("mass")
    theta = ca.MX.sym("theta", model.param_size)
    scene = ca.MX.sym("scene", dynamics.size1_in(5))
    forces_sum = ca.MX.zeros(3, len(model.effects))
    suction_sum = ca.MX.zeros(3, 4)
    state = x
    observed = ca.if_else(timing[Timing.observe_after] < 0.5, x, ca.MX.zeros(STATE_SIZE))
    for i in range(substeps):
        u_i = ca.if_else(timing[Timing.command_switch] > i + 0.5, u_previous, u)
        state, forces, rotor_suction = substep(state, u_i, timing[Timing.motor_time_constant], mass, theta, scene)
        forces_sum += forces
        suction_sum += rotor_suction
        observed += ca.if_else(ca.fabs(timing[Timing.observe_after] - (i + 1)) < 0.5, state, ca.MX.zeros(STATE_SIZE))

    # rotor-wall distances of the final state
    xs = ca.SX.sym("x", STATE_SIZE)
    scene_symbols, scene_vector = symbolic_scene(scene_structure)
    R = quat_to_rotation(xs[StateIndex.q_body_to_world])
    rotors = vehicle.rotor_positions_array
    rows = []
    for point, normal in zip(scene_symbols.wall_points, scene_symbols.wall_normals):
        rows.append(ca.horzcat(*[ca.dot(normal, xs[0:3] + R @ ca.DM(rotors[j]) - point) for j in range(4)]))
    distances = ca.vertcat(*rows) if rows else ca.SX.zeros(0, 4)
    geometry = ca.Function("geometry", [xs, scene_vector], [distances, R])
    distances_next, R_next = geometry(state, scene)

    return ca.Function(
        "control_step",
        [x, u, u_previous, timing, mass, theta, scene],
        [state, forces_sum / substeps, distances_next, R_next, observed, suction_sum / substeps],
        ["x", "u", "u_previous", "timing", "mass", "theta", "scene"],
        ["x_next", "effect_forces_world", "rotor_wall_distances", "R_body_to_world", "x_observed",
         "rotor_suction_world"],
    )


@lru_cache(maxsize=32)
def build_env_step_function(
    vehicle: VehicleParams, structure_key: tuple, scene_structure: tuple, control_dt: float, substeps: int,
    lagged: bool = False,
) -> ca.Function:
    """The environments' control step: :func:`build_step_function` followed by the closed-form
    contact response (:mod:`wall_env.contact`).

    ``env_step(x[17], u[4], u_previous[4], timing[3], mass, theta, scene, restitution) -> (x_next[17],
    effect_forces_world[3 x n_effects], rotor_wall_distances[n_walls x 4], R_body_to_world[3x3],
    penetrations[n_planes], x_observed[17], rotor_suction_world[3 x 4])``: the state, distances and rotation
    after the response; the
    penetrations before it (one per plane: walls, ground, ceiling); ``x_observed`` as
    :func:`build_step_function` (after the response when it is the step's end state).
    """
    step = build_step_function(vehicle, structure_key, scene_structure, control_dt, substeps, lagged)
    xs = ca.SX.sym("x", STATE_SIZE)
    restitution = ca.SX.sym("restitution")
    scene_symbols, scene_vector = symbolic_scene(scene_structure)
    R = quat_to_rotation(xs[StateIndex.q_body_to_world])
    p, v, penetrations = contact_response(xs[StateIndex.p_world], R, xs[StateIndex.v_world], scene_symbols,
                                          collision_shapes(vehicle), restitution)
    x_after = ca.vertcat(p, xs[StateIndex.q_body_to_world], v, xs[10:STATE_SIZE])
    rows = [ca.horzcat(*[ca.dot(normal, p + R @ ca.DM(r) - point) for r in vehicle.rotor_positions_array])
            for point, normal in zip(scene_symbols.wall_points, scene_symbols.wall_normals)]
    distances = ca.vertcat(*rows) if rows else ca.SX.zeros(0, 4)
    respond = ca.Function("contact", [xs, scene_vector, restitution], [x_after, distances, penetrations])

    x = ca.MX.sym("x", STATE_SIZE)
    u = ca.MX.sym("u", 4)
    u_previous = ca.MX.sym("u_previous", 4)
    timing = ca.MX.sym("timing", Timing.size)
    mass = ca.MX.sym("mass")
    theta = ca.MX.sym("theta", step.size1_in(5))
    scene = ca.MX.sym("scene", step.size1_in(6))
    e = ca.MX.sym("restitution")
    x_next, forces, _, R_next, observed, rotor_suction = step(x, u, u_previous, timing, mass, theta, scene)
    x_after_contact, distances_after, depth = respond(x_next, scene, e)
    observed = ca.if_else(timing[Timing.observe_after] > substeps - 0.5, x_after_contact, observed)
    return ca.Function(
        "env_step",
        [x, u, u_previous, timing, mass, theta, scene, e],
        [x_after_contact, forces, distances_after, R_next, depth, observed, rotor_suction],
        ["x", "u", "u_previous", "timing", "mass", "theta", "scene", "restitution"],
        ["x_next", "effect_forces_world", "rotor_wall_distances", "R_body_to_world", "penetrations", "x_observed",
         "rotor_suction_world"],
    )


@lru_cache(maxsize=32)
def build_clearance_function(vehicle: VehicleParams, scene_structure: tuple) -> ca.Function:
    """``clearance(x[17], scene) -> (clearances[n_planes], normals[3 x n_planes])``: how far the vehicle in
    state ``x`` is from each plane of the scene (:func:`wall_env.contact.plane_clearances`, negative inside)
    and each plane's outward unit normal. Called with ``k`` states and scenes as columns, it maps over them."""
    xs = ca.SX.sym("x", STATE_SIZE)
    scene_symbols, scene_vector = symbolic_scene(scene_structure)
    R = quat_to_rotation(xs[StateIndex.q_body_to_world])
    clearances = plane_clearances(xs[StateIndex.p_world], R, scene_symbols, collision_shapes(vehicle))
    normals = [normal for _, normal in scene_planes(scene_symbols)[0]]
    return ca.Function("clearance", [xs, scene_vector],
                       [ca.vertcat(*clearances) if clearances else ca.SX.zeros(0, 1),
                        ca.horzcat(*normals) if normals else ca.SX.zeros(3, 0)],
                       ["x", "scene"], ["clearances", "normals"])


def _step_key(vehicle: VehicleParams) -> VehicleParams:
    """The vehicle as the compiled step's cache key: mass and motor time constant are inputs."""
    return dataclasses.replace(vehicle, mass=1.0, motor_time_constant=0.0)


class BatchSimulator:
    """The environments' compiled step (:func:`build_env_step_function`) for ``n`` vehicles in one call.

    The per-vehicle inputs are rows of arrays that this object owns and the caller fills
    in place: ``x (n, 17)``, ``u (n, 4)``, ``u_previous (n, 4)``, ``timing (n, 3)`` (:class:`Timing`),
    ``mass (n, 1)``, ``theta (n, P)``, ``scene (n, S)``, ``restitution (n, 1)``. :meth:`step` writes the
    outputs, also owned arrays: ``x_next (n, 17)``, ``forces (n, 3 * n_effects)`` (column-major
    ``3 x n_effects`` per row), ``distances (n, n_walls * 4)`` (column-major ``n_walls x 4``), ``R (n, 9)``
    (column-major), ``penetrations (n, n_planes)``, ``x_observed (n, 17)`` and ``rotor_suction (n, 12)``
    (column-major ``3 x 4``: each rotor's wall suction, mean over the step). ``lagged``: rotor
    thrusts are state and follow each row's ``timing[:, Timing.motor_time_constant]`` (default: lagged
    when the vehicle has a motor time constant).
    """

    def __init__(self, vehicle: VehicleParams, model: AeroModel, scene_structure: tuple, control_dt: float,
                 substeps: int, n: int, lagged: bool | None = None):
        lagged = vehicle.motor_time_constant > 0 if lagged is None else bool(lagged)
        function = build_env_step_function(_step_key(vehicle), model.structure_key, scene_structure, control_dt,
                                           substeps, lagged)
        # compiled for the host CPU, as the controllers' solves are: about a tenth faster per vehicle
        self._step = BatchedFunction(function, NATIVE_FLAGS)
        self.n = n
        self.substeps = substeps
        self.lagged = lagged
        (self.x, self.u, self.u_previous, self.timing, self.mass, self.theta, self.scene,
         self.restitution) = (np.zeros((n, size)) for size in self._step.nnz_in)
        self.timing[:, Timing.observe_after] = substeps
        self.timing[:, Timing.motor_time_constant] = vehicle.motor_time_constant
        (self.x_next, self.forces, self.distances, self.R, self.penetrations, self.x_observed,
         self.rotor_suction) = self._step.outputs(n)
        self._clearance = build_clearance_function(_step_key(vehicle), scene_structure)
        self._step.bind([self.x, self.u, self.u_previous, self.timing, self.mass, self.theta, self.scene,
                         self.restitution],
                        [self.x_next, self.forces, self.distances, self.R, self.penetrations, self.x_observed,
                         self.rotor_suction])

    def step(self) -> None:
        """Advance every vehicle one control step (inputs and outputs: the arrays above)."""
        self._step()

    def clearances(self, x: np.ndarray, scene: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How far vehicles in states ``x`` ``(k, 17)`` are from each plane of scenes ``scene`` ``(k, S)``
        (``(k, n_planes)`` m, negative inside) and the planes' outward normals ``(k, 3, n_planes)``."""
        k = x.shape[0]
        n_planes = self._clearance.size1_out(0)
        if k == 0 or n_planes == 0:
            return np.zeros((k, n_planes)), np.zeros((k, 3, n_planes))
        clearances, normals = self._clearance(x.T, scene.T)
        clearances = np.asarray(clearances).reshape(n_planes, k).T
        normals = np.asarray(normals).reshape(3, k, n_planes).transpose(1, 0, 2)
        return clearances, normals


class Simulator:
    """Numeric front end of the compiled control step for one vehicle, model and scene structure
    (commands act at once, the vehicle's own motor lag)."""

    def __init__(self, vehicle: VehicleParams, model: AeroModel, scene: Scene, control_dt: float, substeps: int):
        self.vehicle = vehicle
        self.model = model
        self.scene = scene
        self.control_dt = control_dt
        self.substeps = substeps
        function = build_step_function(_step_key(vehicle), model.structure_key, scene.structure, control_dt, substeps,
                                       vehicle.motor_time_constant > 0)
        self._step = CompiledFunction(function)
        self._timing = np.array([0.0, substeps, vehicle.motor_time_constant])
        self.mass = vehicle.mass
        self.theta = model.theta()
        self.scene_vector = scene.to_vector()
        self.n_walls = len(scene.walls)

    def set_parameters(self, *, mass: float | None = None, theta: np.ndarray | None = None,
                       scene: Scene | None = None) -> None:
        """Change numeric values between episodes (the compiled code stays the same)."""
        if mass is not None:
            self.mass = float(mass)
        if theta is not None:
            self.theta = np.asarray(theta, dtype=float)
        if scene is not None:
            if scene.structure != self.scene.structure:
                raise ValueError("a scene with another number of walls, ground or ceiling needs a new Simulator")
            self.scene = scene
            self.scene_vector = scene.to_vector()

    def step(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Advance one control step.

        Returns ``x_next``, the effect forces ``(3, n_effects)`` (mean over the step), the
        rotor-wall distances ``(n_walls, 4)`` and ``R_body_to_world`` ``(3, 3)`` of ``x_next``.
        """
        x_next, forces, distances, R, _, _ = self._step(x, u, u, self._timing, self.mass, self.theta,
                                                         self.scene_vector)
        return (x_next, forces.reshape(3, -1, order="F"), distances.reshape(self.n_walls, 4, order="F"),
                R.reshape(3, 3, order="F"))

    def hover_state(self, p_world: np.ndarray,
                    q_body_to_world: np.ndarray | tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)) -> np.ndarray:
        """A state at rest with every rotor carrying a quarter of the weight."""
        x = np.zeros(STATE_SIZE)
        x[StateIndex.p_world] = p_world
        x[StateIndex.q_body_to_world] = q_body_to_world
        x[StateIndex.rotor_thrusts] = self.mass * GRAVITY / 4.0
        return x
