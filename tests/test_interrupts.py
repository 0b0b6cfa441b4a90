"""Ctrl-C at random moments: the same command run again finishes the job, with the result of an uninterrupted run."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from wall_env.run_lock import lock_path

CLI = [sys.executable, "-m", "wall_inspector.cli"]


def _interrupt_at_random_moments(command: list[str], out: Path, moments: int, longest: float, seed: int) -> int:
    """Run ``command`` and interrupt it (SIGINT) ``moments`` times, each a random time after it took its run
    folder's lock (the event that says it started), then run it to the end; return how many runs were cut off."""
    rng = np.random.default_rng(seed)
    cut = 0
    for _ in range(moments):
        lock = lock_path(out)
        if lock.exists():
            lock.write_text("")  # the previous, interrupted run's record: wait for this run's own
        process = subprocess.Popen([*CLI, *command, "--out", str(out)], stdout=subprocess.DEVNULL,
                                   stderr=subprocess.PIPE, text=True)
        while process.poll() is None and not (lock.is_file() and lock.read_text().strip()):
            time.sleep(0.01)
        time.sleep(rng.uniform(0.0, longest))
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=300)
        assert "Traceback" not in err, err
        if process.returncode == 0:
            break  # it finished before the interrupt
        # 130, or killed by SIGINT itself (-2) when Python ends on it: a shell shows 130 for both
        assert process.returncode in (130, -signal.SIGINT), (process.returncode, err)
        cut += 1
    finished = subprocess.run([*CLI, *command, "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert finished.returncode == 0, finished.stderr
    return cut


def test_compare_interrupted_twenty_times_gives_the_uninterrupted_tables(tmp_path):
    command = ["compare", "--seeds-i", "1", "--seeds-ii", "6", "--duration", "1.0", "--no-authors", "--no-ppo",
               "--no-progress"]  # 36 flights of 0.1 s or less each
    whole = subprocess.run([*CLI, *command, "--out", str(tmp_path / "whole")], capture_output=True, text=True)
    assert whole.returncode == 0, whole.stderr
    cut = _interrupt_at_random_moments(command, tmp_path / "cut", moments=20, longest=0.15, seed=1)
    assert cut >= 15  # most of the interrupts landed mid-run
    for name in ("results.json", "tables.md"):
        assert (tmp_path / "cut" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()
    assert not (tmp_path / "cut" / ".flights").exists()  # cleared once complete
    assert json.loads((tmp_path / "cut" / "results.json").read_text())["runs"]
