"""``wall-inspector bench-mpc``: SC-MPC solve time in closed loop, against IPOPT on the very same problems.

SC-MPC flies ``WallInspector/WallSweep-v0`` (k_s = 4.1 N/m, d_thr = 0.132 m, command
noise on, collisions do not end the episode) for ``--steps`` control steps, episode
after episode with seeds ``--seed``, ``--seed + 1``, ... After every step the
problem that step solved -- initial guess, measured state, reference, parameters --
is handed to the CasADi + IPOPT reference solver
(:mod:`controllers.mpc.ipopt_reference`), started from the same initial guess.

Reported, in milliseconds: median, p99, p99.8 and max of

- ``lm_solve``: the compiled control step (warm start, reference states and the
  Levenberg-Marquardt optimisation in one native call, :mod:`controllers.mpc.step`),
  wall clock (what :attr:`MPC.solve_times` holds),
- ``lm_solve_cpu``: the same in CPU time of the thread, which other processes that
  take the core away cannot inflate (on a shared machine the wall-clock tail shows
  their time slices; the load average is printed with the figures),
- ``controller_step``: the controller's own step (observation parsing, reference sampling, the call),
- ``single.predict_cpu``: the whole ``predict`` call as the env's user sees it (everything the
  controller does per control step, action mapping included), CPU time of the thread, in a
  second flight of ``--steps`` steps without IPOPT between the steps;
- ``batched.predict_cpu``: the same for ``--batch`` vehicles (default 64) of the batched env
  (``gym.make_vec(..., vectorization_mode="vector_entry_point")``) flown together for
  ``--batched-steps`` steps, one ``predict`` call on the ``(n, 48)`` batch per step, divided
  by ``n`` (per vehicle);
- ``ipopt_solve``: IPOPT's solver call on the same problem;

the ratio of IPOPT's to LM's median, and the relative cost gap
``(F_LM - F_IPOPT) / F_IPOPT`` (its share of steps within 1 %, median and max).
Targets, checked on the wall-clock LM figures: median <= 1.0 ms,
p99.8 <= 3 ms, >= 10x faster than IPOPT, gap within 1 % on >= 95 % of the steps; on
the whole ``predict`` (CPU time per vehicle), single and batched: median <= 0.3 ms,
p99.8 <= 1 ms. The process is pinned to one CPU core
(``--no-pin`` to leave it free); ``--high-priority`` runs the SC-MPC steps (not the
simulator, not IPOPT) with real-time FIFO scheduling where permitted, so that other
processes on a shared machine do not take the core away mid-solve, as a flight
computer runs its controller (what was in force is printed); ``--json FILE`` writes
every figure.
"""

from __future__ import annotations

import os
import time
from typing import Any

import gymnasium as gym
import numpy as np

import wall_env  # noqa: F401
from controllers.evaluation import solve_time_stats
from controllers.mpc.ipopt_reference import IpoptReference
from controllers.mpc.policy import SCMPC

TARGETS = {"median_ms": 1.0, "p99_8_ms": 3.0, "speedup": 10.0, "gap_share": 0.95, "gap": 0.01,
           "predict_median_ms": 0.3, "predict_p99_8_ms": 1.0}
ENV_ID = "WallInspector/WallSweep-v0"


class _ControllerPriority:
    """Real-time FIFO scheduling for the controller's solves only, as a flight computer runs its
    controller thread; everything else (the simulator, IPOPT) stays at normal priority, which
    keeps the process far inside the kernel's real-time budget (95 % of each second).

    ``enabled=False`` or no permission: a no-op. :attr:`description` says what is in force.
    """

    def __init__(self, enabled: bool):
        self.active = False
        self.description = "normal priority"
        if not enabled or not hasattr(os, "sched_setscheduler"):
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except (PermissionError, OSError):
            self.description = "normal priority (no permission for SCHED_FIFO)"
            return
        self.active = True
        self.description = "SC-MPC solves under SCHED_FIFO"

    def __enter__(self):
        if self.active:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
        return self

    def __exit__(self, *exc):
        if self.active:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        return False


