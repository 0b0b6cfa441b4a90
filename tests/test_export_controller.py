"""MPC and SC-MPC exported as C: the built library, called through ctypes, is the Python controller.

The folder is written by ``controllers.export.export_controller`` and built by its own Makefile
(a C compiler, no Python); the tests fly the paper's Table II sweep with both and compare actions
step by step, the flight's metrics, the hover fallback, new episodes and the C timing loop's replay.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import wall_env  # noqa: F401
from controllers import MPC, SCMPC
from controllers.evaluation import evaluate
from controllers.export import NativeController, build, export_controller
from controllers.export.c_code import C_SOURCES, default_parameters, hover_function, parameter_labels
from controllers.export.timing import record_flight, time_native_steps
from controllers.paper_tables import TABLE_II
from controllers.policy import hover_command
from wall_env.observation import OBSERVATION_FIELDS

SCENARIO = TABLE_II[0]  # WallSweep-v0, k_s 4.1 N/m, d_thr 0.132 m, command noise, contacts do not end it
SHORT = {**SCENARIO.make_kwargs(), "duration": 2.0}


def _sweep(**overrides):
    return gym.make(SCENARIO.env_id, **{**SCENARIO.make_kwargs(), **overrides})


@pytest.fixture(scope="module")
def scmpc(tmp_path_factory):
    """SC-MPC for the Table II sweep, exported and built; the Python policy it came from."""
    env = _sweep()
    policy = SCMPC.from_env(env, k_s=SCENARIO.k_s, d_thr=SCENARIO.d_thr)
    folder = tmp_path_factory.mktemp("export") / "scmpc"
    export_controller(policy, folder)
    build(folder)
    yield folder, policy, env
    env.close()


def _lockstep(python, native, env, seed):
    """Fly ``python``'s actions; ask ``native`` the same observation at every step. Returns both action lists."""
    observation, _ = env.reset(seed=seed)
    python_actions, native_actions, start, done = [], [], True, False
    while not done:
        action, _ = python.predict(observation, episode_start=np.array([start]))
        other, _ = native.predict(observation, episode_start=np.array([start]))
        python_actions.append(action)
        native_actions.append(other)
        start = False
        observation, _, terminated, truncated, _ = env.step(action)
        done = terminated or truncated
    return np.asarray(python_actions), np.asarray(native_actions)


def test_the_c_controller_gives_the_python_controllers_actions_over_a_whole_flight(scmpc):
    folder, policy, env = scmpc
    native = NativeController(folder, policy)
    native.follow(env)
    python_actions, native_actions = _lockstep(policy, native, env, seed=101)
    assert len(python_actions) == round(env.unwrapped.task.duration / env.unwrapped.control_dt)  # the whole sweep
    assert native_actions.dtype == np.float32
    assert np.max(np.abs(native_actions - python_actions)) <= 1e-6
    assert np.ptp(python_actions[:, 1]) > 0.1  # the flight commands something (not a constant)
    assert native.failures == policy.failures == 0 and set(native.statuses) == {0}


def test_the_c_controller_flies_the_table_ii_sweep_to_the_python_controllers_metrics(scmpc):
    folder, policy, _ = scmpc
    seeds = [102]

    def native_factory(env):
        native = NativeController(folder, policy)
        native.follow(env)
        return native

    python = evaluate(lambda env: SCMPC.from_env(env, k_s=SCENARIO.k_s, d_thr=SCENARIO.d_thr), SCENARIO.env_id,
                      seeds, SCENARIO.make_kwargs()).metrics()
    native = evaluate(native_factory, SCENARIO.env_id, seeds, SCENARIO.make_kwargs()).metrics()
    assert native["steps"] == python["steps"] == 1700
    assert native["wall_normal_rmse"] == pytest.approx(python["wall_normal_rmse"], abs=1e-6)
    assert native["collisions"] == python["collisions"] == 0  # SC-MPC holds off the wall, as in the paper's flight
    assert native["min_wall_clearance"] == pytest.approx(python["min_wall_clearance"], abs=1e-6)
    assert 0.0 < native["wall_normal_rmse"] < 0.01  # m: it tracks the sweep to millimetres


