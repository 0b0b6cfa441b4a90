"""``wall-inspector fly`` and ``wall-inspector discover`` end to end, through the project's command line."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import wall_env  # noqa: F401
from discovery.flight_log import REQUIRED_COLUMNS, read_log
from discovery.fly import scenario_path
from wall_env.vehicle import VehicleParams
from wall_inspector.cli import main

EFFECT_RECORD_KEYS = {"name", "params", "param_std", "where", "explained_fraction"}


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def suction_log(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "wall.csv"
    code = main(["fly", "--scenario", "wall-sweep", "--effects", "wall_suction:k_s=4.1,d_thr=0.132", "--seed", "11",
                 "--duration", "20", "--out", str(out)])
    assert code == 0
    return out


def test_fly_writes_the_format_with_only_the_nominal_vehicle(tmp_path, capsys):
    out = tmp_path / "drag.csv"
    code = main(["fly", "--scenario", "survey", "--effects", "linear_drag:D=0.2/0.2/0.2;constant_force:F=0.1/0/0",
                 "--seed", "3", "--duration", "4", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "400 samples" in printed and "kept out of the log" in printed
    header = out.read_text().splitlines()[0].split(",")
    assert header == list(REQUIRED_COLUMNS)
    sidecar = json.loads(out.with_suffix(".json").read_text())
    nominal = VehicleParams()
    # the extra drag and the constant force were flown, but the vehicle block is the nominal vehicle only
    assert sidecar["vehicle"] == {"mass": nominal.mass, "rotor_positions": [list(r) for r in nominal.rotor_positions],
                                  "drag": list(nominal.drag)}
    assert set(sidecar) == {"vehicle", "scene", "gravity"}
    truth = json.loads(scenario_path(out).read_text())
    assert [e["name"] for e in truth["effects"]] == ["linear_drag", "constant_force"]
    assert truth["effects"][0]["params"]["D"] == [0.2, 0.2, 0.2]
    log = read_log(out)
    assert log.n_samples == 400 and log.rate_hz == pytest.approx(100.0)


def test_fly_adds_measurement_noise_and_can_leave_it_out(tmp_path):
    clean, noisy = tmp_path / "clean.csv", tmp_path / "noisy.csv"
    for path, scale in ((clean, "0"), (noisy, "1")):
        assert main(["fly", "--scenario", "survey", "--seed", "5", "--duration", "3", "--noise-scale", scale,
                     "--out", str(path)]) == 0
    a, b = read_log(clean), read_log(noisy)
    position_noise = np.std(b.p_world - a.p_world, axis=0)
    velocity_noise = np.std(b.v_world - a.v_world, axis=0)
    np.testing.assert_allclose(position_noise, 0.002, rtol=0.15)
    np.testing.assert_allclose(velocity_noise, 0.02, rtol=0.15)
    np.testing.assert_array_equal(a.thrust_cmd, b.thrust_cmd)  # the commands are the policy's, noise-free


@pytest.mark.parametrize("rate", ["50", "1000"])
def test_fly_at_other_rates_with_optional_columns(tmp_path, rate):
    out = tmp_path / f"r{rate}.csv"
    assert main(["fly", "--scenario", "ground-survey", "--seed", "1", "--duration", "2", "--rate", rate,
                 "--with-acceleration", "--with-rotor-thrusts", "--out", str(out)]) == 0
    log = read_log(out)
    assert log.rate_hz == pytest.approx(float(rate), rel=1e-6)
    assert log.a_world is not None and log.rotor_thrusts is not None
    assert log.n_samples == int(2 * float(rate))
    assert np.allclose(log.rotor_thrusts.sum(axis=1), log.thrust_cmd, atol=1.5)


def test_fly_with_the_mpc_and_with_a_saved_sb3_agent(tmp_path):
    from stable_baselines3 import PPO

    assert main(["fly", "--env", "WallInspector/WallHover-v0", "--policy", "mpc", "--seed", "0", "--duration", "1",
                 "--env-kwargs", '{"standoff": 1.0}', "--out", str(tmp_path / "mpc.csv")]) == 0
    assert read_log(tmp_path / "mpc.csv").n_samples == 100
    env = gym.make("WallInspector/WallHover-v0")
    agent = PPO("MlpPolicy", env, policy_kwargs={"net_arch": [8]}, seed=0, device="cpu")
    agent.save(tmp_path / "agent.zip")
    env.close()
    out = tmp_path / "ppo.csv"
    assert main(["fly", "--env", "WallInspector/WallHover-v0", "--policy", str(tmp_path / "agent.zip"), "--seed", "0",
                 "--duration", "0.5", "--env-kwargs", '{"standoff": 1.0}', "--out", str(out)]) == 0
    assert read_log(out).n_samples >= 20


@pytest.mark.parametrize("argv, message", [
    (["--effects", "wind:F=1"], "unknown effect 'wind'"),
    (["--env-kwargs", '{"k_s": 3}'], "give the effects with --effects"),
    (["--rate", "2000"], "--rate must be in"),
    (["--env-kwargs", "[1]"], "--env-kwargs must be a JSON object"),
])
def test_fly_rejects_bad_arguments_with_a_message(tmp_path, capsys, argv, message):
    assert main(["fly", "--out", str(tmp_path / "x.csv"), *argv]) == 2
    assert message in capsys.readouterr().err


def test_discover_end_to_end(suction_log, tmp_path, capsys):
    inputs = [suction_log, suction_log.with_suffix(".json"), scenario_path(suction_log)]
    before = {p: _digest(p) for p in inputs}
    out = tmp_path / "result"
    code = main(["discover", str(suction_log), "--out", str(out), "--json", str(tmp_path / "report.json"), "--quiet"])
    assert code == 0
    assert {p: _digest(p) for p in inputs} == before  # the logs are only read
    printed = capsys.readouterr().out
    assert "found wall_suction" in printed
    report = json.loads((tmp_path / "report.json").read_text())
    assert report == json.loads((out / "report.json").read_text())
    assert {"effects", "gap_before", "gap_after", "model", "unexplained"} <= set(report)
    assert [e["name"] for e in report["effects"]] == ["wall_suction"]
    record = report["effects"][0]
    assert set(record) == EFFECT_RECORD_KEYS
    assert set(record["params"]) == set(record["param_std"]) == {"k_s", "d_thr"}
    assert record["where"]["regressor"] == "nearest rotor distance to wall 0"
    assert record["where"]["range"][1] == pytest.approx(0.132, abs=0.01)
    assert record["where"]["direction_world"][0] < -0.95  # toward the wall (its normal is +x)
    assert 0.5 < record["explained_fraction"] <= 1.0
    for gap in ("gap_before", "gap_after"):
        assert set(report[gap]) == {"force_rms_N", "prediction_rms_m"}
    assert report["gap_after"]["force_rms_N"] < 0.5 * report["gap_before"]["force_rms_N"]
    assert report["unexplained"] is None
    for name in ("residual_vs_regressor.png", "residual_time.png", "prediction.png"):
        assert (out / name).stat().st_size > 10_000

    # the model file loads in the env and in SC-MPC
    from controllers import SCMPC
    from wall_env.model_file import FlightModel

    model = FlightModel.load(report["model"])
    assert [e.name for e in model.effects] == ["wall_suction"]
    assert set(model.param_std["wall_suction"]) == {"k_s", "d_thr"}
    env = gym.make("WallInspector/WallSweep-v0", model=report["model"])
    env.reset(seed=0)
    policy = SCMPC.from_env(env, model=report["model"])
    assert [e.name for e in policy.model.effects] == ["linear_drag", "wall_suction"]
    env.close()


def test_discover_with_one_named_effect_fits_only_that(suction_log, tmp_path):
    out = tmp_path / "paper"
    assert main(["discover", str(suction_log), "--out", str(out), "--effect", "wall_suction", "--no-plots",
                 "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert [e["name"] for e in report["effects"]] == ["wall_suction"]
    assert report["details"]["settings"]["effect"] == "wall_suction"
    assert not list(out.glob("*.png"))


def test_discover_without_the_motor_lag_search(suction_log, tmp_path):
    out = tmp_path / "no_lag"
    assert main(["discover", str(suction_log), "--out", str(out), "--no-motor-lag", "--no-plots", "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["details"]["settings"]["motor_lag"] is False
    assert report["motor_lag"] is None  # nothing was looked for
    assert [e["name"] for e in report["effects"]] == ["wall_suction"]
    assert json.loads((out / "model.json").read_text())["vehicle"]["motor_time_constant"] == 0.0


def test_discover_rejects_a_malformed_log_naming_file_column_and_row(suction_log, tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    lines = suction_log.read_text().splitlines()
    cells = lines[500].split(",")
    cells[5] = "nan"  # vy
    lines[500] = ",".join(cells)
    bad.write_text("\n".join(lines) + "\n")
    bad.with_suffix(".json").write_text(suction_log.with_suffix(".json").read_text())
    assert main(["discover", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv: line 501 (sample 500), column 'vy'" in err and "not finite" in err
    assert not (tmp_path / "o").exists()


def test_discover_refuses_to_overwrite_an_input(suction_log, tmp_path, capsys):
    assert main(["discover", str(suction_log), "--out", str(tmp_path / "o"),
                 "--json", str(suction_log.with_suffix(".json"))]) == 2
    assert "would overwrite an input" in capsys.readouterr().err


def test_discover_loads_only_what_it_uses():
    """What ``discover`` imports is part of its start-up time: none of these serves it."""
    code = ("import sys, wall_inspector.discover, discovery.workflow, discovery.report; "
            "print(sorted(m for m in ('scipy.signal', 'scipy.stats', 'scipy.ndimage', 'pybullet', 'torch', "
            "'stable_baselines3', 'ray', 'matplotlib', 'wall_env.env') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
