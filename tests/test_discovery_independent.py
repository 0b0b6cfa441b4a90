"""Discovery on logs from a simulator written apart from the project's (``tests/independent_sim.py``):
another vehicle, controller, integrator and noise; the effects written from the literature."""

from __future__ import annotations

import json

import numpy as np
import pytest

from discovery.fitting import EffectFit
from discovery.flight_log import read_log
from discovery.motor_lag import LagTerm, MotorLag
from discovery.residuals import prepare
from discovery.workflow import Discovery
from tests.discovery_support import relative_errors
from tests.independent_sim import NEAR_WALL, fly, write


def _discover(path):
    return Discovery().fit([read_log(path)])


def test_wall_suction_and_a_steady_wind_from_another_simulator(tmp_path):
    truth = {"suction": (5.5, 0.125), "wind_force": [0.3, -0.3, -0.25]}
    rows = fly(truth, centre=(0.25, 0.0, 1.0), amplitude=(0.09, 0.5, 0.25), period=(7.0, 9.0, 3.0),
               duration=60.0, rate_hz=100.0, seed=11, gains=NEAR_WALL)
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


def test_a_motor_lag_from_another_simulator_is_found_and_leaves_the_vertical_drag_right(tmp_path):
    """Rotors lagging their command by 30 ms look like negative vertical drag on a climb and descent; without the
    lag the vertical drag came out 41-55 % low. The log starts 2 s into the flight, as one recorded in flight does."""
    D = [0.17, 0.23, 0.39]
    rows = fly({"linear_drag": D}, centre=(1.5, 0.0, 1.0), amplitude=(1.0, 1.0, 0.4), period=(5.0, 6.0, 3.0),
               duration=62.0, rate_hz=100.0, seed=5, motor_lag=0.03)[200:]
    found = _discover(write(rows, tmp_path / "lag.csv", seed=5, wall=False))
    assert found.names_ == ["linear_drag"]
    lag = found.motor_lag_
    assert lag["kept"] and lag["time_constant_s"] == pytest.approx(0.03, rel=0.1)
    assert lag["time_constant_s"] > 3 * lag["std_s"]
    half = 1.96 * lag["std_s"]  # the largest error the 95 % interval allows, against the true lag at its near end
    assert lag["interval_95_share"] == pytest.approx(half / (lag["time_constant_s"] - half))
    assert (lag["to_narrow"] is not None) == (lag["interval_95_share"] > 0.1)
    assert found.model_.vehicle.motor_time_constant == lag["time_constant_s"]
    assert max(relative_errors(found.effects_[0].values, {"D": D})) < 0.1
    # the gap is measured against the user's nominal model, which has no lag
    assert found.gap_after_["force_rms_N"] < 0.2 * found.gap_before_["force_rms_N"]
    # a vehicle block that gives the lag is taken at its word
    sidecar = json.loads((tmp_path / "lag.json").read_text())
    sidecar["vehicle"]["motor_time_constant"] = 0.03
    (tmp_path / "lag.json").write_text(json.dumps(sidecar))
    given = _discover(tmp_path / "lag.csv")
    assert given.motor_lag_ is None and given.model_.vehicle.motor_time_constant == 0.03
    assert given.names_ == ["linear_drag"]
    assert max(relative_errors(given.effects_[0].values, {"D": D})) < 0.05
    # the vertical drag moves with the lag: the lag found carries its own error into the drag's, which a lag taken as
    # known does not. The drag's standard errors are those it had fitted beside the lag, at least what the lag's
    # standard error moves it by
    moves = lag["moves"]
    assert moves["effect"] == "linear_drag" and moves["parameter"] == "D[2]"
    carried = abs(moves["with"] - moves["without"]) / lag["time_constant_s"] * lag["std_s"]
    std, known = found.param_std_[0]["D"], given.param_std_[0]["D"]
    assert known[2] < 0.5 * carried <= 0.5 * std[2]
    assert std == pytest.approx(np.fmax(known, lag["effect_std"]["linear_drag"]["D"]), rel=0.05)
    assert ("linear_drag", "D[2]") in found.widened_by_lag_ and not given.widened_by_lag_
    # loose for that reason, the vertical drag is pinned by the manoeuvre that pins the lag
    from types import SimpleNamespace

    from discovery.report import _loose
    looser = SimpleNamespace(effects_=found.effects_, param_std_=[{"D": [std[0], std[1], 0.2 * D[2]]}],
                             widened_by_lag_=found.widened_by_lag_)
    (entry,) = [x for x in _loose(looser) if x["parameter"] == "D[2]"]
    assert entry["manoeuvre"].startswith("climb and descend in steps of different lengths")
    # the same flight without the lag: nothing is taken for one
    rows = fly({"linear_drag": D}, centre=(1.5, 0.0, 1.0), amplitude=(1.0, 1.0, 0.4), period=(5.0, 6.0, 3.0),
               duration=62.0, rate_hz=100.0, seed=5)[200:]
    found = _discover(write(rows, tmp_path / "no_lag.csv", seed=5, wall=False))
    assert found.names_ == ["linear_drag"] and not found.motor_lag_["kept"]
    assert found.model_.vehicle.motor_time_constant == 0.0


def test_a_motor_lag_is_found_when_the_rotors_start_away_from_their_command(tmp_path):
    """The simulator starts its rotors at hover thrust under a command far from it, and a gap of 1 s leaves the
    second stretch starting wherever the rotors were. Taking each stretch to start settled at its first command
    made this 30 ms lag 22.9 ms and the vertical drag 9 % low; each stretch's start error is fitted with it."""
    D = [0.17, 0.23, 0.39]
    rows = fly({"linear_drag": D}, centre=(1.5, 0.0, 1.0), amplitude=(1.0, 1.0, 0.4), period=(5.0, 6.0, 3.0),
               duration=60.0, rate_hz=100.0, seed=5, motor_lag=0.03)
    rows = rows[:3000] + rows[3100:]  # 1 s lost at 30 s
    found = _discover(write(rows, tmp_path / "lag.csv", seed=5, wall=False))
    assert found.names_ == ["linear_drag"]
    lag = found.motor_lag_
    assert lag["kept"] and lag["time_constant_s"] == pytest.approx(0.03, rel=0.1)
    assert max(relative_errors(found.effects_[0].values, {"D": D})) < 0.05


def test_a_lag_too_small_to_pay_is_reported_with_the_parameter_it_would_move(tmp_path):
    """An 8 ms lag on one climb-and-descent pace: the drag absorbs it (D_z 12 % low) and the held-out score cannot
    tell the two apart, so the lag is not kept; the report says so, naming the drag entry and the manoeuvre."""
    D = [0.17, 0.23, 0.39]
    rows = fly({"linear_drag": D}, centre=(1.5, 0.0, 1.0), amplitude=(1.0, 1.0, 0.4), period=(5.0, 6.0, 3.0),
               duration=60.0, rate_hz=100.0, seed=56, motor_lag=0.008)
    found = _discover(write(rows, tmp_path / "small.csv", seed=56, wall=False))
    lag = found.motor_lag_
    assert found.names_ == ["linear_drag"] and not lag["kept"] and lag["determined"]
    assert lag["moves"]["parameter"] == "D[2]"
    assert lag["moves"]["with"] == pytest.approx(D[2], rel=0.05)  # with the lag, the drag is right
    limit = next(x for x in found.limits_ if "motor_lag" in x["effects"])
    assert limit["effects"] == ["motor_lag", "linear_drag"] and "D[2]" in limit["reason"]
    assert "different lengths" in limit["manoeuvre"]


