"""The package as an installer and a reader meet it: dependencies that can all be met,
declared imports, type information, lint and type checks in the CI command, and shipped
text that describes the project itself (no paths outside the repository, no tracker numbers)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the same parser, as pip vendors it
    from pip._vendor import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("wall_env", "controllers", "agents", "discovery", "wall_inspector")
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
_TEXT_SUFFIXES = {".py", ".md", ".ipynb", ".yaml", ".yml", ".toml", ".json", ".txt", ".cfg"}
_NOT_OURS = {".venv", ".git", "build", "out", "runs"}


def _tracked_text_files() -> list[Path]:
    listed = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if listed.returncode == 0:
        paths = [ROOT / name for name in listed.stdout.splitlines()]
    else:  # not a git checkout: every file of the source tree
        paths = [p for p in ROOT.rglob("*") if p.is_file() and not (_NOT_OURS & set(p.relative_to(ROOT).parts))
                 and not any(part.endswith(".egg-info") for part in p.parts)]
    return [p for p in paths if p.suffix in _TEXT_SUFFIXES or p.name == "Makefile"]


def test_pip_check_finds_every_requirement_met():
    result = subprocess.run([sys.executable, "-m", "pip", "check"], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_dependencies_are_declared_and_compatible():
    project = PYPROJECT["project"]
    deps = {re.split(r"[<>=!~ \[]", d, maxsplit=1)[0].lower(): d for d in project["dependencies"]}
    assert "stable-baselines3>=2.4" in deps["stable-baselines3"]  # the first SB3 that supports Gymnasium 1.x
    assert "gymnasium>=1.0" in deps["gymnasium"]
    assert "cloudpickle" in deps  # imported by agents.vec_env
    extras = project["optional-dependencies"]
    assert {"nbclient", "nbformat", "ipykernel"} <= {re.split(r"[<>=]", d)[0] for d in extras["notebooks"]}
    assert "wall-inspector[notebooks]" in extras["test"]
    assert not any("nbmake" in d for group in extras.values() for d in group)
    assert project["license"] == "MIT"  # an SPDX expression, not the deprecated table
    makefile = (ROOT / "Makefile").read_text()
    installed = re.search(r'-e "\.\[([^\]]+)\]"', makefile)
    # the documented install brings the notebooks command's needs, the tests' and Ray's (its tests run in make test)
    assert installed is not None and {"notebooks", "test", "ray"} <= set(installed.group(1).split(","))


def test_every_package_ships_type_information():
    for package in PACKAGES:
        assert (ROOT / package / "py.typed").is_file(), package
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["*"]
    assert "*.pkl" in PYPROJECT["tool"]["setuptools"]["package-data"]["*"]  # the agents' VecNormalize files


def test_make_test_lints_and_type_checks_before_the_tests():
    target = re.search(r"^test:.*\n((?:\t.*\n)+)", (ROOT / "Makefile").read_text(), re.M)
    assert target is not None
    steps = target.group(1).split("\n")
    assert [s.strip().split()[0].rsplit("/", 1)[-1] for s in steps if s.strip()][:3] == ["ruff", "mypy", "python"]
    assert PYPROJECT["tool"]["mypy"]["files"] == list(PACKAGES)
    assert "select" in PYPROJECT["tool"]["ruff"]["lint"]


@pytest.mark.parametrize("pattern", [
    r"\.\./shared", r"shared/(notes|paper)", r"/work/", r"reference-numbers\.md",  # files outside the repository
    r"\b[Ii]ssue\s*#?\s*\d+", r"\b[Ii]ssue's\b",  # tracker numbers a reader cannot follow
])
def test_shipped_text_refers_to_nothing_outside_the_repository(pattern):
    offenders = []
    for path in _tracked_text_files():
        if path == Path(__file__).resolve():
            continue
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
            if re.search(pattern, line):
                offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:100]}")
    assert not offenders, "\n".join(offenders)
