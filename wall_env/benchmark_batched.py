"""``wall-inspector bench-env --batched``: how the batched env scales with the number of vehicles.

For one task (default ``WallInspector/WallSweep-v0``, default settings) it measures, in
one run:

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
steps/s for ``Facade-v0`` at N = 256. The table goes to the terminal (and ``--markdown``),
the figures to ``--json`` and the scaling curve to ``--plot``.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import platform
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


def _load() -> str:
    try:
        one, five, fifteen = os.getloadavg()
        return f"{one:.2f}, {five:.2f}, {fifteen:.2f}"
    except OSError:  # pragma: no cover - not on Linux
        return "unknown"


def run_batched(args) -> int:
    env_id = args.envs[0] if args.envs and len(args.envs) == 1 else "WallInspector/WallSweep-v0"
    if args.envs and len(args.envs) > 1:
        print(f"--batched measures one task; using {env_id}")
    sizes = tuple(args.sizes)
    load_start = _load()
    print(f"batched env scaling, {env_id}, one process, random actions, resets included "
          f"(load average at start: {load_start})")
    single = measure_single(env_id, args.steps)
    rows: list[dict[str, Any]] = []
    header = (f"{'N':>6s} {'env steps/s':>12s} {'x single':>9s} {'reset all (ms)':>15s} {'ms / 1000 envs':>15s} "
              f"{'steps/CPU-s':>12s} {'CPU ms/1000':>12s}")
    print(header)
    print("-" * len(header))
    print(f"{'single':>6s} {single:12,.0f} {1.0:9.1f} {'':>15s} {'':>15s}")
    for n in sizes:
        row = measure_batched(env_id, n, args.batched_steps)
        row["ratio_to_single"] = row["steps_per_s"] / single
        rows.append(row)
        print(f"{n:6d} {row['steps_per_s']:12,.0f} {row['ratio_to_single']:9.1f} {row['reset_all_ms']:15.3f} "
              f"{row['reset_ms_per_1000_envs']:15.3f} {row['steps_per_cpu_s']:12,.0f} "
              f"{row['reset_cpu_ms_per_1000_envs']:12.3f}")
    two = measure_two_processes(env_id, args.two_core_n, args.batched_steps) if args.two_core_n else None
    if two:
        print(f"\ntwo processes, one batched env of {two['n_per_process']} each: {two['steps_per_s']:,.0f} env steps/s")
    memory = measure_memory(env_id, 1024, args.memory_resets) if args.memory_resets else None
    if memory:
        print(f"memory over {memory['resets']} resets of a 1,024-env batch: {memory['rss_before_mb']:.1f} MB -> "
              f"{memory['rss_after_mb']:.1f} MB ({memory['growth_mb']:+.1f} MB)")
    geometry = measure_geometry(env_id, args.geometry_n, min(args.batched_steps, 100_000)) if args.geometry_n else []
    if geometry:
        print(f"\nstructures (PyBullet's geometry) beside planes, N = {args.geometry_n}:")
        for row in geometry:
            print(f"  {row['env_id']:28s} {row['steps_per_s']:10,.0f} env steps/s {row['steps_per_cpu_s']:10,.0f} "
                  f"per CPU-second")
    load_end = _load()
    print(f"load average at end: {load_end}")

    at = {r["n"]: r for r in rows}
    checks = {}
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
    print()
    for name, (value, ok) in checks.items():
        print(f"{'met    ' if ok else 'NOT met'}  {name}: {value:,.3f}")

    if args.markdown:
        lines = ["| vehicles N | env steps/s (1 process) | x single env | reset all N (ms) | ms per 1,000 envs | "
                 "env steps per CPU-second |",
                 "|---:|---:|---:|---:|---:|---:|",
                 f"| single env | {single:,.0f} | 1.0 | | | |",
                 *[f"| {r['n']:,} | {r['steps_per_s']:,.0f} | {r['ratio_to_single']:.1f} | {r['reset_all_ms']:.3f} | "
                   f"{r['reset_ms_per_1000_envs']:.3f} | {r['steps_per_cpu_s']:,.0f} |" for r in rows]]
        if two:
            lines += ["", f"Two processes, one batched env of {two['n_per_process']:,} each: "
                          f"{two['steps_per_s']:,.0f} env steps/s."]
        lines += ["", f"`{env_id}`, random actions, resets included, measured by `wall-inspector bench-env --batched` "
                      f"on {os.cpu_count()} cores (load average {load_start} at start)."]
        if geometry:
            lines += ["", f"| structure, N = {args.geometry_n:,} | env steps/s (1 process) | env steps per CPU-second |",
                      "|---|---:|---:|",
                      *[f"| `{r['env_id']}`{' (planes only)' if r['env_id'] == env_id else ''} | "
                        f"{r['steps_per_s']:,.0f} | {r['steps_per_cpu_s']:,.0f} |" for r in geometry],
                      "", "Measured in turn twice in the same run, the better of each; the structures' suction and "
                      "contact come from PyBullet's closest-point queries on their bodies."]
        with open(args.markdown, "w") as fh:
            fh.write("\n".join(lines) + "\n")
        print(f"wrote {args.markdown}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        ax.loglog([r["n"] for r in rows], [r["steps_per_s"] for r in rows], "o-", label="batched env, 1 process")
        ax.loglog([r["n"] for r in rows], [r["steps_per_cpu_s"] for r in rows], "o--", color="tab:blue", alpha=0.5,
                  label="batched env, per CPU-second")
        ax.axhline(single, color="grey", linestyle="--", label="single env (gym.make)")
        if two:
            ax.plot([two["n_per_process"]], [two["steps_per_s"]], "s", label="2 processes")
        ax.axhline(TARGET_BATCHED, color="tab:red", linestyle=":", label="target at N = 1024")
        ax.set_xlabel("vehicles per batched env N")
        ax.set_ylabel("env steps per second")
        ax.set_title(f"{env_id.split('/')[-1]}: random actions, resets included")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        plt.close(fig)
        print(f"wrote {args.plot}")
    if args.json:
        payload = {
            "env_id": env_id,
            "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform(),
                        "load_average_start": load_start, "load_average_end": load_end},
            "single_steps_per_s": single,
            "batched": rows,
            "two_processes": two,
            "memory": memory,
            "geometry": geometry,
            "checks": {name: {"value": value, "met": ok} for name, (value, ok) in checks.items()},
        }
        with open(args.json, "w") as fh:
            json.dump(payload, fh, indent=2)
        print(f"wrote {args.json}")
    return 0