def test_a_motor_lag_under_a_thrust_scale(tmp_path):
    """The rotors produce 0.85 of their lagging thrust: fitted on the logged thrust, the lag came out 0.85 of the
    true one; it is fitted under the thrust scale found first."""
    rows = fly({"thrust_scale": 0.85}, centre=(1.5, 0.0, 1.0), amplitude=(1.0, 1.0, 0.4), period=(5.0, 6.0, 3.0),
               duration=60.0, rate_hz=100.0, seed=8, motor_lag=0.03)
    found = _discover(write(rows, tmp_path / "scale.csv", seed=8, wall=False))
    assert found.names_ == ["thrust_scale"]
    assert found.effects_[0].values["scale"][0] == pytest.approx(0.85, rel=0.02)
    assert found.motor_lag_["kept"] and found.motor_lag_["time_constant_s"] == pytest.approx(0.03, rel=0.07)


@pytest.mark.parametrize("seed", [320, 322])
def test_a_lag_that_leaves_the_vertical_drag_right_is_kept_when_the_score_cannot_pay_for_it(seed, tmp_path):
    """A climb and descent at one pace, about as fast as the other axes' sweeps: the lag and the vertical drag
    look alike, so the lag lowers the held-out score by little. Seed 320: scored on every row, the first second
    (the rotors start at hover, far from their command, and a held-out fold takes them settled) made the lag
    score worse than none. Seed 322: scored past the starts it predicts held-out rows 6.5 % better, one price
    short, at 5.6 standard errors. Both were dropped and D[2] written 23-25 % low."""
    D = [0.25, 0.26, 0.38]
    rows = fly({"linear_drag": D}, centre=(1.5, 0.0, 1.0), amplitude=(0.8, 0.7, 0.4), period=(4.2, 5.7, 4.1),
               duration=60.0, rate_hz=50.0, seed=seed, motor_lag=0.03)
    found = _discover(write(rows, tmp_path / "lag.csv", seed=seed, wall=False))
    lag = found.motor_lag_
    assert found.names_ == ["linear_drag"] and lag["kept"] and lag["explained"] > 0
    assert abs(lag["time_constant_s"] - 0.03) < 3 * lag["std_s"]
    assert found.model_.vehicle.motor_time_constant == lag["time_constant_s"]
    assert max(relative_errors(found.effects_[0].values, {"D": D})) < 0.05
    assert not any("motor_lag" in limit["effects"] for limit in found.limits_)


def test_no_lag_is_kept_beside_a_structure_the_library_cannot_describe(tmp_path):
    """A force growing with height (outside the library) flown with a 30 ms lag: next to the 1 N it leaves, a
    lag fitted at 58 +- 11 ms predicted the rows past the starts better and was kept when the relaxed rules
    applied there too; it is not kept, and the residual is reported as living against height."""
    import dataclasses

    from tests.independent_cases import cases, fly_case

    case = dataclasses.replace(next(c for c in cases(330) if c.name == "height_force"), motor_lag=0.03)
    found = _discover(fly_case(case, 330, 100.0, tmp_path))
    assert found.names_ == [] and not found.motor_lag_["kept"]
    assert found.model_.vehicle.motor_time_constant == 0.0
    assert found.unexplained_ is not None and found.unexplained_["where"]["regressor"] == "height above ground"


def test_the_second_simulators_wall_guard_stops_a_light_vehicle_that_suction_pulls_through_the_wall(monkeypatch):
    """At 0.6 kg the near-wall loop (12 N/m) loses to suction (2 k_s, 13 N/m here) and the vehicle is pulled through
    the wall, which this simulator lets pass by default; with ``WALL_GUARD_RADIUS`` the rotors' guards stop at it."""
    import tests.independent_sim as sim
    from tests.independent_cases import WALL

    def closest(guard: float | None) -> float:
        monkeypatch.setattr(sim, "WALL_GUARD_RADIUS", guard)
        rows = fly({"suction": (6.56, 0.124)}, duration=20.0, rate_hz=100.0, seed=7786, **WALL)
        return min(min((np.asarray(p) + sim._R(np.asarray(q)) @ r)[0] for r in sim.ROTORS_BODY)
                   for _, p, _, q, *_ in rows)

    monkeypatch.setattr(sim, "MASS", 0.6)
    assert closest(None) < -0.03  # through the wall
    assert 0.05 - 0.005 < closest(0.05) < 0.05  # pressed into the guard's spring by at most 5 mm


def test_a_vehicle_that_strikes_the_wall_is_left_out_in_contact_and_the_suction_is_fitted_beyond_it(tmp_path,
                                                                                                   monkeypatch):
    """A 0.6 kg vehicle loses to suction and strikes the wall, where its rotors' 5 cm guards stop it, again and
    again, pinned and sliding there. That contact (the wall pushes, and friction holds the vehicle up) was fitted as
    aerodynamics: nothing was named, 12 % of the weight was left unexplained "against thrust", and the vehicle stuck
    to the wall at 1 m was called "held up" and "ground contact". Each strike is now found (an outward jolt beyond the
    thrust's at the closest approach, several times at one distance), the samples nearer than the strikes left out
    as wall contact, and wall suction fitted on the rest."""
    import tests.independent_sim as sim
    from tests.independent_cases import WALL

    monkeypatch.setattr(sim, "MASS", 0.6)
    monkeypatch.setattr(sim, "WALL_GUARD_RADIUS", 0.05)
    truth = {"k_s": 6.56, "d_thr": 0.124}
    rows = fly({"suction": (truth["k_s"], truth["d_thr"])}, duration=60.0, rate_hz=100.0, seed=7786, **WALL)
    found = _discover(write(rows, tmp_path / "strikes.csv", seed=7786))
    assert {x["reason"] for x in found.left_out_} == {"wall contact"}
    note = next(n for n in found.notes_ if "struck wall 0" in n)
    touch = float(note.split("nearer than ")[1].split(" mm")[0])
    assert 50.0 < touch < 56.0  # the guard reaches 50 mm; the strikes stop the rotor centres 3-4 mm inside that
    assert found.names_ == ["wall_suction"]
    assert max(relative_errors(found.effects_[0].values, truth)) < 0.1
    # suction nearer the wall than the strikes is not determined: a limit says so
    assert any(limit["effects"] == ["wall_suction"] and "touched wall 0" in limit["reason"] for limit in found.limits_)


def test_a_vehicle_suction_holds_sliding_along_the_wall_without_striking_it_is_left_out_in_contact(tmp_path,
                                                                                                     monkeypatch):
    """Flown between waypoints (sharpness 2), the survey eases up to the wall too slowly to strike it, and suction
    holds the rotors' 4 cm guards against it as the vehicle goes on along it, friction holding it back. No strike
    was found: the contact was fitted as suction, k_s 3.5 % off and 2.9 % of the weight left over. The friction at
    the closest approach is now found, those samples left out as wall contact, and suction is fitted on the rest."""
    import tests.independent_sim as sim
    from tests.independent_cases import cases, fly_case

    monkeypatch.setattr(sim, "WALL_GUARD_RADIUS", 0.04)
    case = next(c for c in cases(406) if c.name == "suction")
    found = _discover(fly_case(case, 406, 100.0, tmp_path, waypoints=2.0))
    assert {x["reason"] for x in found.left_out_} == {"wall contact"}
    note = next(n for n in found.notes_ if "slid along wall 0" in n)
    assert "struck" not in note  # found by its friction alone
    assert found.names_ == ["wall_suction"]
    assert max(relative_errors(found.effects_[0].values, case.expected["wall_suction"])) < 0.02
    assert found.unexplained_ is None


