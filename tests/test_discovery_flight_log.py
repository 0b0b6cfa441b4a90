"""The flight-log format: round trip, optional columns, rates, segments, and a clear error for every defect."""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from discovery.flight_log import (
    FlightLog,
    LogFormatError,
    NominalVehicle,
    read_log,
    sidecar_path,
    write_log,
)
from wall_env.scene import Scene, Wall
from wall_env.vehicle import VehicleParams


def synthetic_log(n: int = 200, rate_hz: float = 100.0, with_acceleration: bool = False, with_rotors: bool = False,
                  t0: float = 0.0) -> FlightLog:
    """A smooth made-up flight (no physics needed to test the format)."""
    t = t0 + np.arange(n) / rate_hz
    p = np.column_stack([0.3 + 0.05 * np.sin(t), 0.1 * np.cos(t), 1.0 + 0.2 * np.sin(0.5 * t)])
    v = np.column_stack([0.05 * np.cos(t), -0.1 * np.sin(t), 0.1 * np.cos(0.5 * t)])
    yaw = 0.1 * t
    q = np.column_stack([np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)])
    vehicle = NominalVehicle.from_vehicle_params(VehicleParams())
    scene = Scene((Wall((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),), 0.0, 2.5)
    a = np.column_stack([-0.05 * np.sin(t), -0.1 * np.cos(t), -0.05 * np.sin(0.5 * t)]) if with_acceleration else None
    rotors = np.full((n, 4), 2.45) if with_rotors else None
    return FlightLog(t=t, p_world=p, v_world=v, q_body_to_world=q, omega_body=np.zeros((n, 3)) + [0, 0, 0.1],
                     thrust_cmd=np.full(n, 9.81), omega_cmd_body=np.zeros((n, 3)), vehicle=vehicle, scene=scene,
                     a_world=a, rotor_thrusts=rotors)


@pytest.fixture
def good_log(tmp_path) -> Path:
    path = tmp_path / "flight.csv"
    write_log(synthetic_log(), path)
    return path


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _rewrite_csv(path: Path, edit) -> Path:
    lines = path.read_text().splitlines()
    edit(lines)
    path.write_text("\n".join(lines) + "\n")
    return path


def _set_cell(path: Path, line: int, column: str, value: str) -> None:
    def edit(lines):
        header = lines[0].split(",")
        cells = lines[line - 1].split(",")
        cells[header.index(column)] = value
        lines[line - 1] = ",".join(cells)

    _rewrite_csv(path, edit)


def _edit_json(path: Path, edit) -> None:
    json_path = sidecar_path(path)
    data = json.loads(json_path.read_text())
    edit(data)
    json_path.write_text(json.dumps(data, indent=2))


# ---------------------------------------------------------------------- good logs
def test_round_trip_keeps_every_value_and_the_sidecar(tmp_path):
    log = synthetic_log(with_acceleration=True, with_rotors=True)
    csv_path, json_path = write_log(log, tmp_path / "a.csv")
    assert json_path == tmp_path / "a.json"
    back = read_log(csv_path)
    for name in ("t", "p_world", "v_world", "q_body_to_world", "omega_body", "thrust_cmd", "omega_cmd_body", "a_world",
                 "rotor_thrusts"):
        np.testing.assert_allclose(getattr(back, name), getattr(log, name), rtol=1e-8, atol=1e-9)
    assert back.vehicle == log.vehicle
    assert back.vehicle.motor_time_constant == 0.0  # absent: no lag
    assert back.scene == log.scene
    assert back.gravity == 9.81
    assert json.loads(json_path.read_text()) == {
        "vehicle": {"mass": 1.0, "rotor_positions": [list(r) for r in VehicleParams().rotor_positions],
                    "drag": [0.3, 0.3, 0.2]},
        "scene": {"walls": [{"point": [0.0, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]}], "ground_z": 0.0, "ceiling_z": 2.5},
        "gravity": 9.81,
    }


def test_optional_columns_are_optional_and_other_columns_are_ignored(good_log):
    back = read_log(good_log)
    assert back.a_world is None and back.rotor_thrusts is None

    def add_column(lines):
        lines[0] += ",battery_v"
        for i in range(1, len(lines)):
            lines[i] += ",15.1" if i % 2 else ",n/a"

    _rewrite_csv(good_log, add_column)
    assert read_log(good_log).n_samples == 200


def test_absent_drag_means_zero_drag_and_absent_gravity_means_standard(good_log):
    def edit(data):
        del data["vehicle"]["drag"]
        del data["gravity"]

    _edit_json(good_log, edit)
    log = read_log(good_log)
    assert log.vehicle.drag == (0.0, 0.0, 0.0)
    assert log.gravity == 9.81


@pytest.mark.parametrize("rate", [50.0, 1000.0])
def test_rates_from_50_hz_to_1_khz_are_read(tmp_path, rate):
    path = tmp_path / "r.csv"
    write_log(synthetic_log(n=int(rate * 2), rate_hz=rate), path)
    assert read_log(path).rate_hz == pytest.approx(rate, rel=1e-6)


def test_a_gap_splits_the_log_into_segments(tmp_path):
    first, second = synthetic_log(n=100), synthetic_log(n=120, t0=5.0)
    joined = FlightLog(*(np.concatenate([getattr(first, k), getattr(second, k)]) for k in
                         ("t", "p_world", "v_world", "q_body_to_world", "omega_body", "thrust_cmd", "omega_cmd_body")),
                       vehicle=first.vehicle, scene=first.scene)
    path = tmp_path / "gap.csv"
    write_log(joined, path)
    segments = read_log(path).segments()
    assert [(s.start, s.stop) for s in segments] == [(0, 100), (100, 220)]


def test_two_dropped_samples_do_not_split_the_log_and_three_do(tmp_path):
    """Steps are counted in whole periods: two samples missing at 250 Hz make a step a rounding error longer than
    three periods, which split the log; three missing are a gap."""
    log = synthetic_log(n=2000, rate_hz=250.0)
    keep = np.ones(log.n_samples, dtype=bool)
    keep[[700, 701, 1100, 1101, 1300, 1301, 1302]] = False
    dropped = log.select(keep)
    assert max(np.diff(dropped.t)) / np.median(np.diff(dropped.t)) == pytest.approx(4.0)
    assert [(s.start, s.stop) for s in dropped.segments()] == [(0, 1296), (1296, 1993)]


def test_writer_refuses_to_replace_files_unless_asked(good_log):
    with pytest.raises(FileExistsError, match="flight.csv exists"):
        write_log(synthetic_log(), good_log)
    write_log(synthetic_log(n=150), good_log, overwrite=True)
    assert read_log(good_log).n_samples == 150


# ---------------------------------------------------------------------- malformed logs
def _expect(path: Path, pattern: str) -> None:
    before = {p: _digest(p) for p in (path, sidecar_path(path)) if p.exists()}
    with pytest.raises(LogFormatError) as info:
        read_log(path)
    message = str(info.value)
    assert re.search(pattern, message), message
    # the user's files are never modified, not even when they are rejected
    assert {p: _digest(p) for p in before} == before


def test_missing_column_is_named(good_log):
    def drop_vz(lines):
        header = lines[0].split(",")
        j = header.index("vz")
        for i, line in enumerate(lines):
            cells = line.split(",")
            del cells[j]
            lines[i] = ",".join(cells)

    _rewrite_csv(good_log, drop_vz)
    _expect(good_log, r"flight\.csv: line 1 \(header\): missing required column\(s\) \['vz'\]")


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_nan_or_inf_is_named_with_column_and_row(good_log, value):
    _set_cell(good_log, 42, "thrust_cmd", value)
    _expect(good_log, rf"flight\.csv: line 42 \(sample 41\), column 'thrust_cmd': value '{value}' is not finite")


def test_text_in_a_number_column_is_named(good_log):
    _set_cell(good_log, 7, "x", "oops")
    _expect(good_log, r"flight\.csv: line 7 \(sample 6\), column 'x': 'oops' is not a number")


@pytest.mark.parametrize("value", ["0.05", "0.02"])
def test_non_increasing_time_is_named_with_row(good_log, value):
    _set_cell(good_log, 8, "t", value)  # line 8 holds sample 7 at t = 0.06 s, after 0.05 s: repeat or go back
    _expect(good_log, rf"flight\.csv: line 8 \(sample 7\), column 't': time {value} s does not increase "
                      r"\(previous sample 0\.05 s\)")


def test_quaternion_far_from_unit_norm_is_named_with_row(good_log):
    _set_cell(good_log, 100, "qw", "1.5")
    _expect(good_log, r"flight\.csv: line 100 \(sample 99\), columns 'qw, qx, qy, qz': quaternion norm 1\.5\d* is far "
                      r"from 1")


def test_a_row_with_missing_fields_is_named(good_log):
    def shorten(lines):
        lines[30] = ",".join(lines[30].split(",")[:-2])

    _rewrite_csv(good_log, shorten)
    _expect(good_log, r"flight\.csv: line 31 \(sample 30\) has 16 fields, the header has 18")


def test_partial_optional_group_is_named(good_log):
    def add_ax(lines):
        lines[0] += ",ax"
        for i in range(1, len(lines)):
            lines[i] += ",0.0"

    _rewrite_csv(good_log, add_ax)
    _expect(good_log, r"optional columns \['ax', 'ay', 'az'\] come all together; has \['ax'\] but not column\(s\) "
                      r"\['ay', 'az'\]")


def test_unknown_json_key_is_named_with_its_line(good_log):
    _edit_json(good_log, lambda d: d["vehicle"].update({"inertia": [1, 2, 3]}))
    _expect(good_log, r"flight\.json: key 'vehicle\.inertia', line \d+: unknown key; allowed in vehicle: "
                      r"\['drag', 'mass', 'motor_time_constant', 'rotor_positions', 'thrust_map'\]")


@pytest.mark.parametrize("key, value, pattern", [
    ("mass", "1.0", r"key 'vehicle\.mass', line \d+: must be a number, got a string '1\.0'"),
    ("mass", True, r"key 'vehicle\.mass', line \d+: must be a number, got a boolean True"),
    ("drag", [0.3, 0.3], r"key 'vehicle\.drag', line \d+: must be a list of 3 numbers"),
    ("rotor_positions", [[0, 0, 0]] * 3, r"key 'vehicle\.rotor_positions', line \d+: must be a list of 4"),
    ("motor_time_constant", -0.01, r"key 'vehicle\.motor_time_constant', line \d+: must be a finite number in \[0, 1\]"),
])
def test_json_key_of_the_wrong_type_is_named(good_log, key, value, pattern):
    _edit_json(good_log, lambda d: d["vehicle"].update({key: value}))
    _expect(good_log, r"flight\.json: " + pattern)


def test_json_scene_errors_are_named(good_log):
    _edit_json(good_log, lambda d: d["scene"].update({"ground_z": "low"}))
    _expect(good_log, r"flight\.json: key 'scene\.ground_z', line \d+: must be a number or null, got a string")
    _edit_json(good_log, lambda d: d["scene"].update({"ground_z": 0.0, "walls": [{"point": [0, 0, 0]}]}))
    _expect(good_log, r"flight\.json: key 'scene\.walls\[0\]\.normal'.*required key is missing")
    _edit_json(good_log, lambda d: d.update({"scene": {"walls": [], "ground_z": 0.0}}))
    _expect(good_log, r"flight\.json: key 'scene\.ceiling_z'.*required key is missing")


def test_broken_json_and_missing_sidecar_name_the_file(good_log):
    sidecar_path(good_log).write_text('{"vehicle": {"mass": 1.0,,}')
    _expect(good_log, r"flight\.json: line 1: not valid JSON")
    sidecar_path(good_log).unlink()
    with pytest.raises(FileNotFoundError, match=r"flight\.csv: its JSON sidecar .*flight\.json does not exist"):
        read_log(good_log)


def test_rate_outside_the_supported_range_is_rejected(tmp_path):
    path = tmp_path / "slow.csv"
    write_log(synthetic_log(n=100, rate_hz=20.0), path)
    _expect(path, r"slow\.csv: column 't': median sample rate 20\.0 Hz is outside the supported 50 Hz to 1000 Hz")


def test_a_motor_time_constant_round_trips_and_reaches_the_simulators_vehicle(tmp_path):
    log = synthetic_log()
    log.vehicle = replace(log.vehicle, motor_time_constant=0.035)
    csv_path, json_path = write_log(log, tmp_path / "lag.csv")
    assert json.loads(json_path.read_text())["vehicle"]["motor_time_constant"] == 0.035
    back = read_log(csv_path)
    assert back.vehicle.motor_time_constant == 0.035
    assert back.vehicle.to_vehicle_params().motor_time_constant == 0.035
