"""wall-inspector tune end to end on a tiny budget: study, resume after an interrupt, preset and provenance."""

from __future__ import annotations

import json

import optuna
import pytest

from controllers.presets import load_preset
from controllers.tuning import flight_cost
from controllers.tuning.objective import TrackingObjective, condition_flight_cost
from controllers.tuning.space import PID_RANGES, SearchSpace
from wall_inspector.cli import main
from wall_inspector.tune import parse_seeds, recorded_command

TINY = ["--env", "WallHover-v0", "--seeds", "1", "--heldout-seeds", "2", "--set", "duration=0.5", "--set",
        "standoff=0.3", "--no-progress"]


def _trials(run_dir):
    study = optuna.load_study(study_name="tune", storage=f"sqlite:///{run_dir / 'study.db'}")
    return study.trials


def test_tune_a_tiny_budget_writes_a_preset_with_provenance(tmp_path, capsys):
    out = tmp_path / "pid"
    assert main(["tune", "--method", "pid", "--budget-trials", "3", "--out", str(out), *TINY]) == 0
    trials = _trials(out)
    assert [t.state.name for t in trials] == ["COMPLETE"] * 3
    # the first trial is the authors' gains
    assert trials[0].params["kp_xy"] == 8.0 and trials[0].params["k_attitude_z"] == 4.0
    preset = load_preset(out / "preset.yaml", method="pid")
    p = preset.provenance
    assert p["train_seeds"] == [1] and p["heldout_seeds"] == [2] and p["budget"]["trials"] == 3
    assert p["used"]["trials"] == 3 and p["used"]["env_steps"] == 3 * 50
    assert p["objective"]["train_value"] == pytest.approx(min(t.value for t in trials))
    assert "0.05 cm per contact step" in p["objective"]["definition"]
    assert p["command"].startswith("wall-inspector tune") and p["task"] == "WallInspector/WallHover-v0"
    best = min(trials, key=lambda t: t.value)
    assert preset.methods["pid"]["kp"] == pytest.approx([best.params["kp_xy"]] * 2 + [best.params["kp_z"]])
    report = json.loads((out / "report.json").read_text())
    assert len(report["trials"]) == 3 and report["heldout"]["flights"][0]["seed"] == 2
    assert "held-out seeds 2..2" in capsys.readouterr().out


def test_an_interrupted_study_resumes_to_the_same_budget(tmp_path, monkeypatch, capsys):
    out = tmp_path / "mpc"
    real = TrackingObjective.evaluate
    calls = {"n": 0}

    def interrupt_on_second(self, settings, seeds=None, report=None):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(self, settings, seeds, report)

    monkeypatch.setattr(TrackingObjective, "evaluate", interrupt_on_second)
    args = ["tune", "--method", "mpc", "--budget-trials", "3", "--out", str(out), *TINY]
    assert main(args) == 130
    assert "run the same command again to resume" in capsys.readouterr().err
    assert [t.state.name for t in _trials(out)] == ["COMPLETE", "FAIL"]
    monkeypatch.setattr(TrackingObjective, "evaluate", real)
    assert main(args) == 0
    states = [t.state.name for t in _trials(out)]
    assert states.count("COMPLETE") == 3 and len(states) == 4  # two more trials, not three
    assert load_preset(out / "preset.yaml").provenance["used"]["trials"] == 3


