"""The thread rule (controllers.threads): what it measures on this machine, what it chooses, and who follows it."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from controllers import threads as rule
from controllers.threads import CpuWatch, check_thread_setting, choose_threads, limit_threads, threads_from_free


def test_the_rule_takes_a_thread_per_free_core_and_never_more_than_allowed():
    # floor(free + 0.25): a second thread needs at least 0.75 of a core free for it
    assert [threads_from_free(f, 2) for f in (0.0, 0.9, 1.0, 1.7, 1.75, 2.0)] == [1, 1, 1, 1, 2, 2]
    assert threads_from_free(7.9, 8) == 8 and threads_from_free(12.0, 8) == 8  # never past the cores allowed
    assert threads_from_free(3.9, 8, most=2) == 2  # nor past the caller's cap
    assert threads_from_free(-0.5, 2) == 1  # always one
    assert check_thread_setting("auto") == "auto" and check_thread_setting(3) == 3
    for bad in (0, -1, 2.5, True, "two", None):
        with pytest.raises(ValueError, match=r"torch_threads must be 'auto' \(the cores free to this process\) or an "
                                             r"integer in \[1, 1024\]"):
            check_thread_setting(bad, "torch_threads")


def test_an_explicit_setting_wins_and_one_observation_needs_no_measurement(monkeypatch):
    def no_measuring(*args, **kwargs):
        raise AssertionError("measured although nothing needed measuring")

    monkeypatch.setattr(rule, "CpuWatch", no_measuring)
    explicit = choose_threads(3)
    assert (explicit.threads, explicit.setting, explicit.reason) == (3, 3, "set explicitly")
    single = choose_threads("auto", most=1)
    assert single.threads == 1 and single.busy_elsewhere is None and "one thread at most" in single.reason


def test_others_load_is_the_busy_time_of_the_allowed_cores_less_this_process_own(monkeypatch):
    # /proc/stat says the allowed cores were busy 150 ticks over 1 s; this process took 40 of them
    samples = iter([(10.0, 1000.0, 500.0), (11.0, 1150.0, 540.0)])
    monkeypatch.setattr(CpuWatch, "_sample", lambda self: next(samples))
    watch = CpuWatch()
    watch.cpus, watch._ticks = [0, 1], 100.0
    assert watch.busy_elsewhere() == pytest.approx(1.1)
    choice = choose_threads(watch=_Fixed(1.1, cpus=2))
    assert choice.threads == 1 and choice.busy_elsewhere == pytest.approx(1.1)
    assert choice.reason == "0.90 of 2 allowed cores free (others busy 1.10 by /proc/stat)"
    assert choose_threads(watch=_Fixed(0.1, cpus=2)).threads == 2
    assert choose_threads(watch=_Fixed(0.1, cpus=2), most=1).threads == 1


class _Fixed:
    def __init__(self, busy: float, cpus: int):
        self.busy, self.cpus = busy, list(range(cpus))

    def busy_elsewhere(self) -> float:
        return self.busy


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="the measurement reads /proc (Linux)")
def test_this_process_own_cpu_time_is_counted_as_its_own():
    own0, cpu0 = rule._own_jiffies(), time.process_time()
    x = 0.0
    while time.process_time() - cpu0 < 0.3:  # burn 0.3 s of this process's CPU time
        x += 1.0
    own1, cpu1 = rule._own_jiffies(), time.process_time()
    assert own0 is not None and own1 is not None
    ticks = rule._clock_ticks()
    assert (own1 - own0) / ticks == pytest.approx(cpu1 - cpu0, abs=3.0 / ticks)


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="the measurement reads /proc (Linux)")
def test_a_spinning_neighbour_shows_as_busy_elsewhere():
    spinner = subprocess.Popen([sys.executable, "-c", "print('go', flush=True)\nwhile True: pass"], stdout=subprocess.PIPE)
    try:
        assert spinner.stdout is not None and spinner.stdout.readline().strip() == b"go"
        watch = CpuWatch()
        spun0 = _cpu_ticks(spinner.pid)
        ticks = rule._clock_ticks()
        while _cpu_ticks(spinner.pid) < spun0 + 0.3 * ticks:  # wait until the neighbour has spun 0.3 s of CPU
            time.sleep(0.02)
        spun = _cpu_ticks(spinner.pid) - spun0
        window_start = watch._last[0]
        busy = watch.busy_elsewhere()
        window = watch._last[0] - window_start
    finally:
        spinner.kill()
        spinner.wait()
    assert busy is not None
    # what the others took over the window holds at least the spinner's CPU time in it (3 ticks of accounting aside)
    assert busy * window * ticks >= spun - 3.0
    assert busy <= 2.0 * len(rule.allowed_cores())


def _cpu_ticks(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as handle:
        fields = handle.read().rpartition(")")[2].split()
    return float(fields[11]) + float(fields[12])


def test_limit_threads_holds_torch_inside_and_restores_it():
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        with limit_threads(1):
            assert torch.get_num_threads() == 1
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


def test_evaluation_flies_on_one_thread_and_gives_the_others_back():
    from controllers.evaluation import evaluate

    seen = []

    class Hover:
        def predict(self, observation, state=None, episode_start=None, deterministic=True):
            seen.append(torch.get_num_threads())
            return np.zeros(4, dtype=np.float32), state

    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        evaluate(Hover(), "WallInspector/WallHover-v0", [0])
        assert seen and set(seen) == {1}
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


def test_ray_reserves_one_cpu_for_an_auto_run_and_the_explicit_threads_otherwise():
    from agents.config import apply_overrides, default_config
    from wall_inspector.train_on_ray import cpus_per_run

    config = default_config("WallSweep")
    assert config["torch_threads"] == "auto" and cpus_per_run(config) == 1
    assert cpus_per_run(apply_overrides(config, ["torch_threads=2"])) == 2
    with pytest.raises(ValueError, match=r"rollout_torch_threads must be 'auto'"):
        apply_overrides(config, ["rollout_torch_threads=0"])