def test_a_broken_observation_gives_the_python_hover_fallback_and_a_cold_restart(scmpc):
    folder, policy, env = scmpc
    python = SCMPC.from_env(env, k_s=SCENARIO.k_s, d_thr=SCENARIO.d_thr)
    native = NativeController(folder, policy)
    native.follow(env)
    observation, _ = env.reset(seed=103)
    for k in range(30):  # into the flight, both warm
        a, _ = python.predict(observation, episode_start=np.array([k == 0]))
        b, _ = native.predict(observation, episode_start=np.array([k == 0]))
        observation, *_ = env.step(a)
    broken = observation.copy()
    broken[OBSERVATION_FIELDS["p_world"].start] = np.nan  # a position dropout; the attitude is still known
    with pytest.warns(RuntimeWarning, match="non-finite observation"):
        a, _ = python.predict(broken)
    with pytest.warns(RuntimeWarning, match="non-finite observation"):
        b, _ = native.predict(broken)
    R = broken[OBSERVATION_FIELDS["R_body_to_world"]].astype(float).reshape(3, 3)
    expected = hover_command(policy.vehicle.mass, R, policy.vehicle.body_rate_max)
    assert np.abs(expected[1:]).max() > 1e-3  # the fallback levels a tilted vehicle: non-zero rates
    np.testing.assert_allclose(b, policy.action_mapping.to_normalised(expected), atol=1e-6)
    np.testing.assert_allclose(b, a, atol=1e-6)
    assert native.statuses[-1] == 1 and native.failures == 1
    for _ in range(5):  # both start cold after the failure and agree again
        a, _ = python.predict(observation)
        b, _ = native.predict(observation)
        np.testing.assert_allclose(b, a, atol=1e-6)
        observation, *_ = env.step(a)


def test_the_hover_fallback_in_casadi_equals_the_python_one():
    function = hover_function()
    rng = np.random.default_rng(7)
    mass, rate_max = 1.1, 3.0
    angles = rng.uniform(0.0, 2.8, 200)  # rad away from level, short of the half turn
    axes = rng.normal(size=(200, 3))
    rotations = Rotation.from_rotvec(axes / np.linalg.norm(axes, axis=1, keepdims=True) * angles[:, None])
    yawed = Rotation.from_euler("z", rng.uniform(-np.pi, np.pi, (200, 1))) * rotations
    for R in yawed.as_matrix():
        got = np.asarray(function(R.ravel(), mass, rate_max)).ravel()  # the observation's row-major R
        np.testing.assert_allclose(got, hover_command(mass, R, rate_max), atol=1e-10)
    unknown = np.full(9, np.nan)
    np.testing.assert_array_equal(np.asarray(function(unknown, mass, rate_max)).ravel(), hover_command(mass, None, rate_max))


def test_the_exported_parameters_are_the_policys_by_name(scmpc):
    folder, policy, env = scmpc
    native = NativeController(folder, policy)
    np.testing.assert_array_equal(native.default_parameters(), default_parameters(policy))
    described = json.loads((folder / "export.json").read_text())
    values = described["parameters"]["wi_parameters"]
    assert list(values) == parameter_labels(policy)
    assert values["global.wall_suction.k_s"] == 4.1 and values["global.wall_suction.d_thr"] == 0.132
    assert values["global.wall0.normal[0]"] == 1.0  # the sweep's wall faces +x
    assert values["options.yaw"] == env.unwrapped.reference.yaw
    assert values["fallback_mass"] == policy.vehicle.mass
    assert described["settings"]["horizon"] == policy.problem.horizon
    assert described["settings"]["compensation"] == "dynamics+attitude"


def test_the_timing_loop_replays_a_flight_to_the_python_actions_and_starts_cold_when_time_goes_back(scmpc):
    folder, policy, _ = scmpc
    env = _sweep(duration=1.0)
    try:
        flights = [record_flight(policy, env, seed) for seed in (104, 105)]
    finally:
        env.close()
    # two episodes back to back; the second one's start is not flagged: wi_step sees its time go back
    joined = replace(flights[0], **{name: np.concatenate([getattr(f, name) for f in flights])
                                    for name in ("starts", "observations", "samples", "parameters", "actions",
                                                 "predict_seconds", "predict_cpu_seconds")})
    joined.starts[len(flights[0].starts)] = 0.0
    timing = time_native_steps(folder, joined, passes=2)
    assert timing.passes == 2 and len(timing.seconds) == len(timing.cpu_seconds) == 2 * len(joined.starts)
    assert np.all(timing.seconds > 0) and np.all(np.isfinite(timing.cpu_seconds))
    assert np.max(np.abs(timing.actions.astype(np.float32) - joined.actions)) <= 1e-6
    assert set(timing.statuses.tolist()) == {0}
    assert np.flatnonzero(timing.cold).tolist() == [0, len(flights[0].starts)]  # cold exactly at both starts


