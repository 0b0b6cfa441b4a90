"""The compiled flight dynamics against the rigid-body equations (paper Eq. 3 and 5)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wall_env.aero import AeroModel
from wall_env.codegen import CompiledFunction
from wall_env.dynamics import Simulator, StateIndex
from wall_env.effects import make_effect
from wall_env.model_file import nominal_aero_model
from wall_env.scene import Scene, Wall
from wall_env.vehicle import GRAVITY, VehicleParams

A = 0.1 / np.sqrt(2)
WALL = Scene((Wall((0, 0, 0), (1, 0, 0)),), ground_z=0.0)
Q_FACE_WALL = np.roll(Rotation.from_euler("z", np.pi).as_quat(), 1)


def make_sim(vehicle=None, effects=(), substeps=10):
    vehicle = vehicle or VehicleParams()
    model = nominal_aero_model(vehicle)
    for e in effects:
        model = model.with_effect(e)
    return Simulator(vehicle, model, WALL, 0.01, substeps)


def run(sim, x, u, steps):
    for _ in range(steps):
        x = sim.step(x, np.asarray(u, float))[0]
    return x


def test_hover_thrust_holds_position_in_free_space():
    sim = make_sim()
    x = run(sim, sim.hover_state([2.0, 0.0, 1.0]), [GRAVITY, 0, 0, 0], 100)
    assert x[StateIndex.p_world] == pytest.approx([2.0, 0.0, 1.0], abs=1e-9)
    assert x[StateIndex.v_world] == pytest.approx([0, 0, 0], abs=1e-9)


def test_free_fall_without_drag_matches_g_t():
    sim = make_sim(VehicleParams(drag=(0.0, 0.0, 0.0)))
    x = run(sim, sim.hover_state([2.0, 0.0, 5.0]), [0.0, 0, 0, 0], 50)
    assert x[StateIndex.v_world][2] == pytest.approx(-GRAVITY * 0.5, rel=1e-9)
    assert x[StateIndex.p_world][2] == pytest.approx(5.0 - 0.5 * GRAVITY * 0.5**2, rel=1e-9)


def test_full_thrust_climbs_at_t_over_m_minus_g():
    vehicle = VehicleParams(drag=(0.0, 0.0, 0.0))
    sim = make_sim(vehicle)
    x = run(sim, sim.hover_state([2.0, 0.0, 1.0]), [20.0, 0, 0, 0], 10)
    assert x[StateIndex.v_world][2] == pytest.approx((20.0 / vehicle.mass - GRAVITY) * 0.1, rel=1e-6)


def test_suction_accelerates_toward_the_wall_at_f_over_m():
    sim = make_sim(effects=[make_effect("wall_suction")])
    x0 = sim.hover_state([A + 0.032, 0.0, 1.0], Q_FACE_WALL)
    x1, forces, distances, _ = sim.step(x0, np.array([GRAVITY, 0, 0, 0]))
    accel = x1[StateIndex.v_world][0] / 0.01
    assert accel == pytest.approx(-0.82 / 1.0, rel=0.02)  # F_s / m, suction grows slightly as it closes in
    assert forces[:, 1] == pytest.approx([-0.82, 0, 0], rel=0.02)
    assert distances[0] == pytest.approx([0.032, A + 0.032 + A, A + 0.032 + A, 0.032], abs=1e-3)


def test_body_rate_loop_tracks_a_command_with_its_time_constant():
    vehicle = VehicleParams()
    sim = make_sim(vehicle)
    x = run(sim, sim.hover_state([2.0, 0.0, 3.0]), [GRAVITY, 0.5, 0, 0], 2)  # 20 ms = one time constant
    assert x[StateIndex.omega_body][0] == pytest.approx(0.5 * (1 - np.exp(-vehicle.rate_gains[0] * 0.02)), rel=0.02)
    x = run(sim, x, [GRAVITY, 0.5, 0, 0], 20)
    assert x[StateIndex.omega_body] == pytest.approx([0.5, 0, 0], abs=1e-3)


def test_motor_lag_is_first_order():
    vehicle = VehicleParams(motor_time_constant=0.05)
    sim = make_sim(vehicle)
    x0 = sim.hover_state([2.0, 0.0, 3.0])
    x = run(sim, x0, [GRAVITY + 4.0, 0, 0, 0], 5)  # one time constant
    thrust = x[StateIndex.rotor_thrusts].sum()
    assert thrust == pytest.approx(GRAVITY + 4.0 * (1 - np.exp(-1)), rel=1e-3)


def test_rotor_thrusts_are_clipped_to_their_limits():
    vehicle = VehicleParams()
    sim = make_sim(vehicle)
    x = run(sim, sim.hover_state([2.0, 0.0, 3.0]), [100.0, 0, 0, 0], 1)
    assert x[StateIndex.rotor_thrusts] == pytest.approx([vehicle.thrust_max / 4] * 4)
    x = run(sim, sim.hover_state([2.0, 0.0, 3.0]), [-5.0, 0, 0, 0], 1)
    assert x[StateIndex.rotor_thrusts] == pytest.approx([0.0] * 4)


def test_quaternion_stays_unit_and_matches_the_returned_rotation():
    sim = make_sim()
    x = sim.hover_state([2.0, 0.0, 3.0])
    for _ in range(100):
        x, _, _, R = sim.step(x, np.array([GRAVITY, 1.0, -0.7, 2.0]))
    q = x[StateIndex.q_body_to_world]
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
    assert R == pytest.approx(Rotation.from_quat(q, scalar_first=True).as_matrix(), abs=1e-12)


def test_mass_and_parameters_change_without_rebuilding():
    sim = make_sim(VehicleParams(drag=(0.0, 0.0, 0.0)), effects=[make_effect("constant_force", F=(0.0, 0.0, 0.0))])
    sim.set_parameters(mass=2.0, theta=np.array([0.0, 0.0, 0.0, 0.5, 0.0, 0.0]))
    x0 = sim.hover_state([2.0, 0.0, 3.0])
    x1 = sim.step(x0, np.array([2.0 * GRAVITY, 0, 0, 0]))[0]
    assert x1[StateIndex.v_world][0] / 0.01 == pytest.approx(0.5 / 2.0, rel=1e-9)  # F / m with the new mass


def test_native_code_matches_casadis_evaluator():
    x = ca.SX.sym("x", 3)
    y = ca.SX.sym("y", 2, 2)
    f = ca.Function("probe", [x, y], [ca.sin(x) * ca.sum1(ca.vec(y)), y @ x[:2]])
    compiled = CompiledFunction(f)
    assert compiled.native
    xv, yv = np.array([0.1, 0.2, 0.3]), np.array([[1.0, 2.0], [3.0, 4.0]])
    a, b = compiled(xv, yv)
    ea, eb = (np.asarray(v).ravel() for v in f(xv, yv))
    assert a == pytest.approx(ea, rel=1e-15) and b == pytest.approx(eb, rel=1e-15)
    with pytest.raises(TypeError, match="takes 2 inputs"):
        compiled(xv)


def test_aero_model_rejects_a_repeated_effect():
    with pytest.raises(ValueError, match="repeated"):
        AeroModel([make_effect("wall_suction"), make_effect("wall_suction")])