def test_strikes_on_a_wall_missing_from_the_scene_are_found_left_out_and_the_drag_fitted_on_the_rest(tmp_path,
                                                                                                     monkeypatch):
    """A 0.6 kg vehicle flies a fast survey in wind; its sidecar has no wall, but a wall at x = 0 stops its rotors'
    4 cm guards twelve times and holds it there. That contact was fitted as a 0.45 thrust scale and a 3.3 N upward
    steady force, with 1.5 N unexplained. The strikes are now found against a plane where the rotor centres went
    farthest, along the tried normal nearest their push, and left out; the quadratic drag is fitted on the rest."""
    import tests.independent_sim as sim
    from discovery.surface_contact import UNDECLARED_CONTACT

    monkeypatch.setattr(sim, "MASS", 0.6)
    monkeypatch.setattr(sim, "WALL_GUARD_RADIUS", 0.04)
    C, wind = [0.12, 0.09, 0.07], [1.6, -1.2, 0.0]
    rows = fly({"quadratic_drag": (C, wind)}, centre=(1.5, 0.0, 1.0), amplitude=(2.0, 2.0, 0.4),
               period=(5.0, 6.0, 3.0), duration=60.0, rate_hz=100.0, seed=7861)
    found = _discover(write(rows, tmp_path / "unseen_wall.csv", seed=7861, wall=False))
    assert {x["reason"] for x in found.left_out_} == {UNDECLARED_CONTACT}
    note = next(n for n in found.notes_ if "struck a surface the scene does not have" in n)
    assert "pushed along (+1.000, +0.000, +0.000)" in note
    strikes = int(note.split("does not have ")[1].split(" times")[0])
    assert strikes >= 10  # one or two each time the survey swings to x = -0.5 m, every 5 s
    assert any(limit["effects"] == ["wall_suction"] and "struck a surface the scene does not have" in limit["reason"]
               for limit in found.limits_)
    assert found.names_ == ["quadratic_drag"]
    fitted = found.effects_[0].values
    assert max(relative_errors({"C": fitted["C"]}, {"C": C})) < 0.1
    assert np.linalg.norm(np.asarray(fitted["w"]) - wind) < 0.1 * np.linalg.norm(wind)
    assert found.gap_after_["force_rms_N"] < 0.05 * found.gap_before_["force_rms_N"]


def test_a_vehicle_pressed_against_the_ceiling_is_left_out_in_contact_and_the_ceiling_effect_fitted_beyond_it(
        tmp_path, monkeypatch):
    """Where the image-rotor gain levels off only at 0.3 radii, a survey 8 cm under the ceiling is drawn up onto it,
    and its 3 cm guards stop it there; the loop then holds it pressed against the ceiling with up to 1.35 times the
    weight in thrust. Fitted as aerodynamics, that named nothing and left 3.7 N unexplained. The pressed stretches
    are now ceiling contact, left out, and the ceiling effect is fitted on the rest."""
    import tests.independent_sim as sim
    from tests.independent_cases import CEILING_CLOSE

    monkeypatch.setattr(sim, "GAIN_FLOOR_RADII", 0.3)
    monkeypatch.setattr(sim, "CEILING_GUARD_RADIUS", 0.03)
    radius = 0.08
    rows = fly({"ceiling": (radius, 0.012)}, duration=60.0, rate_hz=100.0, seed=7840, waypoints=2.0,
               **{**CEILING_CLOSE, "centre": (1.5, 0.0, sim.CEILING_Z - 0.08)})
    found = _discover(write(rows, tmp_path / "pressed.csv", seed=7840, wall=False, ceiling=True))
    assert {x["reason"] for x in found.left_out_} == {"ceiling contact"}
    assert any("pressed against the ceiling" in n for n in found.notes_)
    assert found.names_ == ["ceiling_effect"]
    assert found.effects_[0].values["radius"] == pytest.approx(radius, rel=0.05)
    assert any(limit["effects"] == ["ceiling_effect"] and "touched the ceiling" in limit["reason"]
               for limit in found.limits_)


def test_the_second_simulators_judge_counts_a_parameter_off_as_said_only_when_the_report_says_so():
    """``python -m tests.independent_cases`` counts the parameters more than 10 % off that the report called
    uncertain: loose, undetermined, or named in a limit. One it wrote with a narrow interval is not said."""
    from tests.independent_cases import Case, judge

    case = Case("x", {}, {}, {"ground_effect": {"radius": 0.08, "offset": 0.012}, "linear_drag": {"D": [0.3, 0.3, 0.4]}})
    report = {"effects": [{"name": "ground_effect", "params": {"radius": 0.0802, "offset": 0.0194}},
                          {"name": "linear_drag", "params": {"D": [0.3, 0.3, 0.22]}}],
              "gap_before": {"force_rms_N": 0.5}, "gap_after": {"force_rms_N": 0.02}, "noise": {"floor_N": 0.02},
              "loose": [], "undetermined": [], "limits": []}
    assert judge(case, report)["off_said_uncertain"] == {"ground_effect.offset": False, "linear_drag.D": False}
    report["loose"] = [{"effect": "ground_effect", "parameter": "offset"}]
    report["limits"] = [{"effects": ["motor_lag", "linear_drag"], "reason": "a motor lag of 31 ms fits, and with it "
                         "linear_drag D[2] would be 0.39 instead of 0.22: the flight cannot tell the lag from it"}]
    assert judge(case, report)["off_said_uncertain"] == {"ground_effect.offset": True, "linear_drag.D": True}


def test_the_rows_a_start_error_reaches_are_the_first_of_its_segment(tmp_path):
    """The rows left out when a lag is scored: those within half a smoothing window plus a few time constants of
    a segment's first sample, and no others."""
    rows = fly({}, centre=(1.5, 0.0, 1.0), amplitude=(1.0, 1.0, 0.4), period=(5.0, 6.0, 3.0), duration=40.0,
               rate_hz=100.0, seed=7, motor_lag=0.04)
    data = prepare([read_log(write(rows[:1500] + rows[1550:], tmp_path / "gap.csv", seed=7, wall=False))])
    term = LagTerm(data, MotorLag(segments=2))
    clear = term.clear_of_starts(np.array([0.04, 4.8, -1.0]))
    for seg, mask in zip(data.segments, clear):
        t = seg.t[seg.fit_rows] - seg.t[0]
        assert not mask[0] and mask[t > 0.5 + 10 * 0.04].all()
        assert t[~mask].max() < 0.5 + 10 * 0.04
    # without start errors every row is scored
    assert all(mask.all() for mask in LagTerm(data, MotorLag()).clear_of_starts(np.array([0.04])))


