"""Flight conditions against their equations: latency shifts by exactly its steps, the motor lag's step
response, the turbulence spectrum and variance, the sensing error's statistics, and the wind through the drag."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scipy.signal import welch
from scipy.spatial.transform import Rotation

import wall_env  # noqa: F401
from wall_env.conditions import PROFILES, DrydenTurbulence, FlightConditions, Latency, TurbulenceState, Wind
from wall_env.conditions.sensing import MOTION_CAPTURE, VISUAL_INERTIAL
from wall_env.motor_lag import held_command_response


def _vector(n, seed, **kwargs):
    envs = gym.make_vec("WallInspector/WallHover-v0", num_envs=n, vectorization_mode="vector_entry_point",
                        noise=False, **kwargs)
    envs.reset(seed=seed, options={"perturb_start": False})
    return envs


def _commands(steps, seed=0):
    """Small varied actions that keep the vehicle near its hover point."""
    rng = np.random.default_rng(seed)
    return np.clip(0.15 * rng.standard_normal((steps, 4)), -1, 1)


@pytest.mark.parametrize("delay_ms", [3, 10, 17])
def test_a_command_delay_shifts_the_flight_by_exactly_its_physics_steps(delay_ms):
    """100 Hz control with 10 substeps and a command delay of D ms flies exactly as 1 kHz control (one substep a
    step) whose held commands are shifted by D steps: the same RK4 steps with the same inputs."""
    actions = _commands(30)
    slow = _vector(1, 5, conditions={"latency": {"command": delay_ms / 1000}})
    fast = _vector(1, 5, control_dt=0.001, physics_substeps=1, duration=1.0)
    hover = np.zeros(4)
    fine = [hover] * delay_ms + [a for a in actions for _ in range(10)]
    states_slow = []
    for a in actions:
        slow.step(a[None])
        states_slow.append(slow.unwrapped.batch.simulator.x[0].copy())
    states_fast = []
    for a in fine[: 10 * len(actions)]:
        fast.step(a[None])
        states_fast.append(fast.unwrapped.batch.simulator.x[0].copy())
    np.testing.assert_allclose(np.array(states_slow), np.array(states_fast)[9::10], rtol=0, atol=1e-12)


@pytest.mark.parametrize("delay_ms", [4, 10, 23])
def test_an_observation_delay_shows_the_state_of_exactly_that_many_physics_steps_ago(delay_ms):
    actions = _commands(30, seed=1)
    late = _vector(1, 6, conditions={"latency": {"observation": delay_ms / 1000}})
    fast = _vector(1, 6, control_dt=0.001, physics_substeps=1, duration=1.0)
    fine_positions = [fast.unwrapped.batch.simulator.x[0, 0:3].copy()]
    for a in actions:
        for _ in range(10):
            fast.step(a[None])
            fine_positions.append(fast.unwrapped.batch.simulator.x[0, 0:3].copy())
    for t, a in enumerate(actions, start=1):
        obs, *_ = late.step(a[None])
        expected = fine_positions[max(0, 10 * t - delay_ms)]
        np.testing.assert_allclose(obs[0, 0:3], expected, atol=1e-6)  # float32 observation
        assert obs[0, 47] == pytest.approx(0.01 * t)  # the controller's clock is not delayed


def test_latency_must_be_whole_physics_steps_and_a_lag_at_least_one():
    with pytest.raises(ValueError, match="latency.command must be a whole number of physics steps of 1 ms"):
        gym.make("WallInspector/WallHover-v0", conditions={"latency": {"command": 0.0025}})
    with pytest.raises(ValueError, match=r"motor_time_constant must be 0 or at least one physics step"):
        gym.make("WallInspector/WallHover-v0", conditions={"motor_time_constant": 0.0004})
    with pytest.raises(ValueError, match=r"latency.observation \(s\) must be in \[0, 0.2\]"):
        Latency(observation=0.5)
    assert Latency.total(0.02) == Latency(0.01, 0.01)


def test_randomised_motor_lags_give_each_row_its_own_first_order_step_response():
    taus = np.array([0.0, 0.012, 0.03, 0.05])
    envs = _vector(4, 0, randomize={"motor_time_constant": (0.0, 0.05)})
    batch = envs.unwrapped.batch
    batch.simulator.timing[:, 2] = taus  # the rows' lags, set after the draw
    hover = batch.simulator.x[:, 13:17].sum(axis=1).copy()
    step = np.array([[0.3, 0.0, 0.0, 0.0]] * 4)
    thrusts = [hover]
    for _ in range(12):
        envs.step(step)
        thrusts.append(batch.simulator.x[:, 13:17].sum(axis=1).copy())
    commanded = envs.unwrapped.action_mapping.to_physical(step)[0, 0]
    produced = np.array(thrusts)
    for row, tau in enumerate(taus):
        if tau == 0:  # the rate loop's mixer gives the command back at once
            assert produced[1:, row] == pytest.approx(commanded, abs=1e-9)
            continue
        exact = held_command_response(np.full(13, commanded), 0.01, tau, start=hover[row]).at_samples
        np.testing.assert_allclose(produced[:, row], exact[:13], atol=1e-5)


def test_dryden_turbulence_has_the_model_variance_and_spectrum():
    turbulence = DrydenTurbulence.low_altitude(1.5, 5.0)
    Ad, L_noise, C, L_start = turbulence.discrete(0.01)
    P = L_start @ L_start.T
    variance = np.diag(C @ P @ C.T) * np.asarray(turbulence.intensity) ** 2
    np.testing.assert_allclose(variance, np.asarray(turbulence.intensity) ** 2, rtol=1e-9)  # sigma^2, exactly

    n, steps = 64, 8192
    state = TurbulenceState(turbulence, n, 0.01)
    rng = np.random.default_rng(11)
    state.reset(slice(None), rng.standard_normal((n, 6)))
    series = np.empty((steps, n, 3))
    for k in range(steps):
        state.step(rng.standard_normal((n, 6)))
        series[k] = state.gust_world()
    assert np.var(series, axis=(0, 1)) == pytest.approx(np.asarray(turbulence.intensity) ** 2, rel=0.1)
    frequency, density = welch(series, fs=100.0, nperseg=2048, axis=0)  # one-sided, (m/s)^2 per Hz
    density = density.mean(axis=1)  # (freq, 3), averaged over the rows
    band = (frequency > 0.1) & (frequency < 5.0)
    model = turbulence.psd(2 * np.pi * frequency[band]) * 2 * np.pi  # per rad/s -> per Hz
    ratio = density[band].T / model
    assert np.median(ratio, axis=1) == pytest.approx(np.ones(3), abs=0.08)
    assert np.all(np.abs(np.log(ratio)) < 0.35)  # every bin of 64 x 7 Welch segments within 40 %


def test_the_wind_acts_through_the_air_relative_drag():
    envs = _vector(2, 3, conditions={"wind": {"mean": [1.5, -0.5, 0.0]}})
    obs, _, _, _, info = envs.step(np.zeros((2, 4)))
    drag = info["effect_forces_world"]["linear_drag"]
    v = info["v_world"]
    D = np.array(envs.unwrapped.vehicle.drag)
    for row in range(2):
        q = info["q_body_to_world"][row]
        R = Rotation.from_quat(q[[1, 2, 3, 0]]).as_matrix()
        expected = -R @ (D * (R.T @ (v[row] - [1.5, -0.5, 0.0])))
        np.testing.assert_allclose(drag[row], expected, rtol=0.02, atol=2e-3)  # mean over the step's substeps


@pytest.mark.parametrize("mean", [(0.0, 0.0, 0.0), (0.5, 0.5, 0.0)])
def test_an_effects_own_steady_wind_is_kept_and_the_conditions_wind_adds_to_it(mean):
    from wall_env.effects import effects_from_spec

    C, w = np.array([0.08, 0.1, 0.12]), np.array([1.5, -1.0, 0.0])
    effects = effects_from_spec("quadratic_drag:C=0.08/0.1/0.12,w=1.5/-1/0")
    envs = _vector(2, 4, effects=effects, conditions={"wind": {"mean": list(mean)}})
    _, _, _, _, info = envs.step(np.zeros((2, 4)))
    drag, v = info["effect_forces_world"]["quadratic_drag"], info["v_world"]
    for row in range(2):
        q = info["q_body_to_world"][row]
        R = Rotation.from_quat(q[[1, 2, 3, 0]]).as_matrix()
        v_body = R.T @ (v[row] - w - np.asarray(mean))
        np.testing.assert_allclose(drag[row], -R @ (C * np.abs(v_body) * v_body), rtol=0.02, atol=2e-3)
    assert np.linalg.norm(drag[0]) > 0.1  # 0.08 x 1.5^2 N along x alone


def test_the_sensing_error_has_its_presets_statistics():
    rows = 400
    envs = gym.make_vec("WallInspector/WallHover-v0", num_envs=rows, vectorization_mode="vector_entry_point",
                        noise=False, k_s=0.0, conditions={"sensing": "visual_inertial"})  # hovers in place
    obs, info = envs.reset(seed=100, options={"perturb_start": False})
    model = VISUAL_INERTIAL
    errors = []
    for _ in range(200):
        obs, _, _, _, info = envs.step(np.zeros((rows, 4)))
        errors.append(obs[:, 0:3] - info["p_world"])
    errors = np.array(errors)  # (steps, rows, 3)
    # after t seconds: drift variance drift^2 t plus the noise's; no bias on VIO position
    for t_index in (49, 199):
        t = 0.01 * (t_index + 1)
        expected = np.sqrt(model.position.drift**2 * t + model.position.noise**2)
        assert errors[t_index].std() == pytest.approx(expected, rel=0.1)
    velocity = obs[:, 3:6] - info["v_world"]
    expected_v = np.hypot(model.velocity.noise, model.velocity.bias)
    assert velocity.std() == pytest.approx(expected_v, rel=0.1)
    # motion capture: the bias dominates position, the same on every step of an episode
    mocap = gym.make_vec("WallInspector/WallHover-v0", num_envs=rows, vectorization_mode="vector_entry_point",
                         noise=False, k_s=0.0, conditions={"sensing": MOTION_CAPTURE})
    obs, info = mocap.reset(seed=100, options={"perturb_start": False})
    first = obs[:, 0:3] - info["p_world"]
    assert first.std() == pytest.approx(MOTION_CAPTURE.position.bias, rel=0.1)


def test_profiles_and_bad_conditions_are_named():
    realistic = FlightConditions.from_spec("realistic")
    assert realistic is PROFILES["realistic"] and not realistic.is_ideal and PROFILES["ideal"].is_ideal
    assert realistic.latency.seconds == pytest.approx(0.02) and realistic.motor_time_constant == 0.03
    custom = FlightConditions.from_spec({"profile": "realistic", "wind": None})
    assert custom.wind == Wind() and custom.sensing is realistic.sensing
    for spec, message in [("windy", "conditions must be one of"), ({"sensor": "x"}, "unknown \\['sensor'\\]"),
                          ({"sensing": "gps"}, "sensing must be one of"),
                          ({"wind": {"turbulence": "gale"}}, "wind.turbulence must be one of"),
                          ({"sensing": {"position": {"noise": -1}}}, r"sensing.position.noise \(m\) must be in")]:
        with pytest.raises(ValueError, match=message):
            gym.make("WallInspector/WallHover-v0", conditions=spec)
    with pytest.raises(ValueError, match="the motor lag is given twice"):
        gym.make("WallInspector/WallHover-v0", conditions="realistic", motor_time_constant=0.02)


@pytest.mark.parametrize("env_id", ["WallInspector/WallSweep-v0", "WallInspector/Facade-v0"])
def test_ideal_conditions_change_nothing_and_a_row_flies_as_the_single_env_under_every_condition(env_id):
    kwargs = {"conditions": {"sensing": "visual_inertial", "wind": "moderate"},
                  "randomize": {"push": (0, 1), "latency": (0, 0.03), "motor_time_constant": (0.0, 0.05),
                             "sensing_scale": (0, 2), "gust_scale": (0, 2), "k_s": (1, 12)}}
    envs = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **kwargs)
    single = gym.make(env_id, **kwargs)
    rows, _ = envs.reset(seed=[7, 8, 9])
    one, _ = single.reset(seed=8)
    np.testing.assert_array_equal(rows[1], one)
    for a in _commands(150, seed=4) * 0.1:
        rows, *_ = envs.step(np.tile(a, (3, 1)))
        one, _, terminated, truncated, _ = single.step(a)
        np.testing.assert_array_equal(rows[1], one)
        if terminated or truncated:
            break
    ideal = gym.make("WallInspector/WallSweep-v0", conditions="ideal")
    plain = gym.make("WallInspector/WallSweep-v0")
    a_obs, _ = ideal.reset(seed=1)
    b_obs, _ = plain.reset(seed=1)
    for a in _commands(50, seed=2) * 0.1:
        np.testing.assert_array_equal(a_obs, b_obs)
        a_obs, *_ = ideal.step(a)
        b_obs, *_ = plain.step(a)


def test_a_randomised_push_is_horizontal_with_the_drawn_magnitude():
    envs = _vector(300, 0, randomize={"push": (0.1, 1.0)})
    _, _, _, _, info = envs.step(np.zeros((300, 4)))
    force = info["effect_forces_world"]["constant_force"]
    magnitude = np.linalg.norm(force, axis=1)
    np.testing.assert_allclose(magnitude, envs.unwrapped.episode_parameters["push"], rtol=1e-12)
    assert np.all(force[:, 2] == 0) and magnitude.min() >= 0.1 and magnitude.max() <= 1.0
    heading = np.arctan2(force[:, 1], force[:, 0])
    assert np.histogram(heading, bins=4, range=(-np.pi, np.pi))[0].min() > 50  # every quarter of the circle


def test_a_drawn_motor_lag_shorter_than_a_physics_step_is_no_lag():
    """RK4 at 1 ms cannot follow a 0.3 ms lag (it diverged to NaN states); such draws fly without lag."""
    envs = _vector(400, 0, randomize={"motor_time_constant": (0.0, 0.01)})
    drawn = envs.unwrapped.episode_parameters["motor_time_constant"]
    assert np.all((drawn == 0) | (drawn >= 0.001)) and (drawn == 0).sum() > 20
    for _ in range(20):
        obs, *_ = envs.step(np.zeros((400, 4)))
    assert np.all(np.isfinite(obs))