@pytest.mark.parametrize("args, message", [
    (["--method", "pid", "--seeds", "1-3", "--heldout-seeds", "3"], "must differ"),
    (["--method", "pid", "--budget-trials", "0"], "--budget-trials must be in"),
    (["--method", "pid", "--set", "k_s=-1"], "k_s"),
    (["--method", "pid", "--horizon-steps", "10,20"], "apply to the MPCs"),
    (["--method", "pid", "--seeds", "x"], "--seeds must be seeds"),
    (["--method", "pid", "--conditions", "windy"], "--conditions takes flight-condition profiles"),
    (["--method", "pid", "--conditions", "realistic", "--set", "conditions=realistic"], "not both"),
    (["--objective", "paper-table-i", "--conditions", "realistic"], "applies to the tracking objective"),
    ([], "--method is required"),
])
def test_bad_tune_arguments_are_one_line_and_exit_2(tmp_path, capsys, args, message):
    assert main(["tune", "--out", str(tmp_path / "x"), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()  # nothing was made before the check


def test_seed_lists_the_search_space_and_the_recorded_command():
    assert parse_seeds("1000-1002,7", "--seeds") == [1000, 1001, 1002, 7]
    assert recorded_command(["--start", "/home/me/start.yaml", "--out", "runs/x", "--set", "k_s=1 0"]) == \
        "wall-inspector tune --start start.yaml --out runs/x --set 'k_s=1 0'"
    space = SearchSpace("pid", load_preset("paper").methods["pid"])
    values = space.values_of(space.base)
    assert values == {"kp_xy": 8.0, "kp_z": 10.0, "kv_xy": 4.0, "kv_z": 6.0, "k_attitude_xy": 6.0, "k_attitude_z": 4.0}
    assert space.settings(values) == space.base
    assert set(values) == set(PID_RANGES)


def test_the_flight_cost_prices_contacts_and_effort():
    metrics = {"wall_normal_rmse": 0.004, "rmse_norm": 0.005, "collisions": 20, "body_rate_effort_rms": 0.1,
               "thrust_effort_rms": 0.5}
    # 0.3 cm RMS along the wall (a 3-4-5 triangle with the 0.4 cm wall-normal error) at a fifth
    assert flight_cost(metrics) == pytest.approx(0.4 + 0.2 * 0.3 + 0.05 * 20 + 1.0 * 0.1 + 0.2 * 0.5)
    assert flight_cost({**metrics, "wall_normal_rmse": float("nan")}) == pytest.approx(0.5 + 1.0 + 0.1 + 0.1)


def test_the_cost_of_a_flight_under_conditions_is_its_wall_distance_and_contacts():
    metrics = {"wall_normal_rmse": 0.004, "rmse_norm": 0.005, "collisions": 20, "body_rate_effort_rms": 0.1,
               "thrust_effort_rms": 0.5}
    assert condition_flight_cost(metrics) == pytest.approx(0.4 + 0.05 * 20)
    assert condition_flight_cost({**metrics, "wall_normal_rmse": float("nan")}) == pytest.approx(0.5 + 1.0)


def test_tuning_under_conditions_flies_every_seed_in_each_world_and_prices_them_so(tmp_path):
    from controllers.evaluation import evaluate
    from controllers.tuning.study import build_policy

    kwargs = {"noise": True, "terminate_on_collision": False, "duration": 0.5, "standoff": 0.3}
    objective = TrackingObjective("WallInspector/WallHover-v0", "pid", [1, 2], kwargs, build_policy,
                                  conditions=["realistic"])
    settings = load_preset("paper").methods["pid"]
    flights = objective.evaluate(settings)
    rows = flights.details["flights"]
    assert [(f["conditions"], f["seed"]) for f in rows] == [("task", 1), ("task", 2), ("realistic", 1), ("realistic", 2)]
    # each flight is the flight the env gives under those conditions, priced by its world's cost
    realistic = evaluate(lambda env: build_policy("pid", settings, env), objective.env_id, [2],
                         {**kwargs, "conditions": "realistic"}).metrics()
    ideal = evaluate(lambda env: build_policy("pid", settings, env), objective.env_id, [2], kwargs).metrics()
    assert realistic["rmse"] != ideal["rmse"]  # the conditions reached the flight
    assert rows[3]["cost_cm"] == pytest.approx(condition_flight_cost(realistic))
    assert rows[1]["cost_cm"] == pytest.approx(flight_cost(ideal))
    assert flights.value == pytest.approx(sum(f["cost_cm"] for f in rows) / 4)
    assert objective.flights_per_trial() == 4
    with pytest.raises(ValueError, match="conditions must name profiles"):
        TrackingObjective("WallInspector/WallHover-v0", "pid", [1], kwargs, build_policy, conditions=["ideal"])


def test_a_study_started_from_a_tuned_preset_counts_that_presets_budget(tmp_path):
    first = tmp_path / "first"
    assert main(["tune", "--method", "pid", "--budget-trials", "2", "--out", str(first), *TINY]) == 0
    second = tmp_path / "second"
    assert main(["tune", "--method", "pid", "--budget-trials", "2", "--conditions", "realistic",
                 "--start", str(first / "preset.yaml"), "--out", str(second), *TINY]) == 0
    one, two = load_preset(first / "preset.yaml").provenance, load_preset(second / "preset.yaml").provenance
    assert two["objective"]["conditions"] == ["realistic"] and "'realistic'" in two["objective"]["definition"]
    assert two["used"]["trials"] == 2 and two["used"]["env_steps"] == 2 * 2 * 50  # two worlds a seed
    assert two["used_with_start"]["trials"] == 4
    assert two["used_with_start"]["env_steps"] == one["used"]["env_steps"] + two["used"]["env_steps"]
    assert [start["preset"] for start in two["start"]] == ["paper", "tuned-WallHover-v0-pid"]