def test_a_thrust_map_that_ties_with_the_ceiling_on_a_steady_thrust_gives_way_to_it(tmp_path, monkeypatch):
    """Hovering under a ceiling with a 0.5 N rms random force: the stiff loop's thrust answers it, and an affine
    thrust map of scale 0.32 scored 2.0 better than the ceiling effect (a price is 15), so it was named. Near a
    surface on a steady thrust the affine map is no longer fitted, and the report says why; with it fitted (as
    before), the tie on a thrust varying by less than 10 % goes to the ceiling effect, and the report says why."""
    import discovery.selection
    from discovery.report import format_summary
    from tests.independent_cases import CEILING

    rows = fly({"ceiling": (0.08, 0.0)}, duration=60.0, rate_hz=100.0, seed=370, force_noise=0.5, **CEILING)
    path = write(rows, tmp_path / "ceiling.csv", seed=370, wall=False, ceiling=True)
    plain = _discover(path)
    assert plain.names_ == ["ceiling_effect"]
    assert plain.effects_[0].values["radius"] == pytest.approx(0.08, rel=0.05)
    limit = next(x for x in plain.limits_ if x["effects"] == ["thrust_scale[affine]"])
    assert "not fitted" in limit["reason"] and "near the ceiling" in limit["reason"]
    monkeypatch.setattr(discovery.selection, "_affine_map_confounded", lambda data, thrust: [])
    found = _discover(path)
    assert found.names_ == ["ceiling_effect"]
    assert found.effects_[0].values["radius"] == pytest.approx(0.08, rel=0.05)
    pair = next(a for a in found.selection_.alike if a["alike"] == "thrust_scale")
    assert pair["chosen"] == "ceiling_effect" and pair["score_difference"] < 0 and "stiff loop" in pair["why_chosen"]
    assert "ceiling_effect was chosen: the thrust varied too little" in format_summary(found.report())


def test_a_start_error_is_never_fitted_to_the_rows_it_is_scored_on(tmp_path):
    """Cross-validation holds a segment's start error settled (0) in the folds whose held-out rows it reaches, and
    fits it in the others."""
    rows = fly({}, centre=(1.5, 0.0, 1.0), amplitude=(1.0, 1.0, 0.4), period=(5.0, 6.0, 3.0), duration=40.0,
               rate_hz=100.0, seed=7, motor_lag=0.04)
    data = prepare([read_log(write(rows[:1500] + rows[1550:], tmp_path / "gap.csv", seed=7, wall=False))])
    assert len(data.segments) == 2
    problem = EffectFit(data, [MotorLag(segments=2)], data.residuals(data.nominal_model))
    full = problem.fit()
    assert full.theta[0] == pytest.approx(0.04, rel=0.1)
    assert full.theta[1] == pytest.approx(4.8, rel=0.2)  # the rotors start at hover, 12.75 N, under 7.96 N
    _, fold_theta = problem.cross_validate(full)
    for s, seg in enumerate(data.segments):
        # folds holding out a sample within half a window plus 5 time constants of the start hold it settled
        reach = seg.t < seg.t[0] + 0.5 + 5 * 0.04
        near = {int(k) for k in seg.fold[reach]}
        assert seg.fold[0] in near
        for k, theta in enumerate(fold_theta):
            if k in near:
                assert theta[1 + s] == 0.0
            else:  # and the others fit it
                assert theta[1 + s] != 0.0
    others = [float(theta[1]) for k, theta in enumerate(fold_theta) if k != 0]
    assert others == pytest.approx([float(full.theta[1])] * 4, rel=0.05)


def test_the_share_a_95_percent_interval_allows_is_taken_against_the_true_value():
    """Seed 7900 fitted a 30 ms lag as 33.0 +- 1.66 ms: against the estimate its 95 % interval is +-9.8 %, and no
    manoeuvre was offered, yet it was 10.1 % off. Against the true value at the interval's near end the interval allows
    10.9 %: more than 10 %, so the report says how to narrow it. An interval that reaches zero allows any error."""
    from discovery.determination import NARROW_INTERVAL_SHARE, interval_share

    assert 1.96 * 1.66 / 33.04 < NARROW_INTERVAL_SHARE < interval_share(33.04, 1.66)
    assert interval_share(33.04, 1.66) == pytest.approx(0.109, abs=0.001)
    assert abs(33.04 - 30.0) / 30.0 < interval_share(33.04, 1.66)
    assert interval_share(1.0, 0.6) == float("inf")


@pytest.mark.parametrize("std_s, says", [(0.0009, False), (0.0019, True)])
def test_a_lag_the_flight_determines_loosely_is_given_with_its_interval_and_the_manoeuvre(std_s, says):
    """One minute of a climb and descent at one pace determines a 30 ms lag to about 6 % (one standard error): the
    summary then says how wide the 95 % interval is and which flight narrows it; a tight one gets no such line."""
    from discovery.determination import MANOEUVRES
    from discovery.report import format_summary

    share = 1.96 * std_s / (0.031 - 1.96 * std_s)
    lag = {"time_constant_s": 0.031, "std_s": std_s, "interval_95_share": share,
           "to_narrow": MANOEUVRES[("motor_lag", "time_constant")] if share > 0.1 else None,
           "explained": 0.01, "force_rms_N": 0.02, "kept": True, "reason": "", "determined": True, "moves": None}
    report = {"effects": [], "motor_lag": lag, "notes": [], "limits": [], "details": {"selection": {}},
              "gap_before": {"force_rms_N": 0.3, "prediction_rms_m": 0.03},
              "gap_after": {"force_rms_N": 0.024, "prediction_rms_m": 0.005}, "noise": {"floor_N": 0.023}}
    text = format_summary(report)
    assert "found a motor lag: time_constant=0.031 +- " in text
    assert ("determines the motor lag only to +-14 % (95 % interval); to narrow it: climb and descend in steps "
            "of different lengths" in text) == says


def test_an_effect_left_undetermined_once_a_stand_in_goes_is_not_written_and_the_stand_in_is_asked_again(
        tmp_path, monkeypatch):
    """Swept 3.5-22.5 cm under the ceiling, the ceiling's pull holds the vehicle against it (the rotors 1 mm away)
    and the ceiling effect was dropped as a stand-in beside an affine thrust map; fitted alone, the map's scale went
    to its lowest bound, 0.3, with a 9.2 N offset, and was written. The map is now left out as undetermined, the
    ceiling effect judged again without it and kept, and what neither describes reported. (Near a surface on a
    steady thrust the affine map is not fitted at all now; it is here, as it is on any other flight.)"""
    import discovery.selection
    from discovery.report import format_summary

    monkeypatch.setattr(discovery.selection, "_affine_map_confounded", lambda data, thrust: [])
    from tests.independent_cases import CEILING
    from tests.independent_sim import CEILING_Z

    flight = {**CEILING, "centre": (1.5, 0.0, CEILING_Z - 0.13), "amplitude": (0.6, 0.6, 0.095)}
    rows = fly({"ceiling": (0.08, 0.0)}, duration=60.0, rate_hz=100.0, seed=382, **flight)
    found = _discover(write(rows, tmp_path / "ceiling.csv", seed=382, wall=False, ceiling=True))
    assert found.names_ == ["ceiling_effect"] and found.stand_ins_ == []
    left_out = [c for c in found.undetermined_ if c["effect"] == "thrust_scale"]
    assert left_out and left_out[0]["action"] == "effect left out of the model file"
    assert not any("thrust_scale" in limit["effects"] and "proxy" in limit for limit in found.limits_)
    report = found.report()
    assert report["gap_after"]["force_rms_N"] < 0.5 * report["gap_before"]["force_rms_N"]
    assert report["effects"][0]["explained_fraction"] > 0.7  # the share of the set written, not of the map's
    assert report["unexplained"]["share_of_weight"] > 0.02 and "UNEXPLAINED" in format_summary(report)


