"""A run folder belongs to one run: a second run into it refuses naming the first; a dead run's lock is taken over."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from wall_env.run_lock import RunFolderBusy, RunLock, lock_path
from wall_inspector.cli import main as cli_main


def _wait_for_holder(folder, timeout=120.0):
    """The lock file's record once a run holds it (the event itself, polled; the timeout only guards a hang)."""
    path = lock_path(folder)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.is_file() and path.read_text().strip():
            return json.loads(path.read_text())
        time.sleep(0.02)
    raise AssertionError(f"no run took {path} within {timeout} s")


def test_a_held_folder_is_refused_with_the_holder_named_and_released_on_exit(tmp_path):
    with RunLock(tmp_path / "run", "wall-inspector train") as first:
        with pytest.raises(RunFolderBusy, match=r"run is in use by 'wall-inspector train' \(pid \d+ on .*, started "):
            RunLock(tmp_path / "run", "wall-inspector compare").acquire()
        assert first.stale_holder is None
    with RunLock(tmp_path / "run", "wall-inspector compare") as second:  # released: free again
        assert second.stale_holder is None


def test_the_lock_of_a_killed_run_is_taken_over(tmp_path):
    code = (f"from wall_env.run_lock import RunLock; import time; RunLock({str(tmp_path)!r}, 'wall-inspector tune')"
            ".acquire(); print('held', flush=True); time.sleep(600)")
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(RunFolderBusy, match="wall-inspector tune"):
        RunLock(tmp_path, "wall-inspector train").acquire()
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    with RunLock(tmp_path, "wall-inspector train") as lock:
        assert lock.stale_holder is not None and lock.stale_holder["pid"] == holder.pid


# The first run is given work it cannot finish within the test on any machine (an hour-long flight; the largest
# tuning budget of minute-long flights), so it still holds the folder when the second run asks; it is then
# interrupted. With a short first run, a quiet machine finished it before the second run asked, and the test failed.
@pytest.mark.parametrize("command", [
    ["compare", "--seeds-i", "1", "--seeds-ii", "1", "--duration", "3600", "--no-progress", "--no-authors",
     "--no-ppo"],
    ["tune", "--env", "WallHover-v0", "--method", "pid", "--budget-trials", "100000", "--seeds", "1000",
     "--heldout-seeds", "2000", "--set", "duration=60", "--no-progress"],
])
def test_a_second_run_into_the_folder_of_a_running_one_refuses_and_changes_nothing(tmp_path, capsys, command):
    out = tmp_path / "run"
    first = subprocess.Popen([sys.executable, "-m", "wall_inspector.cli", *command, "--out", str(out)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        holder = _wait_for_holder(out)
        assert cli_main([*command, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"in use by 'wall-inspector {command[0]}' (pid {holder['pid']}" in err
        assert json.loads(lock_path(out).read_text())["pid"] == first.pid  # the refused run wrote nothing there
        assert first.poll() is None  # and the first one runs on
    finally:
        first.send_signal(signal.SIGINT)
        first.wait(timeout=120)