def pin_to_one_core() -> int | None:
    """Pin this process to its last allowed CPU core (steadier timings); the core, or ``None`` where not possible."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    core = sorted(os.sched_getaffinity(0))[-1]
    os.sched_setaffinity(0, {core})
    return core


def measure(steps: int, seed: int, k_s: float, d_thr: float, with_ipopt: bool = True,
            high_priority: bool = False) -> dict:
    """Fly SC-MPC for ``steps`` control steps and time it (and IPOPT) on every step."""
    if steps < 1:
        raise ValueError(f"steps must be at least 1, got {steps}")
    env = gym.make(ENV_ID, k_s=k_s, d_thr=d_thr, noise=True, terminate_on_collision=False)
    policy = SCMPC.from_env(env, k_s=k_s, d_thr=d_thr)
    ipopt = IpoptReference(policy.problem) if with_ipopt else None
    lm_cost, ipopt_cost, ipopt_times, ipopt_failures = [], [], [], 0
    collisions, episodes = 0, 1
    priority = _ControllerPriority(high_priority)
    observation, _ = env.reset(seed=seed)
    start = True
    for _ in range(steps):
        with priority:
            action, _ = policy.predict(observation, episode_start=np.array([start]))
        start = False
        record = policy.last_solves[0]
        if ipopt is not None and record is not None:
            result = ipopt.solve(record.Z0, record.start, record.stage_params, record.global_params)
            ipopt_times.append(result.seconds)
            ipopt_cost.append(result.cost)
            lm_cost.append(record.result.cost)
            ipopt_failures += not result.success
        observation, _, terminated, truncated, info = env.step(action)
        collisions += int(info["collision"])
        if terminated or truncated:
            observation, _ = env.reset(seed=seed + episodes)
            episodes += 1
            start = True
    env.close()
    out: dict[str, Any] = {
        "env": ENV_ID,
        "k_s": k_s,
        "d_thr": d_thr,
        "steps": steps,
        "episodes": episodes,
        "collisions": collisions,
        "policy_failures": policy.failures,
        "priority": priority.description,
        "lm_iterations_mean": float(np.mean(policy.iteration_counts)),
        "lm_solve_ms": solve_time_stats(policy.solve_times),
        "lm_solve_cpu_ms": solve_time_stats(policy.solve_cpu_times),
        "controller_step_ms": solve_time_stats(policy.step_times),
    }
    if ipopt is not None:
        lm_c, ip_c = np.asarray(lm_cost), np.asarray(ipopt_cost)
        gap = (lm_c - ip_c) / np.maximum(np.abs(ip_c), 1e-12)
        out["ipopt_solve_ms"] = solve_time_stats(ipopt_times)
        out["ipopt_failures"] = ipopt_failures
        out["speedup_median"] = out["ipopt_solve_ms"]["median"] / out["lm_solve_ms"]["median"]
        out["cost_gap"] = {
            "share_within_1pct": float(np.mean(gap <= TARGETS["gap"])),
            "median": float(np.median(gap)),
            "max": float(np.max(gap)),
            "min": float(np.min(gap)),
        }
    return out


def measure_predict(steps: int, seed: int, k_s: float, d_thr: float) -> dict:
    """Fly one env with SC-MPC for ``steps`` control steps (episode after episode) and time each whole
    ``predict`` call in CPU time: a flight of its own, because IPOPT between the steps would evict the
    controller's code and data from the caches, which no user's flight does."""
    env = gym.make(ENV_ID, k_s=k_s, d_thr=d_thr, noise=True, terminate_on_collision=False)
    policy = SCMPC.from_env(env, k_s=k_s, d_thr=d_thr)
    observation, _ = env.reset(seed=seed)
    start, episodes, seconds = True, 1, []
    for _ in range(steps):
        cpu = time.thread_time()
        action, _ = policy.predict(observation, episode_start=np.array([start]))
        seconds.append(time.thread_time() - cpu)
        start = False
        observation, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            observation, _ = env.reset(seed=seed + episodes)
            episodes += 1
            start = True
    env.close()
    return {"vehicles": 1, "steps": steps, "episodes": episodes, "policy_failures": policy.failures,
            "predict_cpu_ms": solve_time_stats(seconds)}


def measure_batched(n: int, steps: int, seed: int, k_s: float, d_thr: float) -> dict:
    """Fly ``n`` vehicles of the batched env with one SC-MPC ``predict`` call per step; CPU time per vehicle."""
    if n < 1 or steps < 1:
        raise ValueError(f"batch and batched steps must be at least 1, got {n} and {steps}")
    envs = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", k_s=k_s, d_thr=d_thr,
                        noise=True, terminate_on_collision=False)
    policy = SCMPC.from_env(envs, k_s=k_s, d_thr=d_thr)
    observations, _ = envs.reset(seed=seed)
    per_vehicle = []
    for _ in range(steps):
        cpu = time.thread_time()
        actions, _ = policy.predict(observations)
        per_vehicle.append((time.thread_time() - cpu) / n)
        observations, *_ = envs.step(actions)
    envs.close()
    return {"vehicles": n, "steps": steps, "policy_failures": policy.failures,
            "lm_iterations_mean": float(np.mean(policy.iteration_counts)),
            "predict_cpu_ms": solve_time_stats(per_vehicle)}


def check_targets(figures: dict) -> dict[str, bool]:
    checks = {
        "lm median <= 1.0 ms": figures["lm_solve_ms"]["median"] <= TARGETS["median_ms"],
        "lm p99.8 <= 3 ms": figures["lm_solve_ms"]["p99_8"] <= TARGETS["p99_8_ms"],
        "steps >= 2000": figures["steps"] >= 2000,
    }
    median, tail = TARGETS["predict_median_ms"], TARGETS["predict_p99_8_ms"]
    runs = [("single", figures["single"]["predict_cpu_ms"])]
    if "batched" in figures:
        runs.append((f"batched N={figures['batched']['vehicles']}", figures["batched"]["predict_cpu_ms"]))
    for name, stats in runs:
        checks[f"predict CPU per vehicle, {name}: median <= {median} ms"] = stats["median"] <= median
        checks[f"predict CPU per vehicle, {name}: p99.8 <= {tail} ms"] = stats["p99_8"] <= tail
    if "speedup_median" in figures:
        checks["IPOPT / LM median >= 10"] = figures["speedup_median"] >= TARGETS["speedup"]
        checks["cost within 1 % on >= 95 % of steps"] = figures["cost_gap"]["share_within_1pct"] >= TARGETS["gap_share"]
    return checks


def markdown(figures: dict) -> str:
    """The figures as a Markdown table (for ``wall-inspector readme``)."""
    rows = [("SC-MPC, compiled step with Levenberg-Marquardt (wall clock)", figures["lm_solve_ms"]),
            ("SC-MPC, compiled step with Levenberg-Marquardt (CPU time)", figures["lm_solve_cpu_ms"]),
            ("SC-MPC, whole `predict`, one env (CPU time)", figures["single"]["predict_cpu_ms"])]
    if "batched" in figures:
        rows.append((f"SC-MPC, whole `predict` on {figures['batched']['vehicles']} envs, per vehicle (CPU time)",
                     figures["batched"]["predict_cpu_ms"]))
    if "ipopt_solve_ms" in figures:
        rows.append(("same problems, CasADi + IPOPT", figures["ipopt_solve_ms"]))
    lines = ["| solver | median (ms) | p99 (ms) | p99.8 (ms) | max (ms) |", "|---|---:|---:|---:|---:|"]
    lines += [f"| {name} | {s['median']:.3f} | {s['p99']:.3f} | {s['p99_8']:.3f} | {s['max']:.3f} |" for name, s in rows]
    lines.append("")
    text = (f"{figures['steps']:,} closed-loop control steps of `{ENV_ID}` (k_s 4.1 N/m, d_thr 0.132 m, command noise), "
            f"{figures['lm_iterations_mean']:.1f} LM iterations per solve on average, "
            f"{'pinned to one core' if figures['machine']['pinned_core'] is not None else 'not pinned'}, "
            f"{figures['priority']}.")
    if "ipopt_solve_ms" in figures:
        gap = figures["cost_gap"]
        text += (f" IPOPT takes {figures['speedup_median']:.0f}x longer (median); the LM cost is within 1 % of "
                 f"IPOPT's optimum on {100 * gap['share_within_1pct']:.1f} % of the steps (largest gap {gap['max']:.1e}).")
    text += (" The whole `predict` (observation, reference, warm start, LM, action mapping) is timed in a flight of "
             "one env of its own (no IPOPT between the steps)")
    if "batched" in figures:
        b = figures["batched"]
        text += (f" and with {b['vehicles']} envs of the batched env answered by one `predict` call per step "
                 f"({b['steps']:,} steps, per vehicle)")
    load = figures["machine"]["load_average_1min"]
    text += f"; load average {load[0]:.1f} -> {load[1]:.1f} on {figures['machine']['cpus']} CPUs."
    lines.append(text + " Measured by `wall-inspector bench-mpc`.")
    return "\n".join(lines) + "\n"
