"""The readme command puts command-written tables between markers, and tabulates model cards."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from tests.docs_pages import block_under
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


def test_the_documented_controller_snippet_flies_every_episode_without_contact():
    # run exactly as printed: SC-MPC (its default, tuned preset) through SB3's evaluate_policy on 4 envs
    namespace: dict = {}
    block = block_under("With Stable-Baselines3's tools", "python")  # docs/guide/controllers.md
    exec(compile(block.code, str(block.page), "exec"), namespace)
    assert namespace["lengths"] == [1700, 1700, 1700, 1700]  # a collision would end an episode early
    assert namespace["policy"].failures == 0
    assert namespace["result"].metrics()["episodes"] == 5


ROBUSTNESS_MD = """Grid note.

| world | PID | SC-MPC |
|---|---:|---:|
| nominal | 0.50 | 0.07 |

Checks, as measured by this run:

- pass: SC-MPC below PID in every world (measured 0.14)
- FAIL: PID has no contact (measured 3)

The whole grid (1 cells of 5 flights) took 0.1 min.
"""


def _site(tmp_path: Path) -> tuple[Path, Path]:
    """A README and a docs/ folder beside it, as the repository lays them out."""
    readme = tmp_path / "README.md"
    readme.write_text("# x\n<!-- BEGIN agents -->\nold\n<!-- END agents -->\n"
                      "<!-- BEGIN robustness-headline -->\nold\n<!-- END robustness-headline -->\n")
    page = tmp_path / "docs" / "results" / "robustness.md"
    page.parent.mkdir(parents=True)
    page.write_text("# R\n<!-- BEGIN robustness -->\nplaceholder\n<!-- END robustness -->\ntext after\n")
    return readme, page


def test_a_block_is_filled_in_the_docs_page_that_holds_it_with_its_figure_and_the_readme_headline(tmp_path):
    readme, page = _site(tmp_path)
    out = tmp_path / "out" / "robustness"
    out.mkdir(parents=True)
    (out / "robustness.md").write_text(ROBUSTNESS_MD)
    (out / "robustness.png").write_bytes(b"\x89PNG picture")
    assert main(["readme", "--readme", str(readme), "--set", f"robustness={out / 'robustness.md'}"]) == 0
    text = page.read_text()
    block = text[text.index("<!-- BEGIN robustness -->"):text.index("<!-- END robustness -->")]
    assert ROBUSTNESS_MD.strip() in block and "placeholder" not in block and text.endswith("text after\n")
    # the heat map beside the table goes into docs/ under the block's name, linked from the page
    assert (tmp_path / "docs" / "robustness.png").read_bytes() == b"\x89PNG picture"
    assert block.rstrip().endswith("(../robustness.png)")
    # the README's headline is the checks list cut from the same table, nothing else
    headline = readme.read_text().split("<!-- BEGIN robustness-headline -->\n")[1].split("<!-- END")[0]
    assert headline == ("Checks, as measured by this run:\n\n- pass: SC-MPC below PID in every world (measured 0.14)\n"
                        "- FAIL: PID has no contact (measured 3)\n")
    assert "<!-- BEGIN agents -->\nold\n" in readme.read_text()  # blocks not asked for stay


def test_links_are_rewritten_for_the_page_a_block_lands_in(tmp_path):
    readme, _ = _site(tmp_path)
    page = tmp_path / "docs" / "results" / "agents.md"
    page.write_text("<!-- BEGIN agents -->\n<!-- END agents -->\n")
    table = tmp_path / "agents.md"
    table.write_text("| [card](agents/pretrained/a/model_card.md) | [site](https://example.org/x) | [here](#top) |\n")
    assert main(["readme", "--readme", str(readme), "--set", f"agents={table}"]) == 0
    assert "| [card](agents/pretrained/a/model_card.md) |" in readme.read_text()  # the README is at the root
    assert "| [card](../../agents/pretrained/a/model_card.md) | [site](https://example.org/x) | [here](#top) |" \
        in page.read_text()


def test_a_headline_that_cannot_be_cut_stops_the_command_before_anything_is_written(tmp_path, capsys):
    readme, page = _site(tmp_path)
    before = readme.read_text(), page.read_text()
    table = tmp_path / "robustness.md"
    table.write_text("| a |\n|---|\n| 1 |\n")  # no checks to cut the README's headline from
    assert main(["readme", "--readme", str(readme), "--set", f"robustness={table}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "has no paragraph starting 'Checks, as measured by this run:'" in err
    assert "robustness-headline" in err
    assert (readme.read_text(), page.read_text()) == before


def test_the_repositorys_headlines_match_the_tables_they_are_cut_from():
    """Every cut block of the README and the docs holds what the readme command would cut from its
    source block now: a headline never disagrees with the full table."""
    from tests.docs_pages import ROOT
    from wall_inspector.readme_pages import DERIVED

    texts = [(ROOT / "README.md").read_text()] + [p.read_text() for p in sorted((ROOT / "docs").rglob("*.md"))]

    def content(name: str) -> list[str]:
        return [m for text in texts for m in re.findall(rf"<!-- BEGIN {re.escape(name)} -->\n(.*?)<!-- END", text, re.S)]

    checked = 0
    for derived, (source, cut) in DERIVED.items():
        for part in content(derived):
            (full,) = content(source)
            if full.startswith("(") and part.startswith("("):  # both still the placeholder the lead fills
                continue
            assert part == cut(full), derived
            checked += 1
    assert checked >= 3  # compare-headline, compare-budget, compare-paper-sim-budget


def test_the_repositorys_robustness_blocks_take_the_robustness_command_output(tmp_path):
    """``wall-inspector readme --set robustness=OUT/robustness.md`` on the repository's README and docs
    fills the results page (with the heat map) and the README's headline."""
    import shutil

    from tests.docs_pages import ROOT

    shutil.copy(ROOT / "README.md", tmp_path / "README.md")
    shutil.copytree(ROOT / "docs", tmp_path / "docs", ignore=shutil.ignore_patterns("*.png"))
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "robustness.md").write_text(ROBUSTNESS_MD)
    (tmp_path / "out" / "robustness.png").write_bytes(b"png")
    assert main(["readme", "--readme", str(tmp_path / "README.md"), "--set",
                 f"robustness={tmp_path / 'out' / 'robustness.md'}"]) == 0
    assert "- FAIL: PID has no contact (measured 3)" in (tmp_path / "README.md").read_text()
    results = (tmp_path / "docs" / "results" / "robustness.md").read_text()
    assert "| nominal | 0.50 | 0.07 |" in results and "(../robustness.png)" in results
    assert (tmp_path / "docs" / "robustness.png").is_file()
