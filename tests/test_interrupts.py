"""Ctrl-C at random moments: the same command run again finishes the job, with the result of an uninterrupted run."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

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


def test_a_ctrl_c_while_the_settings_are_written_does_not_refuse_the_rerun(tmp_path, monkeypatch):
    """Seen on CI: Ctrl-C landed while the first flight's settings file was half written, and every rerun then
    read a different signature and stopped with exit code 2."""
    from controllers.evaluation import EpisodeRecord
    from wall_inspector.compare import FinishedFlights, UsageError

    n = 3
    record = EpisodeRecord(seed=4, time=np.arange(n) * 0.02, p_world=np.zeros((n, 3)), p_ref=np.zeros((n, 3)),
                           wall_normal=np.tile([1.0, 0.0, 0.0], (n, 1)), collision=np.zeros(n, bool),
                           wall_clearance=np.full(n, 0.1), action=np.zeros((n, 4)), command=np.zeros((n, 4)),
                           hover_thrust=3.3, terminated=False, solve_times=[0.001] * n)
    signature = {"seeds": [4], "duration": 1.0, "policies": ["pid", "mpc", "sc-mpc"]}
    real_write_text = Path.write_text

    def cut_off_halfway(path, text, *args, **kwargs):
        real_write_text(path, text[: len(text) // 2], *args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(Path, "write_text", cut_off_halfway)
    try:
        FinishedFlights(tmp_path, signature).save("flight", record)
    except KeyboardInterrupt:
        pass
    monkeypatch.setattr(Path, "write_text", real_write_text)
    rerun = FinishedFlights(tmp_path, signature)  # raised UsageError before the settings were written whole
    assert rerun.load("flight") is None  # nothing of the cut-off save counts as a flown flight
    rerun.save("flight", record)
    assert rerun.load("flight").wall_clearance == pytest.approx([0.1] * n)
    assert FinishedFlights(tmp_path, signature).load("flight").seed == 4
    other = dict(signature, duration=2.0)
    with pytest.raises(UsageError, match="--out .* other settings"):
        FinishedFlights(tmp_path, other)
