"""``wall-inspector robustness``: the grid, its checks against the reference, the report, the heat map."""

from __future__ import annotations

import json

import pytest

from controllers.robustness import DEFAULT_GRID, CellResult, World, acceptance, default_methods, fly_cell, markdown_report
from wall_inspector.cli import main as cli_main


def _cell(world: World, method: str, rmse_cm: float, contacts: int = 0) -> CellResult:
    metrics = {"wall_normal_rmse": rmse_cm / 100, "collision_episodes": contacts, "episodes": 5, "collisions": contacts}
    return CellResult(world, method, metrics, [])


def test_the_grid_holds_every_world_the_issue_names():
    suction = {(w.k_s, w.d_thr) for w in DEFAULT_GRID if w.group == "suction"}
    assert suction == {(k, d) for k in (1, 2, 4.1, 8, 12) for d in (0.10, 0.132, 0.16)}
    pushes = sorted((w.push, w.label) for w in DEFAULT_GRID if w.group == "push")
    assert len(pushes) == 6 and {abs(sum(p)) for p, _ in pushes} == {0.1, 0.3, 1.0}
    assert {w.group for w in DEFAULT_GRID} == {"suction", "push", "gusts", "latency", "sensing", "motor lag",
                                               "realistic"}
    assert sum(w.nominal for w in DEFAULT_GRID) == 1
    # a push toward the wall points against the wall's outward normal (+x)
    toward = next(w for w in DEFAULT_GRID if w.label == "1 N toward the wall")
    assert toward.push == (-1.0, -0.0, -0.0) and toward.env_kwargs()["effects"]["constant_force"]["F"][0] == -1.0


def test_every_world_of_the_grid_can_key_the_results_and_the_checks_run_over_all_of_them():
    from controllers.robustness import CellResult, acceptance, markdown_report

    assert len({w: w.label for w in DEFAULT_GRID}) == len(DEFAULT_GRID) == len({w.label for w in DEFAULT_GRID})
    metrics = {"wall_normal_rmse": 0.002, "collision_episodes": 0, "episodes": 5}
    results = [CellResult(w, m, metrics, [], 0.0) for w in DEFAULT_GRID
               for m in ("MPC", "SC-MPC adaptive", "SC-MPC told the truth", "PPO")]
    checks = acceptance(results)
    assert checks and all(c["pass"] for c in checks if "0.1 cm" not in c["check"])
    assert markdown_report(results, [1], checks).count("\n| ") >= len(DEFAULT_GRID)


def test_the_checks_hold_the_adaptive_controller_and_ppo_to_the_reference():
    strong = World("suction", "k_s 12, d_thr 0.16", k_s=12.0, d_thr=0.16)
    nominal = World("suction", "k_s 4.1, d_thr 0.132")
    realistic = World("realistic", "realistic profile", conditions="realistic")
    good = [_cell(strong, "SC-MPC told the truth", 0.17), _cell(strong, "SC-MPC adaptive", 0.30),
            _cell(strong, "MPC", 2.0, 5), _cell(strong, "PPO", 0.4),
            _cell(nominal, "SC-MPC told the truth", 0.06), _cell(nominal, "SC-MPC adaptive", 0.06),
            _cell(nominal, "MPC", 0.47), _cell(nominal, "PPO", 0.35),
            _cell(realistic, "SC-MPC told the truth", 0.46), _cell(realistic, "SC-MPC adaptive", 0.3),
            _cell(realistic, "PPO", 0.9)]
    assert all(c["pass"] for c in acceptance(good))
    bad = list(good)
    bad[1] = _cell(strong, "SC-MPC adaptive", 0.31)  # above 1.5 x 0.17 + 0.05 = 0.305
    bad[3] = _cell(strong, "PPO", 0.4, 1)  # a contact where the reference has none
    bad[10] = _cell(realistic, "PPO", 1.1)
    failed = {c["check"].split(":")[0] for c in acceptance(bad) if not c["pass"]}
    assert failed == {"SC-MPC adaptive, every suction and push cell", "PPO", "PPO, realistic profile"}
    worst = next(c for c in acceptance(bad) if "1.5 x" in c["check"])
    assert worst["world"] == "k_s 12, d_thr 0.16" and worst["value"] == pytest.approx(0.005)


