"""How many threads a process may run: the cores that are free to it, never more.

One rule for every part of the project that runs PyTorch or BLAS threads (training's rollouts
and updates, evaluation, tuning, Ray workers)::

    threads = explicit setting, if there is one; otherwise
    threads = max(1, min(most, cores allowed, floor(free cores + SLACK)))

* *cores allowed*: ``os.sched_getaffinity(0)`` (what ``taskset``, a container's CPU set or a
  scheduler gives this process), or ``os.cpu_count()`` where affinity is unknown;
* *free cores*: cores allowed minus the CPU time that **other** processes took on them over a
  short window, read from ``/proc/stat`` (busy jiffies of the allowed CPUs) with this process's
  own time (``/proc/self/stat``, all its threads) taken out; where ``/proc`` is missing, the
  1-minute load average stands in for the others' load;
* *most*: what the caller can use (a Ray trial's CPUs; one for a policy acting on one
  observation at a time).

Why: PyTorch's threads spin at every parallel region; two of them on a 2-core machine where a
neighbour keeps one core busy wait on each other's preempted thread, and a PPO update runs
tens of times slower than on one thread (981 env steps/s on two threads against 25,740 on one,
measured at load average 4). ``SLACK`` = 0.25: a second thread is taken only when at least
0.75 of a core is free for it.

:class:`CpuWatch` measures the others' load between two moments without sleeping (training
samples it once per rollout, over the time the rollout and update took), and
:func:`choose_threads` applies the rule; the :class:`ThreadChoice` it returns says what was
chosen and why (training writes it into the model card). :func:`limit_threads` holds PyTorch's
(if imported) and BLAS's thread counts at a number for a block of code.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["AUTO", "SLACK", "CpuWatch", "ThreadChoice", "allowed_cores", "check_thread_setting", "choose_threads",
           "limit_threads", "threads_from_free"]

AUTO = "auto"
SLACK = 0.25  # a thread is added when at least 1 - SLACK of a core is free for it
_WINDOW_S = 0.25  # default measuring window of choose_threads (s)


def allowed_cores() -> list[int]:
    """The CPUs this process may run on (affinity), sorted."""
    try:
        return sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # no affinity on this platform
        return list(range(os.cpu_count() or 1))


def check_thread_setting(value: Any, name: str = "threads") -> int | str:
    """``value`` if it is a positive integer or ``"auto"``; ``ValueError`` naming ``name`` otherwise."""
    if value == AUTO:
        return AUTO
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 1024:
        raise ValueError(f"{name} must be 'auto' (the cores free to this process) or an integer in [1, 1024], "
                         f"got {value!r}")
    return value


def _clock_ticks() -> float:
    try:
        return float(os.sysconf("SC_CLK_TCK"))
    except (AttributeError, ValueError, OSError):
        return 100.0


def _busy_jiffies(cpus: list[int]) -> float | None:
    """Busy time (user, nice, system, irq, softirq, steal) of ``cpus`` since boot, in clock ticks;
    ``None`` where ``/proc/stat`` cannot be read."""
    try:
        with open("/proc/stat") as handle:
            lines = handle.read().splitlines()
    except OSError:
        return None
    wanted = {f"cpu{c}" for c in cpus}
    total = 0.0
    found = 0
    for line in lines:
        name, _, rest = line.partition(" ")
        if name in wanted:
            fields = [float(f) for f in rest.split()]
            # user nice system idle iowait irq softirq steal (guest time is already inside user)
            total += fields[0] + fields[1] + fields[2] + sum(fields[5:8])
            found += 1
    return total if found == len(wanted) else None


def _own_jiffies() -> float | None:
    """CPU time (user + system) of this process, all its threads, in clock ticks."""
    try:
        with open("/proc/self/stat") as handle:
            text = handle.read()
    except OSError:
        times = os.times()
        return (times.user + times.system) * _clock_ticks()
    fields = text.rpartition(")")[2].split()  # the fields after the command name (which may hold spaces)
    return float(fields[11]) + float(fields[12])  # utime, stime (fields 14 and 15 of proc(5))


class CpuWatch:
    """The CPU load of other processes on this process's cores between two calls of :meth:`busy_elsewhere`."""

    def __init__(self) -> None:
        self.cpus = allowed_cores()
        self._ticks = _clock_ticks()
        self._last = self._sample()

    def _sample(self) -> tuple[float, float | None, float | None]:
        return time.perf_counter(), _busy_jiffies(self.cpus), _own_jiffies()

    def busy_elsewhere(self) -> float | None:
        """Cores' worth of CPU time other processes took since the previous call (or since this
        watch was made), in ``[0, cores allowed]``; ``None`` where ``/proc`` cannot tell."""
        now = self._sample()
        (t0, busy0, own0), (t1, busy1, own1) = self._last, now
        self._last = now
        if busy0 is None or busy1 is None or own0 is None or own1 is None or t1 - t0 < 0.02:
            return None
        others = ((busy1 - busy0) - (own1 - own0)) / self._ticks / (t1 - t0)
        return min(max(others, 0.0), float(len(self.cpus)))


