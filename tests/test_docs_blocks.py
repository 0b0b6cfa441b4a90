"""Every code block of the README and of the documentation pages, run as printed, page by page in the
site's order and, within a page, top to bottom (a page's Python blocks share one namespace, as for a
reader who runs them in turn; its shell commands run in the same folder).

How each kind of block is checked:

- ``python``: executed as printed.
- ``bash`` / no language, ``wall-inspector`` commands: run for real (exit 0, no traceback) when they
  take seconds; the commands that take minutes to hours (:data:`PARSED_ONLY`: training, tuning, the
  full comparison) go only through the command's own argument parser, with the arguments exactly as
  printed, which must accept them.
- ``make TARGET``: ``make -n TARGET`` in the repository (the target exists and its recipe expands).
- ``ray ...`` (the two-machine cluster): every option is one ``ray`` lists in its own help.
- ``yaml`` / ``json``: files the page tells the reader to save (first line ``# NAME``) are written
  into the page's folder for the blocks after them; the flight-log sidecar is checked by the sidecar
  reader of :mod:`discovery.flight_log`.
- ``c``: compiled against the exported controller's header (the export command runs before it).
- ``bibtex``: a well-formed entry with a title and authors.

Any other kind of block fails the test, so no block goes unchecked.
"""

from __future__ import annotations

import functools
import importlib
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.docs_pages import DOCS, ROOT, Block, blocks, nav, pages, shell_commands

# commands that take minutes to hours: argument parsing only
PARSED_ONLY = {"train", "tune", "compare", "robustness", "bench-env", "bench-mpc", "bench-ray", "bench-train",
               "bench-throughput", "bench-discover", "bench-export", "notebooks"}
# repository folders the pages' commands read by relative path (linked into each page's folder)
_LINKED = ("agents", "docs", "tests")
_ENV = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")


def _parse_only(argv: list[str]) -> None:
    """The command's own parser, as ``wall-inspector`` builds it, takes ``argv`` (exit 2 would fail)."""
    from wall_inspector.cli import COMMANDS, OneLineParser

    module_name, help_text = COMMANDS[argv[0]]
    parser = OneLineParser(prog=f"wall-inspector {argv[0]}", description=help_text)
    importlib.import_module(module_name).add_arguments(parser)
    parser.parse_args(argv[1:])


@functools.cache
def _ray_start_help() -> str:
    listed = subprocess.run(["ray", "start", "--help"], env=_ENV, capture_output=True, text=True, timeout=120)
    assert listed.returncode == 0, listed.stderr
    return listed.stdout


