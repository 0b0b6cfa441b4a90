"""Training throughput of PPO on a wall task for several vector-env layouts.

:func:`measure` trains the task's configured learner (:func:`agents.learner.make_ppo`) for a number of
env steps with one layout and returns env steps per second of wall time, PPO updates included (no
evaluation, no checkpoints): ``batched`` (every env in one batched env in this process, what
``wall-inspector train`` uses), ``sb3`` (Stable-Baselines3's ``SubprocVecEnv``, one env per process)
or ``multi`` (:class:`~agents.vec_env.MultiEnvSubprocVecEnv`, the envs in a few worker processes).
The update work per env step is kept equal across layouts by holding ``n_envs * n_steps`` (the
rollout size) at the configured value. ``wall-inspector bench-throughput`` runs it.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from agents.config import apply_overrides, default_config

__all__ = ["measure", "LAYOUTS", "parse_layout"]

LAYOUTS = ("batched", "sb3", "multi")


def parse_layout(text: str) -> tuple[str, int, int]:
    """``batched-N``, ``sb3-N`` or ``multi-N/W`` as ``(kind, n_envs, n_workers)``, or a ``ValueError``."""
    kind, _, size = str(text).partition("-")
    envs, _, workers = size.partition("/")
    try:
        n_envs, n_workers = int(envs), int(workers or (envs if kind != "batched" else 0))
    except ValueError:
        n_envs = n_workers = -1
    if kind not in LAYOUTS or not 1 <= n_envs <= 4096 or not 0 <= n_workers <= min(n_envs, 64) \
            or (kind == "multi" and n_workers < 1):
        raise ValueError(f"a layout is batched-N, sb3-N or multi-N/W (N envs in 1..4096, W workers in 1..N), "
                         f"got {text!r}")
    return kind, n_envs, n_workers


def measure(task: str, layout: str, timesteps: int, overrides: Sequence[str] = ()) -> float:
    """Env steps per second of ``timesteps`` training steps with ``layout`` (:func:`parse_layout`)."""
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from agents.envs import env_factory, make_vec_env
    from agents.learner import make_ppo
    from controllers.threads import choose_threads, limit_threads

    kind, n_envs, n_workers = parse_layout(layout)
    config = apply_overrides(default_config(task), list(overrides))
    rollout = config["n_envs"] * config["ppo"]["n_steps"]
    config = {**config, "n_envs": n_envs, "ppo": {**config["ppo"], "n_steps": max(rollout // n_envs, 1)}}
    venv: Any
    if kind == "sb3":
        venv = SubprocVecEnv([env_factory(config) for _ in range(n_envs)])
    else:
        venv = make_vec_env(config, n_envs, n_workers, vector="batched" if kind == "batched" else "subprocess")
    env = VecNormalize(venv, gamma=float(config["ppo"]["gamma"]))
    try:
        with limit_threads(choose_threads(config["torch_threads"]).threads):
            model = make_ppo(config, env, None)
            start = time.perf_counter()
            model.learn(total_timesteps=timesteps)
            return model.num_timesteps / (time.perf_counter() - start)
    finally:
        env.close()
