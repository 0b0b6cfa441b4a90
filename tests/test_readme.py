"""The readme command puts command-written tables between markers, and tabulates model cards."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from wall_inspector.cli import main
from wall_inspector.readme import agents_table, replace_block


def test_a_block_is_replaced_and_the_rest_kept():
    text = "intro\n<!-- BEGIN speed -->\nold\n<!-- END speed -->\noutro\n"
    assert replace_block(text, "speed", "| a |\n") == "intro\n<!-- BEGIN speed -->\n| a |\n<!-- END speed -->\noutro\n"
    with pytest.raises(ValueError, match="README has no block '<!-- BEGIN other -->'"):
        replace_block(text, "other", "x")


def test_the_command_copies_a_file_into_the_readme(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("<!-- BEGIN bench-env -->\nplaceholder\n<!-- END bench-env -->\n")
    table = tmp_path / "bench.md"
    table.write_text("| env | steps/s |\n|---|---|\n| x | 10 |\n")
    assert main(["readme", "--readme", str(readme), "--set", f"bench-env={table}"]) == 0
    assert readme.read_text() == "<!-- BEGIN bench-env -->\n| env | steps/s |\n|---|---|\n| x | 10 |\n<!-- END bench-env -->\n"


def test_model_cards_become_one_row_each(tmp_path):
    card = {
        "env_id": "WallInspector/WallSweep-v0", "residual": None,
        "training": {"total_timesteps": 10_000_000, "total_wall_time_s": 1500.0, "steps_per_s": 6700.0,
                     "n_envs": 256, "vector": "batched", "n_workers": 0},
        "evaluation": {"seeds": list(range(10)), "metrics": {
            "completed": 1.0, "position_rmse_m": 0.031, "wall_normal_rmse_m": 0.0281, "collisions": 0}},
    }
    (tmp_path / "wall_sweep").mkdir()
    (tmp_path / "wall_sweep" / "model_card.json").write_text(json.dumps(card))
    text = agents_table(tmp_path)
    row = [line for line in text.splitlines() if "WallSweep-v0" in line][0]
    assert "| 10,000,000 | 25.0 min | 6,700 | 256 batched | 100 % | 3.10 cm | 2.81 cm | 0 |" in row
    assert "over 10 seeds" in text
    card["training"].update(n_envs=32, vector="subprocess", n_workers=2)
    (tmp_path / "wall_sweep" / "model_card.json").write_text(json.dumps(card))
    assert "| 6,700 | 32 in 2 processes | 100 % |" in agents_table(tmp_path)
    assert "warm-started" not in row
    card["training"]["warm_start"] = {"controller": "scmpc"}
    (tmp_path / "wall_sweep" / "model_card.json").write_text(json.dumps(card))
    row = [line for line in agents_table(tmp_path).splitlines() if "WallSweep-v0" in line][0]
    assert row.startswith("| [`WallSweep-v0`, warm-started from SC-MPC demonstrations](")
    # a distilled agent: a row that says so, its teacher's labelled steps as its env steps, no PPO rate
    del card["training"]["warm_start"]
    card["training"].update(total_timesteps=0, steps_per_s=0.0, teacher={"controller": "scmpc", "labels": 81_600})
    (tmp_path / "wall_sweep" / "model_card.json").write_text(json.dumps(card))
    row = [line for line in agents_table(tmp_path).splitlines() if "WallSweep-v0" in line][0]
    assert row.startswith("| [`WallSweep-v0`, distilled from SC-MPC (DAgger)](")
    assert "| 81,600 | 25.0 min | - | 32 in 2 processes |" in row


def _python_block_after(heading: str) -> str:
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = text[text.index(heading):]
    start = section.index("```python\n") + len("```python\n")
    return section[start:section.index("```", start)]


def test_the_readme_controller_snippet_flies_every_episode_without_contact():
    # run exactly as printed: SC-MPC (its default, tuned preset) through SB3's evaluate_policy on 4 envs
    namespace: dict = {}
    exec(compile(_python_block_after("### Controllers, with Stable-Baselines3's tools"), "README.md", "exec"), namespace)
    assert namespace["lengths"] == [1700, 1700, 1700, 1700]  # a collision would end an episode early
    assert namespace["policy"].failures == 0
    assert namespace["result"].metrics()["episodes"] == 5