def test_a_cell_flies_its_seeds_as_rows_and_the_reference_is_told_the_push():
    world = World("push", "0.3 N toward the wall", push=(-0.3, 0.0, 0.0))
    methods = default_methods()
    told = fly_cell(world, methods["SC-MPC told the truth"], [4, 5], duration=2.0)
    blind = fly_cell(world, methods["SC-MPC"], [4, 5], duration=2.0)
    assert [e["seed"] for e in told.per_episode] == [4, 5] and told.metrics["episodes"] == 2
    assert told.rmse_cm < 0.5 * blind.rmse_cm  # knowing the push, it leans against it from the start
    text = markdown_report([told, blind], [4, 5], acceptance([told, blind]))
    assert "| 0.3 N toward the wall |" in text and "SC-MPC told the truth" in text


def test_the_command_writes_the_table_json_and_heat_map(tmp_path):
    out = tmp_path / "rob"
    code = cli_main(["robustness", "--groups", "realistic", "--seeds", "7,8", "--duration", "0.5", "--no-ppo",
                     "--workers", "1", "--no-progress", "--out", str(out)])
    assert code == 0
    data = json.loads((out / "robustness.json").read_text())
    methods = [c["method"] for c in data["cells"]]
    assert methods == ["PID", "MPC", "SC-MPC", "SC-MPC adaptive", "SC-MPC told the truth", "PID (authors')",
                       "MPC (authors')", "SC-MPC (authors')"]
    assert all(c["metrics"]["episodes"] == 2 for c in data["cells"]) and data["seeds"] == [7, 8]
    text = (out / "robustness.md").read_text()
    assert "The realistic profile beside the paper's real flight" in text and "| realistic profile |" in text
    assert (out / "robustness.png").stat().st_size > 10_000


def test_the_card_option_writes_the_agents_rows_into_its_model_card(tmp_path):
    import shutil

    from agents import pretrained_path

    agent = tmp_path / "agent"
    shutil.copytree(pretrained_path("WallSweep-v0"), agent)
    shipped = {p.name: p.read_bytes() for p in agent.iterdir() if not p.name.startswith("model_card")}
    code = cli_main(["robustness", "--groups", "realistic", "--seeds", "3", "--duration", "0.3", "--no-authors",
                     "--ppo", str(agent), "--card", "--workers", "1", "--no-progress", "--out", str(tmp_path / "rob")])
    assert code == 0
    grid = json.loads((tmp_path / "rob" / "robustness.json").read_text())
    ppo = next(c for c in grid["cells"] if c["method"] == "PPO")
    card = json.loads((agent / "model_card.json").read_text())
    assert card["robustness"]["seeds"] == [3]
    assert {c["check"] for c in card["robustness"]["checks"]} == {
        c["check"] for c in grid["checks"] if c["check"].startswith("PPO")}
    text = (agent / "model_card.md").read_text()
    assert "## Robustness" in text and f"| realistic profile | {100 * ppo['metrics']['wall_normal_rmse']:.2f}" in text
    assert {p.name: p.read_bytes() for p in agent.iterdir() if not p.name.startswith("model_card")} == shipped


@pytest.mark.parametrize("args, message", [
    (["--groups", "wind"], "--groups must name some of"),
    (["--seeds", "x"], "--seeds must be seeds such as"),
    (["--duration", "0"], "--duration must be in [0.05, 60] s"),
    (["--ppo", "/nonexistent/agent"], "/nonexistent/agent"),
    (["--workers", "0"], "--workers must be in [1, 256]"),
    (["--no-ppo", "--card"], "--card writes the PPO agent's results into its model card"),
])
def test_bad_options_are_one_line_usage_errors(tmp_path, capsys, args, message):
    assert cli_main(["robustness", "--out", str(tmp_path / "x"), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "x").exists()
