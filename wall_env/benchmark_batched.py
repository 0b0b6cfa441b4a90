"""How the batched env scales with the number of vehicles: the measurements behind
``wall-inspector bench-env --batched`` (:mod:`wall_inspector.bench_env_batched` prints and writes them).

For one task (default ``WallInspector/WallSweep-v0``, default settings) the command measures,
in one run:

* env steps per second of :class:`~wall_env.vector_env.WallInspectorVectorEnv` for
  N = 1, 8, 64, 256, 1024, 4096 vehicles in one process (random actions from the action
  space, next-step autoresets included);
* the single env through ``gym.make`` in the same run, and the ratio of each figure to it;
* the time to reset all N envs (median, and per 1,000 envs);
* two processes each stepping one batched env of ``--two-core-n`` vehicles at the same
  time (env steps of both over the wall time of the slower);
* the resident memory before and after ``--memory-resets`` resets of a batch of 1,024;
* the structure tasks (``Facade-v0``, ``Pier-v0``: suction and contact from PyBullet's queries on
  the scene's bodies, :mod:`wall_env.surfaces`) at N = ``--geometry-n`` (256), each beside the
  plane-only task at the same N, the three measured in turn twice in the same run (the
  better of each pair is reported, so a burst of other work on a shared machine hurts all alike).

Targets: >= 100,000 steps/s at N = 1024 in one process and >= 20x the
single env; >= 200,000 with two processes; reset <= 1 ms per 1,000 envs; >= 20,000
steps/s for ``Facade-v0`` at N = 256 (:func:`check_targets`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from typing import Any

import gymnasium as gym
import numpy as np

import wall_env  # noqa: F401  (registers the tasks)

SIZES = (1, 8, 64, 256, 1024, 4096)
TARGET_BATCHED = 100_000.0
TARGET_RATIO = 20.0
TARGET_TWO_CORES = 200_000.0
TARGET_RESET_MS_PER_1000 = 1.0
TARGET_FACADE = 20_000.0  # env steps/s of the batched Facade-v0 at N = 256
GEOMETRY_TASKS = ("WallInspector/Facade-v0", "WallInspector/Pier-v0")


def _make(env_id: str, n: int):
    return gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")


def measure_batched(env_id: str, n: int, min_steps: int, seed: int = 0) -> dict[str, float]:
    """Env steps per second of a batch of ``n`` with random actions (at least ``min_steps`` env
    steps and 20 calls), and the median time of resetting all ``n``; also per second of this
    process's CPU time, which a machine shared with other work depresses far less than the
    wall-clock figures."""
    envs = _make(env_id, n)
    envs.reset(seed=seed)
    envs.action_space.seed(seed)
    for _ in range(20):
        envs.step(envs.action_space.sample())
    calls = max(20, -(-min_steps // n))
    episodes = 0
    start, cpu_start = time.perf_counter(), time.process_time()
    for _ in range(calls):
        _, _, terminated, truncated, _ = envs.step(envs.action_space.sample())
        episodes += int(np.count_nonzero(terminated | truncated))
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    reset_times, reset_cpu = [], []
    for _ in range(max(20, min(100, 50_000 // n))):
        t0, c0 = time.perf_counter(), time.process_time()
        envs.reset()
        reset_times.append(time.perf_counter() - t0)
        reset_cpu.append(time.process_time() - c0)
    envs.close()
    reset_ms = 1e3 * float(np.median(reset_times))
    return {"n": n, "calls": calls, "env_steps": calls * n, "steps_per_s": calls * n / elapsed,
            "steps_per_cpu_s": calls * n / max(cpu, 1e-9), "episodes_ended": episodes, "reset_all_ms": reset_ms,
            "reset_ms_per_1000_envs": reset_ms * 1000.0 / n,
            "reset_cpu_ms_per_1000_envs": 1e3 * float(np.mean(reset_cpu)) * 1000.0 / n}


def measure_single(env_id: str, steps: int, seed: int = 0) -> float:
    """Env steps per second of one env through ``gym.make`` (random actions, resets included)."""
    env = gym.make(env_id)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    for _ in range(200):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed


def _two_core_worker(env_id: str, n: int, calls: int, seed: int, barrier, queue) -> None:
    envs = _make(env_id, n)
    envs.reset(seed=seed)
    envs.action_space.seed(seed)
    for _ in range(20):
        envs.step(envs.action_space.sample())
    barrier.wait()
    start = time.perf_counter()
    for _ in range(calls):
        envs.step(envs.action_space.sample())
    queue.put((start, time.perf_counter()))
    envs.close()


def measure_two_processes(env_id: str, n: int, min_steps: int, processes: int = 2) -> dict[str, float]:
    """Env steps per second of ``processes`` batched envs of ``n`` stepping at the same time."""
    ctx = mp.get_context("spawn")
    barrier, queue = ctx.Barrier(processes), ctx.Queue()
    calls = max(20, -(-min_steps // n))
    workers = [ctx.Process(target=_two_core_worker, args=(env_id, n, calls, 1000 * k, barrier, queue))
               for k in range(processes)]
    for w in workers:
        w.start()
    spans = [queue.get(timeout=600) for _ in workers]
    for w in workers:
        w.join(timeout=60)
    wall = max(end for _, end in spans) - min(start for start, _ in spans)
    return {"processes": processes, "n_per_process": n, "env_steps": processes * calls * n,
            "steps_per_s": processes * calls * n / wall}


def measure_geometry(plane_env_id: str, n: int, min_steps: int, repeats: int = 2) -> list[dict[str, Any]]:
    """The structure tasks and the plane-only task at ``n`` vehicles, measured in turn ``repeats`` times;
    the better figure of each."""
    best: dict[str, dict[str, Any]] = {}
    for _ in range(repeats):
        for env_id in (plane_env_id, *GEOMETRY_TASKS):
            row = measure_batched(env_id, n, min_steps)
            if env_id not in best or row["steps_per_s"] > best[env_id]["steps_per_s"]:
                best[env_id] = {"env_id": env_id, **row}
    return list(best.values())


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def measure_memory(env_id: str, n: int, resets: int) -> dict[str, float]:
    """Resident memory (MB) after a warm-up and after ``resets`` more resets (with a step each)."""
    envs = _make(env_id, n)
    envs.reset(seed=0)
    zeros = np.zeros((n, 4), dtype=np.float32)
    for _ in range(20):
        envs.reset()
        envs.step(zeros)
    before = _rss_mb()
    for _ in range(resets):
        envs.reset()
        envs.step(zeros)
    after = _rss_mb()
    envs.close()
    return {"n": n, "resets": resets, "rss_before_mb": before, "rss_after_mb": after, "growth_mb": after - before}


def check_targets(rows: list[dict[str, Any]], two: dict[str, float] | None,
                  geometry: list[dict[str, Any]]) -> dict[str, tuple[float, bool]]:
    """The targets the figures reach: ``{name: (value, met)}`` for those the run measured.

    ``rows`` are :func:`measure_batched`'s (with ``ratio_to_single``), ``two`` is
    :func:`measure_two_processes`'s (or None) and ``geometry`` :func:`measure_geometry`'s.
    """
    at = {r["n"]: r for r in rows}
    checks: dict[str, tuple[float, bool]] = {}
    if 1024 in at:
        checks[f">= {TARGET_BATCHED:,.0f} steps/s at N = 1024"] = (at[1024]["steps_per_s"], at[1024]["steps_per_s"]
                                                                   >= TARGET_BATCHED)
        checks[f">= {TARGET_RATIO:.0f}x the single env at N = 1024"] = (at[1024]["ratio_to_single"],
                                                                        at[1024]["ratio_to_single"] >= TARGET_RATIO)
    if two:
        checks[f">= {TARGET_TWO_CORES:,.0f} steps/s with two processes"] = (two["steps_per_s"],
                                                                            two["steps_per_s"] >= TARGET_TWO_CORES)
    # per 1,000 envs at scale: below about 1,000 envs the call's fixed cost dominates the figure
    worst_reset = max((r["reset_ms_per_1000_envs"] for r in rows if r["n"] >= 1024), default=None)
    if worst_reset is not None:
        checks[f"reset <= {TARGET_RESET_MS_PER_1000} ms per 1,000 envs (N >= 1024)"] = (
            worst_reset, worst_reset <= TARGET_RESET_MS_PER_1000)
    facade = next((r for r in geometry if r["env_id"] == GEOMETRY_TASKS[0]), None)
    if facade is not None and facade["n"] == 256:
        checks[f">= {TARGET_FACADE:,.0f} steps/s for Facade-v0 at N = 256"] = (facade["steps_per_s"],
                                                                            facade["steps_per_s"] >= TARGET_FACADE)
    return checks
