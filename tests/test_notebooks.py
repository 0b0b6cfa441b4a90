"""Every notebook runs top to bottom (fast setting) without an error, on a copy."""

from __future__ import annotations

import time

import pytest

from wall_inspector.notebooks import NOTEBOOK_DIR, execute

NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))


def test_the_notebooks_exist():
    assert [p.name for p in NOTEBOOKS] == [
        "01_wall_suction.ipynb", "02_controllers_vs_ppo.ipynb", "03_discover_missing_effect.ipynb",
        "04_learning_the_wall.ipynb", "05_structures.ipynb",
    ]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_top_to_bottom(path):
    before = path.read_bytes()
    start = time.perf_counter()
    notebook = execute(path, fast=True, timeout=300)
    print(f"{path.name}: {time.perf_counter() - start:.0f} s")
    errors = [o for c in notebook.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors
    images = [o for c in notebook.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if "image/png" in o.get("data", {})]
    assert images, "each notebook shows at least one figure"
    assert path.read_bytes() == before  # the committed notebook is not modified by running it
