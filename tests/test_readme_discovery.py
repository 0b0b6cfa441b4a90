"""The discovery commands of the documentation (docs/guide/discovery.md), run exactly as printed."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.docs_pages import ROOT, block_under, shell_commands


def _commands(section: str) -> list[str]:
    """The commands of the first bash block under the heading ``section`` (README or docs; comments dropped)."""
    return shell_commands(block_under(section, "bash").code)


def _run(commands: list[str], cwd: Path) -> list[str]:
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    outputs = []
    for command in commands:
        assert command.startswith("wall-inspector "), command
        done = subprocess.run(command, shell=True, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"{command}\n{done.stdout}\n{done.stderr}"
        assert "Traceback" not in done.stderr
        outputs.append(done.stdout)
    return outputs


@pytest.mark.slow
def test_the_discovery_example_finds_the_hidden_suction(tmp_path):
    commands = _commands("Discovering a missing effect from flight logs")
    assert len(commands) == 2
    _, summary = _run(commands, tmp_path)
    report = json.loads((tmp_path / "results" / "report.json").read_text())
    assert [e["name"] for e in report["effects"]] == ["wall_suction"], summary
    params = report["effects"][0]["params"]
    assert params["k_s"] == pytest.approx(4.1, rel=0.1) and params["d_thr"] == pytest.approx(0.132, rel=0.1)
    assert report["gap_after"]["force_rms_N"] < 0.3 * report["gap_before"]["force_rms_N"]
    # what the page says: the residual falls to the log's noise floor ("within noise": within 1.5 times it)
    assert report["unexplained"] is None
    assert report["gap_after"]["force_rms_N"] <= 1.5 * report["noise"]["floor_N"]


def test_the_px4_example_imports_and_discovers(tmp_path):
    commands = _commands("Logs from PX4 and ROS 2")
    # the commands name files of the repository by relative path: give them the same layout
    for command in commands:
        for word in shlex.split(command):
            if (ROOT / word).is_file():
                (tmp_path / word).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(ROOT / word, tmp_path / word)
    imported, summary = _run(commands, tmp_path)
    assert "read PX4 ULog" in imported and "thrust map: motor_command" in imported
    report = json.loads((tmp_path / "sitl-results" / "report.json").read_text())
    assert report["limits"] and report["notes"]
    # what the page says it finds: a thrust scale a few per cent above 1 that halves the held-out force residual
    assert [e["name"] for e in report["effects"]] == ["thrust_scale"], summary
    assert 1.0 < report["effects"][0]["params"]["scale"] < 1.05
    assert report["gap_after"]["force_rms_N"] < 0.5 * report["gap_before"]["force_rms_N"]
    assert "cannot determine wall_suction: the scene has no wall" in summary