def test_a_thrust_scale_standing_in_for_a_gust_frees_the_vertical_steady_force_it_had_left_undetermined(
        tmp_path, monkeypatch):
    """A 0.6 kg vehicle flies briskly between waypoints in a steady wind with a horizontal gust near the survey's own
    frequency: its tilts follow the survey, so a thrust scale (its force along the tilted thrust) catches part of the
    gust. Kept beside the steady force, the scale of 0.966 also carried the wind's vertical -0.23 N, which left that
    component undetermined and held at zero; asked whether it stood in for the gust, the scale was compared with the
    vertical component still held, kept, and written (seed 7876). The other effects are now fitted afresh without
    the effect asked about: the scale is a stand-in, and the steady force comes out whole."""
    import tests.independent_sim as sim
    from tests.independent_cases import OPEN

    monkeypatch.setattr(sim, "MASS", 0.6)
    wind = [0.3425, -0.3136, -0.2255]
    rows = fly({"wind_force": wind, "gust": ([0.274, 0.232, 0.0], 0.2047)}, duration=60.0, rate_hz=100.0, seed=7876,
               waypoints=2.0, **OPEN)
    found = _discover(write(rows, tmp_path / "gust_wind.csv", seed=7876, wall=False))
    assert found.names_ == ["constant_force"]
    assert [s["effect"] for s in found.stand_ins_] == ["thrust_scale"]
    assert max(relative_errors(found.effects_[0].values, {"F": wind})) < 0.05
    assert not any(c["effect"] == "constant_force" for c in found.undetermined_)


def test_a_drag_in_wind_whose_coefficients_the_flight_leaves_undetermined_does_not_replace_the_steady_force(
        tmp_path, monkeypatch):
    """A steady wind with a gust at the survey's vertical period (3 s), the heading swinging 50 degrees: the gust
    follows the vertical velocity, and a drag in wind with C about 0.001 and its wind at the 30 m/s bound (only
    C w^2 means anything) scored a little better than the steady force and replaced it. Its coefficients were then
    undetermined and nulled, which left no effect at all and 0.97 N unexplained (seed 7943 of the second
    simulator's wide draws). A fuller form now counts only if the flight determines some of its main parameter."""
    import tests.independent_sim as sim
    from tests.independent_cases import OPEN

    monkeypatch.setattr(sim, "YAW_SWING", (np.radians(50.0), 9.0))
    wind = [-0.727, 0.576, -0.161]
    rows = fly({"wind_force": wind, "gust": ([0.301, 0.240, 0.0], 0.3348)}, duration=60.0, rate_hz=100.0, seed=7943,
               **OPEN)
    found = _discover(write(rows, tmp_path / "gust_wind.csv", seed=7943, wall=False))
    assert found.names_ == ["constant_force"]
    assert max(relative_errors(found.effects_[0].values, {"F": wind})) < 0.03


def test_a_ceiling_flown_nearer_than_its_form_is_trusted_is_fitted_beyond_that(tmp_path):
    """Moving briskly between waypoints, the survey dips its rotors to 2-3 cm under the ceiling: inside 0.6 of the
    radius, where this simulator's gain levels off (the library's levels off at half of it). Fitted on those samples
    too, the radius came out 7-13 % large with a spurious distance offset (seeds 7721, 7725, 7728, 7747). The
    radius now comes from the samples whose rotors stay one effective radius away; the others are still scored, and
    the report says what was set aside and where the residual is left."""
    from discovery.report import format_summary
    from tests.independent_cases import CEILING

    radius = 0.085
    rows = fly({"ceiling": (radius, 0.0)}, duration=60.0, rate_hz=100.0, seed=387, waypoints=2.0, **CEILING)
    found = _discover(write(rows, tmp_path / "ceiling.csv", seed=387, wall=False, ceiling=True))
    assert found.names_ == ["ceiling_effect"]
    summary = found.form_range_
    assert summary["applied"] and 0.1 < summary["share_set_aside"] < 0.7
    assert 0.0 < summary["closest_m"] < 0.6 * radius  # inside the range where this simulator's gain levels off
    assert summary["on_all"]["ceiling_effect"]["radius"] > 1.05 * radius  # what those samples would have done
    assert found.effects_[0].values["radius"] == pytest.approx(radius, rel=0.04)
    text = format_summary(found.report())
    assert "ceiling_effect fitted without the samples nearer the ceiling than its form is trusted" in text
    assert found.unexplained_["where"]["regressor"] == "distance to ceiling"  # what the form leaves near it
    assert found.unexplained_["where"]["range"][0] < 0.6 * radius


def test_a_thrust_scale_that_widens_the_ceilings_untrusted_range_goes_once_the_ceiling_is_fitted_alone(
        tmp_path, monkeypatch):
    """A 1.5 kg vehicle moves briskly 5-15 cm under a ceiling (radius 0.10 m, offset 1.2 cm) whose gain levels off at
    0.6 radii. A thrust scale of 0.96 beside it let the radius reach 0.24 m and the offset 9.7 cm; from that radius
    most of the flight lay nearer than the form is trusted, so the fit on all of it was kept and written (seed 7944
    of the second simulator's wide draws, flown between waypoints). The range is now also taken from the ceiling
    effect fitted alone; within it the thrust scale does not pay and goes."""
    import tests.independent_sim as sim
    from tests.independent_cases import CEILING_CLOSE

    monkeypatch.setattr(sim, "MASS", 1.5)
    truth = {"radius": 0.1006, "offset": 0.012}
    rows = fly({"ceiling": (truth["radius"], truth["offset"])}, duration=120.0, rate_hz=100.0, seed=7944,
               waypoints=2.2, **CEILING_CLOSE)
    found = _discover(write(rows, tmp_path / "ceiling.csv", seed=7944, wall=False, ceiling=True))
    assert found.names_ == ["ceiling_effect"]
    summary = found.form_range_
    assert summary["applied"] and summary["on_all"]["ceiling_effect"]["radius"] > 2.0 * truth["radius"]
    assert summary["changed"][0]["from"] == ["ceiling_effect[distance_offset]", "thrust_scale"]
    assert found.effects_[0].values["radius"] == pytest.approx(truth["radius"], rel=0.03)
    assert found.effects_[0].values["offset"] == pytest.approx(truth["offset"], rel=0.15)


