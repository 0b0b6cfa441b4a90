"""The floors of the project: the library packages below, the command line on top.

``wall_env`` <- ``controllers`` <- ``agents``; ``discovery`` uses them; ``wall_inspector`` (the command
line) sits on top of all. The library packages parse no options (no argparse, no ``add_arguments``) and
import nothing from ``wall_inspector``; every command of the table lives in ``wall_inspector``. Read
from the source (every import, including those inside functions), so nothing is imported to check it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from wall_inspector.cli import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ("wall_env", "controllers", "agents", "discovery")
# package -> the packages it must not import (agents <- discovery: discovery flies saved agents, so the
# reverse would be a cycle)
BELOW = {
    "wall_env": ("controllers", "agents", "discovery", "wall_inspector"),
    "controllers": ("agents", "discovery", "wall_inspector"),
    "agents": ("discovery", "wall_inspector"),
    "discovery": ("wall_inspector",),
}


def _modules(package: str) -> list[Path]:
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"no Python files under {package}/"
    return files


def _imported(path: Path) -> set[str]:
    """The absolute module names ``path`` imports, anywhere in it (top level, functions, TYPE_CHECKING)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


def _top(name: str) -> str:
    return name.split(".")[0]


@pytest.mark.parametrize("package", LIBRARY)
def test_no_library_module_parses_options(package):
    offenders = [str(path.relative_to(ROOT)) for path in _modules(package)
                 if "argparse" in (text := path.read_text()) or "add_arguments" in text]
    assert not offenders, f"command-line code (argparse / add_arguments) in library modules {offenders}: " \
                          "move it to wall_inspector/"


@pytest.mark.parametrize("package", LIBRARY)
def test_imports_point_down_only(package):
    wrong = {str(path.relative_to(ROOT)): sorted(name for name in _imported(path) if _top(name) in BELOW[package])
             for path in _modules(package)}
    wrong = {file: names for file, names in wrong.items() if names}
    assert not wrong, f"{package} must import none of {BELOW[package]}: {wrong}"


def test_the_checks_see_imports_inside_functions_and_from_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("import os\n\ndef f():\n    from wall_inspector.cli import main\n    import agents.train as t\n"
                      "    from . import sibling\n")
    assert _imported(module) == {"os", "wall_inspector.cli", "agents.train"}


def test_every_command_lives_in_wall_inspector_under_its_own_name():
    for name, (module, _) in COMMANDS.items():
        assert module == f"wall_inspector.{name.replace('-', '_')}", (name, module)
        tree = ast.parse((ROOT / "wall_inspector" / f"{module.split('.')[1]}.py").read_text())
        defined = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
        assert {"add_arguments", "run"} <= defined, f"{module} must define add_arguments(parser) and run(args)"
