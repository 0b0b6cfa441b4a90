"""Usage errors of the command line: one line on stderr, exit status 2, no traceback, and
nothing created or started before the check."""

from __future__ import annotations

import pytest

from wall_inspector.cli import COMMANDS, main


@pytest.fixture
def no_workers(monkeypatch):
    """Fail the test if a training worker process would be started."""
    import agents.vec_env

    def refuse(*args, **kwargs):
        raise AssertionError("a worker process was started before the arguments were checked")

    monkeypatch.setattr(agents.vec_env.MultiEnvSubprocVecEnv, "__init__", refuse)


def _one_line_error(capsys, command: str) -> str:
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1, captured.err
    assert captured.err.startswith(f"wall-inspector {command}: error: ")
    assert "Traceback" not in captured.err
    return captured.err


@pytest.mark.parametrize(("args", "message"), [
    (["--env", "Bogus-v0"], "unknown task 'Bogus-v0'"),
    (["--env", "WallHover-v0", "--n-envs", "0"], "n_envs must be a positive integer, got 0"),
    (["--env", "WallHover-v0", "--timesteps", "-5"], "timesteps must be a positive integer, got -5"),
    (["--env", "WallHover-v0", "--set", "ppo.n_steps=abc"], "ppo.n_steps must be a positive integer, got 'abc'"),
    (["--env", "WallHover-v0", "--set", "ppo.bogus=1"], "unknown key 'bogus'"),
    (["--env", "WallHover-v0", "--set", "ppo.gamma=[1"], "not valid YAML"),
    (["--env", "WallHover-v0", "--set", "env_kwargs.k_s=-3"], "k_s must be in [0, 200] N/m"),
    (["--env", "WallHover-v0", "--set", "env_kwargs.bogus=1"], "unexpected keyword argument 'bogus'"),
    (["--env", "WallHover-v0", "--randomize", "--set", "randomize_ranges.k_s=[5, 1]"], "must have low <= high"),
    (["--env", "WallHover-v0", "--n-envs", "4", "--workers", "8"], "n_workers (8) must not exceed n_envs (4)"),
    (["--env", "WallHover-v0", "--timesteps", "100"], "no room for one PPO rollout of 4096 env steps"),
    (["--env", "WallHover-v0", "--checkpoint-minutes", "-1"], "checkpoint_minutes must be in [0.0, inf]"),
    (["--env", "WallHover-v0", "--n-envs", "x"], "argument --n-envs: invalid int value: 'x'"),
    (["--env", "WallHover-v0", "--bogus"], "unrecognized arguments: --bogus"),
])
def test_train_rejects_bad_arguments_before_any_folder_or_worker(args, message, tmp_path, capsys, no_workers):
    out = tmp_path / "run"
    assert main(["train", *args, "--out", str(out)]) == 2
    assert message in _one_line_error(capsys, "train")
    assert not out.exists()


def test_train_rejects_an_unwritable_run_folder(capsys, no_workers):
    assert main(["train", "--env", "WallHover-v0", "--out", "/proc/x/run"]) == 2
    assert "--out /proc/x/run: cannot create files in /proc" in _one_line_error(capsys, "train")


def test_train_refuses_to_ship_from_a_dirty_tree(monkeypatch, tmp_path, capsys, no_workers):
    import agents.train

    monkeypatch.setattr(agents.train, "git_state", lambda: {"commit": "abc", "uncommitted": ["agents/train.py"]})
    out = tmp_path / "run"
    assert main(["train", "--env", "WallHover-v0", "--out", str(out), "--ship"]) == 2
    assert "agents/train.py differ from it; commit first" in _one_line_error(capsys, "train")
    assert not out.exists()


def test_demo_checks_its_output_folder_before_flying(monkeypatch, capsys):
    import wall_inspector.demo

    monkeypatch.setattr(wall_inspector.demo, "fly", lambda *a, **k: pytest.fail("flew before checking --out"))
    assert main(["demo", "--out", "/proc/x"]) == 2
    assert "--out /proc/x: cannot create files in /proc" in _one_line_error(capsys, "demo")