def test_the_nominal_mpc_exports_too_and_a_library_of_other_sizes_is_refused(scmpc, tmp_path):
    scmpc_folder, _, _ = scmpc
    env = gym.make(SCENARIO.env_id, **SHORT)
    try:
        policy = MPC.from_env(env)
        export_controller(policy, tmp_path / "mpc")
        build(tmp_path / "mpc")
        native = NativeController(tmp_path / "mpc", policy)
        native.follow(env)
        python_actions, native_actions = _lockstep(policy, native, env, seed=106)
        with pytest.raises(ValueError, match="built for another controller"):
            NativeController(scmpc_folder, policy)  # SC-MPC's model has the suction's two parameters more
    finally:
        env.close()
    assert len(python_actions) == 200
    assert np.max(np.abs(native_actions - python_actions)) <= 1e-6


def test_the_hand_written_c_is_warning_free_c99(scmpc):
    folder, _, _ = scmpc
    compiler = shutil.which("cc") or shutil.which("gcc")
    assert compiler is not None
    for name in ("wi_controller.c", "wi_defaults.c", "wi_bench.c"):
        done = subprocess.run([compiler, "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-c", name,
                               "-o", "/dev/null"], cwd=folder, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    assert (C_SOURCES / "wi_controller.h").read_text() == (folder / "wi_controller.h").read_text()


def test_the_export_command_writes_the_c_folder_it_announces(tmp_path, capsys):
    from wall_inspector.cli import main

    folder = tmp_path / "c"
    assert main(["export", "scmpc", "--k-s", "3.0", "--d-thr", "0.12", "--out", str(folder), "--no-build"]) == 0
    out = capsys.readouterr().out
    assert f"wrote {folder}: SC-MPC for {SCENARIO.env_id} as C" in out and f"make -C {folder}" in out
    for name in ("wi_casadi.c", "wi_casadi.h", "wi_controller.c", "wi_controller.h", "wi_config.h", "wi_defaults.c",
                 "wi_bench.c", "Makefile", "export.json"):
        assert (folder / name).is_file(), name
    values = json.loads((folder / "export.json").read_text())["parameters"]["wi_parameters"]
    assert values["global.wall_suction.k_s"] == 3.0 and values["global.wall_suction.d_thr"] == 0.12
    assert not (folder / "libwi_controller.so").exists()  # --no-build


def test_bench_export_times_the_c_step_on_a_whole_flight_and_writes_its_figures(tmp_path, capsys):
    from wall_inspector.cli import main

    figures, table = tmp_path / "bench.json", tmp_path / "bench.md"
    assert main(["bench-export", "--no-onnx", "--passes", "1", "--no-pin", "--out", str(tmp_path / "out"),
                 "--json", str(figures), "--markdown", str(table)]) == 0
    c = json.loads(figures.read_text())["c_controller"]
    assert c["steps"] == 1700 and c["c_step_ms"]["count"] == 1700 and c["python_predict_ms"]["count"] == 1700
    assert c["max_action_difference"] <= 1e-6 and c["c_failures"] == c["python_failures"] == 0
    assert 0 < c["c_step_ms"]["median"] <= c["c_step_ms"]["p99_8"] <= c["c_step_ms"]["max"]
    assert "exported C: `wi_step` in a C timing loop (wall clock)" in table.read_text()
    assert "SC-MPC exported C, wi_step (wall)" in capsys.readouterr().out


@pytest.mark.parametrize(("args", "message"), [
    (["--passes", "0"], "--passes must be a positive integer, got 0"),
    (["--out", "{tmp}/a-file"], "--out {tmp}/a-file: exists and is not a folder"),
    (["--agent", "{tmp}/no-agent"], "--agent {tmp}/no-agent: no such folder, and not a task name"),
    (["--json", "{tmp}"], "--json {tmp}: is a folder"),
    (["--method", "pid"], "argument --method: invalid choice: 'pid'"),
])
def test_bench_export_rejects_bad_input_in_one_line(args, message, tmp_path, capsys):
    from wall_inspector.cli import main

    (tmp_path / "a-file").write_text("mine")
    assert main(["bench-export", *[a.format(tmp=tmp_path) for a in args]]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("wall-inspector bench-export: error: ")
    assert message.format(tmp=tmp_path) in err
