"""Discovery on logs from a simulator written apart from the project's (``tests/independent_sim.py``):
another vehicle, controller, integrator and noise; the effects written from the literature."""

from __future__ import annotations

import pytest

from discovery.flight_log import read_log
from discovery.workflow import Discovery
from tests.discovery_support import relative_errors
from tests.independent_sim import fly, write


def _discover(path):
    return Discovery().fit([read_log(path)])


def test_wall_suction_and_a_steady_wind_from_another_simulator(tmp_path):
    truth = {"suction": (5.5, 0.125), "wind_force": [0.3, -0.3, -0.25]}
    rows = fly(truth, centre=(0.25, 0.0, 1.0), amplitude=(0.09, 0.5, 0.25), period=(7.0, 9.0, 3.0),
               duration=60.0, rate_hz=100.0, seed=11)
    found = _discover(write(rows, tmp_path / "wall.csv", seed=11))
    assert sorted(found.names_) == ["constant_force", "wall_suction"]
    fitted = {f.name: f.values for f in found.effects_}
    assert max(relative_errors(fitted["wall_suction"], {"k_s": 5.5, "d_thr": 0.125})) < 0.05
    assert max(relative_errors(fitted["constant_force"], {"F": truth["wind_force"]})) < 0.05
    assert found.gap_after_["force_rms_N"] < 0.2 * found.gap_before_["force_rms_N"]


def test_quadratic_drag_in_wind_from_another_simulator(tmp_path):
    C, wind = [0.12, 0.09, 0.07], [1.6, -1.2, 0.0]
    rows = fly({"quadratic_drag": (C, wind)}, centre=(1.5, 0.0, 1.0), amplitude=(2.0, 2.0, 0.4),
               period=(5.0, 6.0, 3.0), duration=60.0, rate_hz=200.0, seed=12)
    found = _discover(write(rows, tmp_path / "drag.csv", seed=12, wall=False))
    assert found.names_ == ["quadratic_drag"]
    drag = found.effects_[0]
    assert drag.option_values == {"wind": True}
    assert max(relative_errors(drag.values, {"C": C})) < 0.1
    assert drag.values["w"][:2] == pytest.approx(wind[:2], abs=0.15)  # m/s


def test_a_clean_log_from_another_simulator_names_nothing(tmp_path):
    rows = fly({}, centre=(1.5, 0.0, 1.0), amplitude=(1.0, 1.0, 0.4), period=(5.0, 6.0, 3.0), duration=60.0,
               rate_hz=50.0, seed=13)
    assert _discover(write(rows, tmp_path / "clean.csv", seed=13, wall=False)).names_ == []