def test_unknown_command_is_one_line(capsys):
    assert main(["fly-to-the-moon"]) == 2
    err = capsys.readouterr().err
    assert err == "wall-inspector: error: unknown command 'fly-to-the-moon'; choose from " + ", ".join(COMMANDS) + "\n"


def test_readme_checks_every_input_before_writing(tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text("<!-- BEGIN a -->\nold\n<!-- END a -->\n")
    table = tmp_path / "a.md"
    table.write_text("| new |\n")
    cases = [
        (["--readme", str(tmp_path / "missing.md")], f"--readme {tmp_path / 'missing.md'}: cannot read"),
        (["--readme", str(readme), "--set", f"a={table}", "--set", f"a={tmp_path / 'gone.md'}"], "cannot read"),
        (["--readme", str(readme), "--set", f"a={table}", "--set", f"b={table}"], "README has no block"),
        (["--readme", str(readme), "--set", "a"], "--set takes NAME=FILE"),
    ]
    for args, message in cases:
        assert main(["readme", *args]) == 2
        assert message in _one_line_error(capsys, "readme")
        assert readme.read_text() == "<!-- BEGIN a -->\nold\n<!-- END a -->\n"  # untouched: the first block was not written


def test_notebooks_checks_its_paths_before_running_any(tmp_path, capsys):
    assert main(["notebooks", str(tmp_path / "missing.ipynb")]) == 2
    assert "missing.ipynb: not a notebook file" in _one_line_error(capsys, "notebooks")


def test_ctrl_c_in_any_command_ends_without_a_traceback(monkeypatch, capsys):
    import wall_inspector.demo

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(wall_inspector.demo, "run", interrupted)
    assert main(["demo"]) == 130
    assert capsys.readouterr().err == "wall-inspector demo: interrupted\n"


def test_ctrl_c_that_native_code_reports_as_another_error_is_still_an_interrupt(monkeypatch, capsys):
    """CasADi's SWIG layer, interrupted while it converts an argument, raises NotImplementedError ("Wrong
    number or type of arguments") instead of the KeyboardInterrupt; after a Ctrl-C that error is the interrupt's,
    and without one an error is an error."""
    import signal

    import wall_inspector.demo

    def interrupted_in_native_code(args):
        signal.raise_signal(signal.SIGINT)  # the command line's handler: the flag, then KeyboardInterrupt ...

    def swallowing(args):
        try:
            interrupted_in_native_code(args)
        except KeyboardInterrupt:  # ... which the native layer turns into an error of its own
            raise NotImplementedError("Wrong number or type of arguments for function 'new_DM'.") from None

    monkeypatch.setattr(wall_inspector.demo, "run", swallowing)
    assert main(["demo"]) == 130
    assert capsys.readouterr().err == "wall-inspector demo: interrupted\n"

    def broken(args):
        raise NotImplementedError("a real error")

    monkeypatch.setattr(wall_inspector.demo, "run", broken)
    with pytest.raises(NotImplementedError, match="a real error"):  # no Ctrl-C this time: not hidden
        main(["demo"])


# what a command needs besides the bad flag, so that the flag is the only thing wrong
REQUIRED = {
    "import-log": ["flight.ulg", "--vehicle", "vehicle.yaml", "--scene", "scene.yaml"],
    "fly": ["--out", "flight.csv"],
    "discover": ["flight.csv", "--out", "results"],
    "export": ["ppo", "--out", "exported"],
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_command_of_the_table_refuses_a_bad_flag_in_one_line(command, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main([command, *REQUIRED.get(command, []), "--no-such-flag"]) == 2
    captured = capsys.readouterr()
    assert captured.err == (f"wall-inspector {command}: error: unrecognized arguments: --no-such-flag "
                            f"(see wall-inspector {command} --help)\n"), \
        f"{captured.err!r}; if {command} has required arguments, add them to REQUIRED"
    assert captured.out == ""
    assert not any(tmp_path.iterdir())  # nothing written before the check