def _run_command(command: str, cwd: Path, block: Block) -> str:
    argv = shlex.split(command)
    program = argv[0]
    if program == "wall-inspector":
        if argv[1] in PARSED_ONLY:
            _parse_only(argv[1:])
            return "parsed"
        done = subprocess.run(command, shell=True, cwd=cwd, env=_ENV, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"{block.where}: {command}\n{done.stdout}\n{done.stderr}"
        assert "Traceback" not in done.stderr, f"{block.where}: {command}\n{done.stderr}"
        return "run"
    if program == "make":
        done = subprocess.run(["make", "-n", *argv[1:]], cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, f"{block.where}: {command}\n{done.stderr}"
        return "make -n"
    if program == "ray":
        if argv[1:2] == ["start"]:
            for option in (a.split("=")[0] for a in argv[2:] if a.startswith("--")):
                assert re.search(rf"^\s+{re.escape(option)}(?=[\s,=])", _ray_start_help(), re.M), \
                    f"{block.where}: ray start has no option {option}"
        else:
            assert argv[1:] == ["stop"], f"{block.where}: {command}"
        return "options checked"
    raise AssertionError(f"{block.where}: no rule to check the command {command!r}")


def _check_block(block: Block, cwd: Path, namespace: dict) -> list[str]:
    """Run or check one block; what was done with it, for the test's report."""
    language, code = block.language, block.code
    if language == "python":
        exec(compile(code, block.where, "exec"), namespace)
        return ["python run"]
    if language in ("bash", ""):
        commands = shell_commands(code)
        assert commands, f"{block.where}: an empty shell block"
        return [f"{_run_command(command, cwd, block)}: {command[:60]}" for command in commands]
    if language in ("yaml", "json"):
        first = code.splitlines()[0]
        data = json.loads(code) if language == "json" else yaml.safe_load(code)
        name = re.fullmatch(r"# ([\w.-]+\.(?:yaml|yml|json))", first.strip())
        if name:  # a file the page has the reader save
            (cwd / name.group(1)).write_text(code)
            return [f"saved as {name.group(1)}"]
        if language == "json" and block.page == DOCS / "reference" / "log-format.md":
            from discovery.flight_log import parse_sidecar

            vehicle, scene, gravity = parse_sidecar(cwd / "flight.json", code, data)
            assert vehicle.mass == data["vehicle"]["mass"] and gravity == data["gravity"]
            assert len(scene.walls) == len(data["scene"]["walls"])
            return ["read as a sidecar"]
        raise AssertionError(f"{block.where}: a {language} block that is neither a file to save nor a sidecar")
    if language == "c":
        source = cwd / "flight.c"
        source.write_text(code)
        headers = [p.parent for p in cwd.rglob("wi_controller.h")]
        assert headers, f"{block.where}: no exported controller to compile against (the export command runs first)"
        done = subprocess.run(["cc", "-c", "-Wall", "-Wextra", "-Werror", "-I", str(headers[0]), str(source),
                               "-o", str(cwd / "flight.o")], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, f"{block.where}\n{done.stderr}"
        return ["compiled"]
    if language == "bibtex":
        assert code.count("{") == code.count("}") and re.match(r"@\w+\{\w+,", code)
        assert re.search(r"\btitle\s*=", code) and re.search(r"\bauthor\s*=", code)
        return ["bibtex checked"]
    raise AssertionError(f"{block.where}: no rule to run a {language!r} block")


def _page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


@pytest.mark.parametrize("page", [p for p in pages() if blocks(p)], ids=_page_id)
def test_every_code_block_of_the_page_runs_as_printed(page, tmp_path, monkeypatch):
    for name in _LINKED:  # the repository's files, read by the relative paths the pages print
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__main__"}
    done = []
    for block in blocks(page):
        done += [f"{block.where}: {what}" for what in _check_block(block, tmp_path, namespace)]
    print("\n".join(done))  # pytest -s shows what was run and what was only parsed


def test_every_page_of_docs_is_in_the_site():
    listed = set(nav())
    pages_on_disk = {p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")}
    assert pages_on_disk <= listed, f"pages missing from mkdocs.yml's nav: {sorted(pages_on_disk - listed)}"


def test_the_parse_only_rule_refuses_what_the_command_refuses():
    """Parsing is a real check: a flag the command does not have, or a value of the wrong type, fails."""
    _parse_only(["train", "--env", "WallInspector/WallSweep-v0", "--timesteps", "1000", "--out", "runs/x"])
    for bad in (["train", "--env", "WallSweep-v0", "--no-such-flag"], ["train", "--timesteps", "many"],
                ["tune", "--budget-trials", "abc"]):
        with pytest.raises(SystemExit) as exit_:
            _parse_only(bad)
        assert exit_.value.code == 2


def test_make_test_builds_the_site_with_warnings_as_errors():
    target = re.search(r"^test:.*\n((?:\t.*\n)+)", (ROOT / "Makefile").read_text(), re.M)
    assert target is not None and "mkdocs build --strict" in target.group(1)
    assert re.search(r"^docs:.*\n\t.*mkdocs build --strict", (ROOT / "Makefile").read_text(), re.M)
    site = re.search(r"--site-dir (\S+)", target.group(1))
    assert site is not None
    folder = "build/site" if site.group(1) == "$(SITE)" else site.group(1)
    ignored = subprocess.run(["git", "check-ignore", "-q", f"{folder}/index.html"], cwd=ROOT)
    assert ignored.returncode == 0, f"{folder} is not git-ignored"


def test_the_two_agent_loading_snippets_run_in_order_give_the_same_action(monkeypatch):
    """Plain Stable-Baselines3 with ``VecNormalize``, then ``agents.load_policy`` on the observation
    the page gives it: one agent, one action (a normalised observation normalised again would not be)."""
    import numpy as np

    page = DOCS / "guide" / "agents.md"
    loading = [b for b in blocks(page) if b.heading == "Loading an agent" and b.language == "python"]
    assert len(loading) == 2
    monkeypatch.chdir(ROOT)
    namespace: dict = {}
    exec(compile(loading[0].code, loading[0].where, "exec"), namespace)
    sb3_action = np.array(namespace["action"])
    exec(compile(loading[1].code, loading[1].where, "exec"), namespace)
    np.testing.assert_allclose(namespace["action"], sb3_action, atol=1e-6)
