"""Environment speed with random actions: the measurements behind ``wall-inspector bench-env``.

:func:`measure_single` gives a task's env steps per second in one process with random
actions (resets included, through ``gym.make`` and its wrappers) and its median ``reset()``
time; :func:`measure_vector` the steps per second of an N-process vector env
(``gymnasium.vector.AsyncVectorEnv``). The targets are :data:`TARGET_STEPS_PER_S` and
:data:`TARGET_RESET_MS`. The batched env's scaling curve is :mod:`wall_env.benchmark_batched`'s;
the command that prints and writes the figures is :mod:`wall_inspector.bench_env`.
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np

TARGET_STEPS_PER_S = 5000.0
TARGET_RESET_MS = 1.0


def measure_single(env_id: str, steps: int, seed: int = 0) -> dict[str, float]:
    env = gym.make(env_id)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    for _ in range(200):  # warm-up: first calls load the compiled dynamics
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    env.reset(seed=seed)
    reset_times = []
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            t0 = time.perf_counter()
            env.reset()
            reset_times.append(time.perf_counter() - t0)
    elapsed = time.perf_counter() - start
    # reset time on its own, so every task reports a median over many resets
    for _ in range(200):
        t0 = time.perf_counter()
        env.reset()
        reset_times.append(time.perf_counter() - t0)
    env.close()
    return {
        "steps_per_s": steps / elapsed,
        "reset_median_ms": 1e3 * float(np.median(reset_times)),
        "episodes_in_run": len(reset_times) - 200,
    }


def measure_vector(env_id: str, steps: int, n_envs: int = 2, seed: int = 0) -> float:
    envs = gym.vector.AsyncVectorEnv([lambda: gym.make(env_id) for _ in range(n_envs)])
    envs.reset(seed=seed)
    envs.action_space.seed(seed)
    for _ in range(100):
        envs.step(envs.action_space.sample())
    n_calls = steps // n_envs
    start = time.perf_counter()
    for _ in range(n_calls):
        envs.step(envs.action_space.sample())  # autoreset handles episode ends
    elapsed = time.perf_counter() - start
    envs.close()
    return n_calls * n_envs / elapsed