def test_a_vehicle_drawn_onto_the_ceiling_is_left_out_as_held_at_the_ceiling_not_as_ground_contact(tmp_path,
                                                                                                    monkeypatch):
    """Where the image-rotor gain levels off only at 0.3 radii (up to 3.3 times the thrust), a survey 8 cm under the
    ceiling is drawn up onto it again and again and hangs there on less than half its weight. That was reported as
    "held up" and, for 29 s of the 60, as "ground contact" (the stretch next to a rest was extended for as long as
    the vehicle stayed no *higher* than it hung, so the whole way down): the ceiling radius came out 8.8 % small and
    its distance offset was not found. Those stretches are now held at the ceiling, extended only while the vehicle
    stays within 3 cm below where it hung, and the note names the ceiling."""
    import tests.independent_sim as sim
    from tests.independent_cases import CEILING_CLOSE

    monkeypatch.setattr(sim, "GAIN_FLOOR_RADII", 0.3)
    radius = 0.08
    rows = fly({"ceiling": (radius, 0.012)}, duration=60.0, rate_hz=100.0, seed=391, waypoints=2.0,
               **{**CEILING_CLOSE, "centre": (1.5, 0.0, sim.CEILING_Z - 0.08)})
    found = _discover(write(rows, tmp_path / "hang.csv", seed=391, wall=False, ceiling=True))
    assert {x["reason"] for x in found.left_out_} == {"held at the ceiling"}
    held = sum(x["seconds"] for x in found.left_out_)
    assert 14.0 < held < 25.0  # 14.2 s hanging and 3.8 s next to it; before, 43 s in all
    note = next(n for n in found.notes_ if "held at the ceiling" in n)
    assert "past the ceiling plane" in note  # this simulator lets a rotor through the ceiling: the note says so
    assert found.names_ == ["ceiling_effect"]
    assert found.effects_[0].values["radius"] == pytest.approx(radius, rel=0.04)


def test_a_flight_that_stays_nearer_the_ground_than_the_form_is_trusted_keeps_the_fit_on_all_of_it(tmp_path):
    """Hovering 3-7 cm over the ground, nearly every sample has a rotor within one effective radius of it: nothing
    would be left to fit on, so the fit on everything is kept and the report names it as a limit, with the
    parameters that rest on how the form levels off there."""
    rows = fly({"ground": (0.08, 0.0)}, centre=(1.5, 0.0, 0.07), amplitude=(0.6, 0.6, 0.02),
               period=(7.0, 9.0, 5.0), duration=60.0, rate_hz=100.0, seed=388)
    found = _discover(write(rows, tmp_path / "ground.csv", seed=388, wall=False))
    assert "ground_effect" in found.names_
    summary = found.form_range_
    assert not summary["applied"] and summary["share_set_aside"] > 0.7
    limit = next(x for x in found.limits_ if x["effects"] == ["ground_effect"])
    assert "the fit on all of it is kept" in limit["reason"]
    assert "ground_effect radius rests on that guess" in limit["reason"]  # the parameters that guess sets


def _hold(flight: dict, share: float = 0.15) -> dict:
    """``flight`` with every amplitude scaled by ``share``: a hold with little excitation."""
    return {**flight, "amplitude": tuple(share * a for a in flight["amplitude"])}


def test_a_hold_against_a_force_growing_with_height_writes_no_thrust_map(tmp_path):
    """Holding near 1.2 m (the thrust varying by 0.5 %) against a force growing with height, an affine thrust map of
    scale 1.50 with a -7.6 N offset was written: the loop's small thrust changes answer that force, and the map fitted
    it through them. In a hold the map is not fitted, and the report says why."""
    from tests.independent_cases import TALL

    rows = fly({"height_force": 0.6}, duration=60.0, rate_hz=100.0, seed=389, **_hold(TALL))
    found = _discover(write(rows, tmp_path / "height.csv", seed=389, wall=False))
    assert not any(e.name == "thrust_scale" and "offset" in e.values for e in found.effects_)
    limit = next(x for x in found.limits_ if x["effects"] == ["thrust_scale[affine]"])
    assert "a hold" in limit["reason"] and "climb and descend briskly" in limit["manoeuvre"]


def test_a_hover_whose_thrust_varies_by_two_percent_still_determines_a_thrust_map(tmp_path):
    """Away from surfaces, the thrust varying by 2 % as the hover answers random forces, the map is fitted."""
    from tests.independent_cases import OPEN

    rows = fly({"thrust_scale": 0.91, "thrust_offset": -1.2}, duration=60.0, rate_hz=100.0, seed=390,
               **_hold(OPEN))
    found = _discover(write(rows, tmp_path / "map.csv", seed=390, wall=False))
    assert found.names_ == ["thrust_scale"]
    values = found.effects_[0].values
    assert values["scale"][0] == pytest.approx(0.91, rel=0.05) and values["offset"][0] == pytest.approx(-1.2, rel=0.1)


def test_a_vehicle_yawing_beside_the_wall_with_rotors_on_its_axes_gives_suction_and_body_drag(tmp_path, monkeypatch):
    """The heading swings 60 degrees either way (the other logs hold it at 0), so the rotor nearest the wall changes
    and the body's drag axes turn against the world's: per-rotor suction and body-frame drag must both be followed."""
    import tests.independent_sim as sim

    monkeypatch.setattr(sim, "ROTORS_BODY", sim.rotor_layout(0.125, plus=True))
    monkeypatch.setattr(sim, "YAW_SWING", (np.radians(60.0), 23.0))
    truth = {"suction": (5.5, 0.125), "linear_drag": [0.15, 0.4, 0.3]}
    # the rotor nearest the wall comes as near it as on the other wall logs: 9 cm short of the centre at 45 degrees
    centre = (0.25 + sim.reach_toward_wall() - 0.125 / np.sqrt(2.0), 0.0, 1.0)
    rows = fly(truth, centre=centre, amplitude=(0.09, 0.5, 0.25), period=(7.0, 9.0, 3.0), duration=60.0,
               rate_hz=100.0, seed=21, gains=NEAR_WALL)
    yaw = [np.degrees(np.arctan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2)))
           for _, _, _, q, *_ in rows]
    assert min(yaw) < -55.0 and max(yaw) > 55.0
    found = _discover(write(rows, tmp_path / "yawing.csv", seed=21))
    assert sorted(found.names_) == ["linear_drag", "wall_suction"]
    fitted = {f.name: f.values for f in found.effects_}
    assert max(relative_errors(fitted["wall_suction"], {"k_s": 5.5, "d_thr": 0.125})) < 0.05
    # the body's x axis sees the wall's slow in-and-out and, turned, some of the sweep along it: D[0] is known to
    # +-0.01 N s/m (at a held heading, +-0.02), so each entry is checked against its own standard error
    drag_std = next(std for f, std in zip(found.effects_, found.param_std_) if f.name == "linear_drag")["D"]
    assert np.all(np.abs(fitted["linear_drag"]["D"] - truth["linear_drag"]) < 3.0 * np.asarray(drag_std))
    assert max(relative_errors(fitted["linear_drag"], {"D": truth["linear_drag"]})[1:]) < 0.05


