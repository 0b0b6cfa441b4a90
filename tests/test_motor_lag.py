"""The motor-lag model (``wall_env.motor_lag``): its exact response to a held command, against the
equation and against the simulator that integrates the same right-hand side."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_dynamics import make_sim
from wall_env.dynamics import StateIndex
from wall_env.motor_lag import held_command_response, thrust_rate
from wall_env.vehicle import GRAVITY, VehicleParams


def test_a_held_step_rises_with_the_time_constant():
    tau, dt = 0.03, 0.01
    command = np.array([9.0, 13.0, 13.0, 13.0, 13.0])
    response = held_command_response(command, dt, tau)
    # f(t) = 13 - 4 exp(-t / tau) from the step at t = 0.01 s
    assert response.at_samples == pytest.approx([9.0, 9.0, 13 - 4 * np.exp(-1 / 3), 13 - 4 * np.exp(-2 / 3),
                                                 13 - 4 * np.exp(-1.0)], rel=1e-12)
    # mean over the second step: 13 - 4 tau / dt (1 - exp(-dt / tau))
    assert response.step_mean[1] == pytest.approx(13 - 4 * 3 * (1 - np.exp(-1 / 3)), rel=1e-12)
    assert response.step_mean[0] == 9.0


def test_the_derivative_in_the_time_constant_matches_finite_differences():
    rng = np.random.default_rng(3)
    command = 10.0 + np.cumsum(rng.normal(0.0, 0.3, (300, 4)), axis=0)
    for tau in (0.0, 5e-324, 1e-9, 0.004, 0.03, 0.2):  # a least-squares step may try a denormal
        step = 1e-7
        slope = (held_command_response(command, 0.005, tau + step).step_mean
                 - held_command_response(command, 0.005, tau).step_mean) / step
        derivative = held_command_response(command, 0.005, tau).d_step_mean_d_tau
        assert derivative == pytest.approx(slope, rel=1e-4, abs=1e-4 * np.abs(slope).max())


def test_a_start_away_from_the_command_decays_with_the_time_constant():
    tau, dt = 0.03, 0.01
    command = np.full(4, 13.0)
    response = held_command_response(command, dt, tau, start=9.0)
    # f(t) = 13 - 4 exp(-t / tau) from t = 0; its mean over the first step 13 - 4 tau / dt (1 - exp(-dt / tau))
    assert response.at_samples == pytest.approx(13 - 4 * np.exp(-np.arange(4) / 3), rel=1e-12)
    assert response.step_mean[0] == pytest.approx(13 - 4 * 3 * (1 - np.exp(-1 / 3)), rel=1e-12)
    # the step means are linear in the start, with slope b a^k
    b = tau / dt * (1 - np.exp(-dt / tau))
    assert response.d_step_mean_d_start == pytest.approx(b * np.exp(-np.arange(3) / 3), rel=1e-12)
    with pytest.raises(ValueError, match="start must be a finite thrust"):
        held_command_response(command, dt, tau, start=np.nan)


def test_the_derivatives_with_a_start_match_finite_differences():
    rng = np.random.default_rng(5)
    command = 10.0 + np.cumsum(rng.normal(0.0, 0.3, (200, 4)), axis=0)
    start = command[0] + np.array([2.0, -1.0, 0.5, 3.0])
    for tau in (0.0, 1e-9, 0.004, 0.03):
        step = 1e-7
        base = held_command_response(command, 0.005, tau, start)
        slope = (held_command_response(command, 0.005, tau + step, start).step_mean - base.step_mean) / step
        assert base.d_step_mean_d_tau == pytest.approx(slope, rel=1e-4, abs=1e-4 * np.abs(slope).max())
        moved = held_command_response(command, 0.005, tau, start + 1.0).step_mean - base.step_mean
        assert moved == pytest.approx(np.repeat(base.d_step_mean_d_start[:, None], 4, axis=1), abs=1e-9)


def test_no_lag_gives_back_the_command_and_bad_arguments_are_named():
    command = np.array([1.0, 2.0, 4.0])
    response = held_command_response(command, 0.01, 0.0)
    assert response.at_samples.tolist() == [1.0, 2.0, 4.0] and response.step_mean.tolist() == [1.0, 2.0]
    with pytest.raises(ValueError, match="time_constant must be >= 0 s"):
        held_command_response(command, 0.01, -0.01)
    with pytest.raises(ValueError, match="dt must be a positive number of seconds"):
        held_command_response(command, 0.0, 0.01)
    assert thrust_rate(5.0, 3.0, 0.04) == pytest.approx(50.0)


def test_the_simulator_integrates_the_same_lag():
    """The simulator integrates ``thrust_rate`` with RK4 substeps; its rotor thrusts at the control steps are the
    exact response to the held commands."""
    vehicle = VehicleParams(motor_time_constant=0.025)
    sim = make_sim(vehicle)
    x = sim.hover_state([2.0, 0.0, 3.0])
    commands = GRAVITY + np.array([0.0, 3.0, 3.0, -2.0, -2.0, -2.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    produced = [x[StateIndex.rotor_thrusts].sum()]
    for thrust in commands[:-1]:
        x = sim.step(x, np.array([thrust, 0.0, 0.0, 0.0]))[0]
        produced.append(x[StateIndex.rotor_thrusts].sum())
    exact = held_command_response(commands, 0.01, vehicle.motor_time_constant).at_samples
    assert produced == pytest.approx(exact, abs=1e-5)
