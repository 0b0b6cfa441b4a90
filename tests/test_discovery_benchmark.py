"""bench-discover --acceptance: its figures from the per-log records, and how its pairs are planned (no flights)."""

from __future__ import annotations

import numpy as np
import pytest

from discovery.benchmark import summarise
from discovery.hidden_effects import draw_pair, steady_height_shift
from discovery.scenarios import SCENARIOS
from wall_env.vehicle import GRAVITY, VehicleParams


def _record(case, errors, in_std, *, named_right=True, form_right=True, left_open=(), seed=7):
    return {"case": case, "flown": [{"name": case}], "ended_early": False, "named": [case], "named_right": named_right,
            "form_right": form_right, "spurious": [], "param_errors": errors, "param_errors_in_std": in_std,
            "forms_left_open": list(left_open), "gap_reduction": 0.9, "seed": seed, "rate_hz": 100.0}


def test_misses_of_ten_percent_are_told_apart(capsys):
    records = [
        _record("a", {"a.x": 0.02}, {"a.x": 0.5}),
        _record("b", {"b.x": 0.12}, {"b.x": 1.5}),  # noise: the log does not resolve it to 10 %
        _record("c", {"c.x": 0.30}, {"c.x": 3.0}),  # beyond its noise
        _record("d", {"d.x": 0.25, "d.k": None}, {"d.x": 40.0}, form_right=False, left_open=["d[k]"]),
        {"case": "clean", "flown": [], "ended_early": False, "named": [], "seed": 8, "rate_hz": 50.0},
        {"case": "e", "flown": [{"name": "e"}], "ended_early": True, "seed": 9, "rate_hz": 50.0},
    ]
    summary = summarise(records, [0], 30.0)
    assert summary["logs_with_hidden_effects"] == 4 and summary["named_right_no_spurious"] == 4
    assert summary["logs_with_all_params_within_10_percent"] == 1
    assert summary["params_off_within_2_std"] == 1
    assert [o["param"] for o in summary["params_off_by_more_than_10_percent"]] == ["b.x", "c.x", "d.x", "d.k"]
    assert summary["clean_logs_nothing_named"] == 1 and summary["flights_ended_early"] == 1
    out = capsys.readouterr().out
    assert "b (log seed 7, 100 Hz): b.x 12.0 %, 1.5 standard errors" in out
    assert "1 within 2 standard errors" in out and "2 of a fuller form the report names as left open" in out
    assert "1 farther or missing" in out


@pytest.mark.parametrize("scale", [0.85, 1.0, 1.15])
def test_steady_height_shift_of_a_thrust_scale_is_the_pids_rest_point(scale):
    # T = m (g - kp e) and scale * T = m g at rest: e = g (1 - 1 / scale) / kp
    shift = steady_height_shift({"name": "thrust_scale", "params": {"scale": scale}}, 10.0)
    assert shift == pytest.approx(GRAVITY * (1.0 - 1.0 / scale) / 10.0, abs=1e-9)


def test_steady_height_shift_of_a_steady_force_is_its_vertical_part_over_the_spring():
    shift = steady_height_shift({"name": "constant_force", "params": {"F": [0.3, -0.2, -0.4]}}, 20.0)
    assert shift == pytest.approx(-0.4 / (VehicleParams().mass * 20.0), abs=1e-12)


def test_a_ground_pair_is_planned_where_the_vehicle_will_hold_it():
    rng = np.random.default_rng(5)
    effects, flight = draw_pair(("ground_effect", "thrust_scale"), rng)
    planned = SCENARIOS["ground-survey"].survey["centre"][2]
    shift = steady_height_shift(effects[1], 10.0)  # the ground survey flies the authors' PID, kp_z = 10
    assert abs(shift) > 0.02
    assert flight["survey"]["centre"][2] == pytest.approx(planned - shift, abs=1e-12)