def test_a_wall_suction_too_weak_to_find_is_bounded_by_the_pull_the_flight_could_hide(tmp_path, monkeypatch):
    """Measurement noise four times the usual. Flown without suction, the report bounds what could hide by 0.02 N
    of pull on a rotor at its closest approach; a suction pulling 0.036 N there (k_s 1 N/m, d_thr 0.1 m) is not
    found either, and its bound holds that pull."""
    import tests.independent_sim as sim

    monkeypatch.setattr(sim, "NOISE_SCALE", 4.0)

    def flown(truth: dict, seed: int) -> tuple[Discovery, float]:
        rows = fly(truth, centre=(0.25, 0.0, 1.0), amplitude=(0.09, 0.5, 0.25), period=(7.0, 9.0, 3.0),
                   duration=60.0, rate_hz=100.0, seed=seed, gains=NEAR_WALL)
        closest = min(min((np.asarray(p) + sim._R(np.asarray(q)) @ r)[0] for r in sim.ROTORS_BODY)
                      for _, p, _, q, *_ in rows)
        return _discover(write(rows, tmp_path / f"wall_{seed}.csv", seed=seed)), closest

    def bound(found: Discovery) -> float:
        (limit,) = [x for x in found.limits_ if x["effects"] == ["wall_suction"] and "bound_N" in x]
        return limit["bound_N"]

    clean, _ = flown({}, 31)
    assert clean.names_ == [] and 0.0 < bound(clean) < 0.02
    weak, closest = flown({"suction": (1.0, 0.1)}, 33)
    pull = 1.0 * (0.1 - closest)
    assert weak.names_ == [] and 0.03 < pull < bound(weak) < 2 * pull


def test_a_turbulent_wind_lasting_seconds_is_not_written_as_a_thrust_scale(tmp_path):
    """A zero-mean turbulent wind whose force lasts about 2 s, on a brisk 50 Hz waypoint flight: by chance its vertical
    part follows the climbs and descents for a minute, and a thrust scale of 0.987 took 8 % of the held-out gap. Its
    standard error summed the residual's correlation over two smoothing windows (0.6 s) only, so 0.0043 put 1 far
    outside its interval and the scale was written as physics (seed 7951 of the second simulator). What the fit leaves
    is still correlated a window apart here, so the sum now runs over the wind's seconds: the interval reaches 1 and
    nothing is written, and the report says the force left lives in time."""
    from tests.independent_cases import OPEN
    from tests.independent_sim import turbulence

    wind = turbulence([0.442, 0.385, 0.342], 2.0, 90.0, 7958)
    rows = fly({"turbulence": wind}, duration=60.0, rate_hz=50.0, seed=7951, waypoints=1.7, **OPEN)
    found = _discover(write(rows, tmp_path / "turbulence.csv", seed=7951, wall=False))
    assert found.names_ == []
    scale = [c for c in found.undetermined_ if c["effect"] == "thrust_scale"]
    assert scale and 0.98 < scale[0]["value"] < 0.995
    assert scale[0]["value"] - 1.96 * scale[0]["std"] < 1.0 < scale[0]["value"] + 1.96 * scale[0]["std"]
    assert found.unexplained_["lives_in"].startswith("time")


def test_a_ground_effect_left_out_beside_a_thrust_scale_is_taken_in_where_its_form_is_trusted(tmp_path, monkeypatch):
    """Flown 8-18 cm over the ground by a simulator whose gain levels off at 0.9 of the 0.106 m radius (the library's
    at half of it), the gain is flat over the lower part of the flight: on every sample a thrust scale of 1.054 was
    chosen first, the ground effect beside it ran to its 0.5 m bound and was left out, and the thrust scale was
    written (seed 7957 of the second simulator). The ground effect is now fitted alone within the range its form is
    trusted, where it is determined and scores better than the thrust scale, which no longer pays there."""
    import tests.independent_sim as sim
    from discovery.report import format_summary
    from tests.independent_cases import GROUND

    monkeypatch.setattr(sim, "GAIN_FLOOR_RADII", 0.9)
    radius = 0.10587
    rows = fly({"ground": (radius, 0.0)}, duration=60.0, rate_hz=100.0, seed=7957, **GROUND)
    found = _discover(write(rows, tmp_path / "ground.csv", seed=7957, wall=False))
    assert found.names_ == ["ground_effect"]
    assert found.effects_[0].values["radius"] == pytest.approx(radius, rel=0.01)
    summary = found.form_range_
    assert summary["added"] == "ground_effect" and summary["applied"]
    assert summary["on_all"]["ground_effect"]["radius"] < 0.97 * radius  # alone on every sample, the flat gain bends it
    assert 0.2 < summary["share_set_aside"] < 0.6
    assert not found.undetermined_  # what was said of it when it was left out is gone
    text = format_summary(found.report())
    assert "ground_effect added where its form is trusted" in text
    assert found.unexplained_["where"]["regressor"] == "height above ground"  # what the form leaves nearer


def test_a_thrust_scale_that_explains_nothing_material_within_the_trusted_range_is_left_out_and_the_leak_counted(
        tmp_path, monkeypatch):
    """Flown 2-15 cm under a ceiling whose gain levels off at 0.8 of its 0.078 m radius (the library's at half of
    it), the fit on every sample chose a thrust scale beside the ceiling effect: it paid for the form's error on the
    samples nearer than one radius. Within the trusted range it still scored a little better, by bending the ceiling
    effect (radius 0.091 m, offset 25 mm for 12 mm), while explaining 0.004 N rms, 0.03 % of the weight: the thrust
    scale was written (seed 7958 of the second simulator, 1.4 kg, noise x1.4, yaw swinging 50 degrees, its world
    turned). Selection's test of a material share and force, asked again within the range, leaves it out.

    The offset then comes out 14.4 mm, 20 % large, at a standard error of 0.5 mm: the rows fitted on carry, through
    the smoothing of their force, what the form leaves on the samples just inside the range. Taken out, the offset
    moves toward 12 mm by about 3 mm; counted in its standard error, the offset is said loose."""
    import math

    import tests.independent_sim as sim
    from discovery.report import format_summary
    from tests.independent_cases import CEILING_CLOSE

    monkeypatch.setattr(sim, "GAIN_FLOOR_RADII", 0.8)
    monkeypatch.setattr(sim, "MASS", 1.4)
    monkeypatch.setattr(sim, "NOISE_SCALE", 1.4)
    monkeypatch.setattr(sim, "YAW_SWING", (math.radians(50.0), 7.0))
    monkeypatch.setattr(sim, "WORLD_TURN", math.radians(210.0))
    monkeypatch.setattr(sim, "WORLD_SHIFT", (0.4, -0.3))
    radius = 0.0777268
    rows = fly({"ceiling": (radius, 0.012)}, duration=360.0, rate_hz=50.0, seed=7958, waypoints=1.9,
               **CEILING_CLOSE)
    found = _discover(write(rows, tmp_path / "ceiling.csv", seed=7958, wall=False, ceiling=True))
    assert found.names_ == ["ceiling_effect"]
    assert found.effects_[0].values["radius"] == pytest.approx(radius, rel=0.03)
    changed = found.form_range_["changed"]
    assert any("thrust_scale" in c["from"] and "thrust_scale" not in c["to"] and c.get("immaterial") for c in changed)
    report = found.report()
    assert "thrust_scale explains less than 2 % of the force gap" in format_summary(report)
    offset, std = found.effects_[0].values["offset"], found.param_std_[0]["offset"]
    assert offset > 1.15 * 0.012  # the leak bends it
    shift = found.form_range_["leakage_shift"]["ceiling_effect"]["offset"]
    assert -0.006 < shift < -0.0015  # taken out, it moves toward the 12 mm flown
    assert abs(shift) < std < abs(shift) + 0.001  # counted beside the fit's own error (about 0.5 mm), in quadrature
    assert ("ceiling_effect", "offset") in {(x["effect"], x["parameter"]) for x in report["loose"]}