def _load_average() -> float | None:
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


def threads_from_free(free_cores: float, allowed: int, most: int | None = None) -> int:
    """The rule's number of threads for ``free_cores`` free out of ``allowed``, at most ``most``."""
    threads = int(math.floor(max(free_cores, 0.0) + SLACK))
    cap = allowed if most is None else min(allowed, int(most))
    return max(1, min(threads, cap))


@dataclass(frozen=True)
class ThreadChoice:
    """What :func:`choose_threads` chose and what it saw (for a model card or a log line)."""

    threads: int
    setting: int | str  # the configured value: "auto" or an explicit number
    cores_allowed: int
    busy_elsewhere: float | None  # cores' worth of other processes' CPU time over the window (None: not measured)
    load_average_1min: float | None
    most: int | None
    reason: str

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        if self.busy_elsewhere is not None:
            out["busy_elsewhere"] = round(self.busy_elsewhere, 2)
        return out


def choose_threads(setting: int | str = AUTO, *, most: int | None = None, window_s: float = _WINDOW_S,
                   watch: CpuWatch | None = None) -> ThreadChoice:
    """Apply the rule (module docstring) to ``setting`` (``"auto"`` or an explicit number, which wins).

    ``watch``: measure the others' load since that watch's previous call (no waiting); otherwise
    over ``window_s`` seconds from now. ``most``: the caller's own cap; with ``most=1`` nothing
    is measured.
    """
    setting = check_thread_setting(setting, "threads")
    cpus = len(watch.cpus) if watch is not None else len(allowed_cores())
    load = _load_average()
    if setting != AUTO:
        assert isinstance(setting, int)
        return ThreadChoice(setting, setting, cpus, None, load, most, "set explicitly")
    if most is not None and int(most) <= 1:
        return ThreadChoice(1, AUTO, cpus, None, load, most, "the work uses one thread at most")
    if watch is None:
        watch = CpuWatch()
        time.sleep(window_s)
    busy = watch.busy_elsewhere()
    if busy is None:  # no /proc: the load average is the others' load (our own part of it unknown)
        busy = load if load is not None else 0.0
        source = "load average"
    else:
        source = "/proc/stat"
    free = cpus - busy
    threads = threads_from_free(free, cpus, most)
    reason = (f"{free:.2f} of {cpus} allowed cores free (others busy {busy:.2f} by {source})"
              + (f", at most {most}" if most is not None else ""))
    return ThreadChoice(threads, AUTO, cpus, busy, load, most, reason)


@contextmanager
def limit_threads(threads: int) -> Iterator[None]:
    """Hold PyTorch's intra-op threads (if PyTorch is imported) and BLAS's threads at ``threads``
    inside the block; restored afterwards."""
    threads = max(1, int(threads))
    torch = sys.modules.get("torch")
    before = torch.get_num_threads() if torch is not None else None
    if torch is not None and before != threads:
        torch.set_num_threads(threads)
    try:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=threads, user_api="blas"):
            yield
    finally:
        if torch is not None and before is not None and torch.get_num_threads() != before:
            torch.set_num_threads(before)