def test_a_distance_offset_whose_form_describes_the_samples_set_aside_is_kept_within_the_trusted_range(
        tmp_path, monkeypatch):
    """Flown 4.6 cm to about 14 cm over the ground by a 0.7 kg vehicle with 0.15 m arms, whose gain levels off at 0.55 of its
    0.084 m radius (the library's at half of it) behind a 12 mm distance offset (seed 7966 of the second simulator,
    noise x1.5, an accelerometer, its world turned and shifted): fitted on every sample the offset form is right
    (radius 0.084 m, offset 12.2 mm), but within the trusted range (54 % of the flight) the plain form scored better
    by less than the offset's price, and it was written with its radius 11 % small at a standard error of 1 %.

    The offset form fitted on every sample predicts the samples set aside as well as the rest (their vertical mean
    square 0.98 times): it was not chosen for their sake, so within the range its form stays. The offset is pinned
    only loosely there, and said so."""
    import math

    import tests.independent_sim as sim
    from discovery.report import format_summary
    from tests.independent_cases import GROUND_CLOSE

    monkeypatch.setattr(sim, "GAIN_FLOOR_RADII", 0.55)
    monkeypatch.setattr(sim, "MASS", 0.7)
    monkeypatch.setattr(sim, "NOISE_SCALE", 1.5)
    monkeypatch.setattr(sim, "ROTORS_BODY", sim.rotor_layout(0.15))
    monkeypatch.setattr(sim, "ACCELEROMETER", True)
    monkeypatch.setattr(sim, "WORLD_TURN", math.radians(300.0))
    monkeypatch.setattr(sim, "WORLD_SHIFT", (1.2, -0.4))
    radius = 0.0837083
    rows = fly({"ground": (radius, 0.012)}, duration=360.0, rate_hz=50.0, seed=7966, waypoints=1.3, **GROUND_CLOSE)
    found = _discover(write(rows, tmp_path / "ground.csv", seed=7966, wall=False))
    assert found.names_ == ["ground_effect"]
    values = found.effects_[0].values
    assert "offset" in values  # the plain form was written before
    assert values["radius"] == pytest.approx(radius, rel=0.05)
    misfit = found.form_range_["set_aside_misfit"]
    assert misfit["forms_kept"] and 0.8 < misfit["ratio"] < 1.2 < misfit["limit"]
    assert found.form_range_["changed"] == []
    report = found.report()
    assert ("ground_effect", "offset") in {(x["effect"], x["parameter"]) for x in report["loose"]}
    assert "the gain levels off there as the form says" in format_summary(report)


def test_a_thrust_scale_beside_a_ground_effect_flown_mostly_nearer_than_its_form_is_trusted_goes(tmp_path,
                                                                                                 monkeypatch):
    """A 1.3 kg vehicle with 0.16 m arms flies 2.5-14 cm over a ground whose gain levels off at 0.6 of its 0.110 m
    radius behind a 12 mm distance offset (seed 7986 of the second simulator, noise x1.3, its world turned and
    shifted). On every sample a thrust scale of 0.928 let the ground effect take a radius of 0.293 m and an offset of
    0.110 m; from that radius the whole flight lay nearer than the form is trusted. Fitted alone, the ground effect's
    range still set aside 81 % of the flight, more than the 70 % a refit was allowed to set aside, so the fit on
    every sample, thrust scale and all, was written. Within the ground effect's own range (21 % of the flight, 76 s)
    the parameters are determined and the thrust scale does not pay."""
    import math

    import tests.independent_sim as sim
    from tests.independent_cases import GROUND_CLOSE

    monkeypatch.setattr(sim, "GAIN_FLOOR_RADII", 0.6)
    monkeypatch.setattr(sim, "MASS", 1.3)
    monkeypatch.setattr(sim, "NOISE_SCALE", 1.3)
    monkeypatch.setattr(sim, "ROTORS_BODY", sim.rotor_layout(0.16))
    monkeypatch.setattr(sim, "WORLD_TURN", math.radians(275.0))
    monkeypatch.setattr(sim, "WORLD_SHIFT", (-2.0, 0.5))
    truth = {"radius": 0.1096648, "offset": 0.012}
    rows = fly({"ground": (truth["radius"], truth["offset"])}, duration=360.0, rate_hz=50.0, seed=7986,
               waypoints=2.0, **GROUND_CLOSE)
    found = _discover(write(rows, tmp_path / "ground.csv", seed=7986, wall=False))
    assert found.names_ == ["ground_effect"]
    summary = found.form_range_
    assert summary["applied"] and 0.7 < summary["share_set_aside"] < 0.85
    assert summary["on_all"]["ground_effect"]["radius"] > 2.0 * truth["radius"]  # what the thrust scale allowed
    assert summary["changed"][0]["from"] == ["ground_effect[distance_offset]", "thrust_scale"]
    assert found.effects_[0].values["radius"] == pytest.approx(truth["radius"], rel=0.03)
    assert found.effects_[0].values["offset"] == pytest.approx(truth["offset"], rel=0.1)


def test_no_ground_effect_is_fitted_far_from_the_ground_so_a_thrust_map_standing_in_for_height_is_asked(
        tmp_path, monkeypatch):
    """A 2 kg vehicle (rotors in a plus, noise x1.8, an accelerometer) flies up and down between 0.7 m and 1.7 m
    against a force growing with height, outside the library (seed 7990 of the second simulator). An affine thrust
    map, a vertical steady force and a ground effect of radius 0.42 m were written, leaving 1.2 times the noise
    floor; the report said at the same time that the rotors never came closer than 0.68 m to the ground, so the
    flight could not determine a ground effect. Written, that ground effect made the height the model's own
    quantity, and the map was never asked whether it stood in for a force of the height. Not fitted, the map and
    the steady force are found to stand in for it, and the residual is said to depend on the height."""
    import tests.independent_sim as sim
    from tests.independent_cases import TALL

    monkeypatch.setattr(sim, "MASS", 2.0)
    monkeypatch.setattr(sim, "NOISE_SCALE", 1.8)
    monkeypatch.setattr(sim, "ROTORS_BODY", sim.rotor_layout(sim.ROTOR_RADIUS, plus=True))
    monkeypatch.setattr(sim, "ACCELEROMETER", True)
    rows = fly({"height_force": 0.81402}, duration=60.0, rate_hz=100.0, seed=7990, **TALL)
    path = write(rows, tmp_path / "height.csv", seed=7990, wall=False)
    found = _discover(path)
    assert found.names_ == []
    assert {s["effect"] for s in found.stand_ins_} >= {"thrust_scale"}
    assert found.unexplained_["where"]["regressor"] == "height above ground"
    limit = next(x for x in found.limits_ if x["effects"] == ["ground_effect"])
    assert limit["reason"].startswith("the rotors never came closer than 0.6") and "not fitted" in limit["reason"]
    # asked for by name, it is fitted all the same, and the limit does not say otherwise
    asked = Discovery(effect="ground_effect").fit([read_log(path)])
    limit = next(x for x in asked.limits_ if x["effects"] == ["ground_effect"])
    assert limit["reason"].startswith("the rotors never came closer than 0.6") and "not fitted" not in limit["reason"]
