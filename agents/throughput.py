"""Training throughput of PPO on a wall task for several vector-env layouts.

``python -m agents.throughput --env WallSweep-v0 --timesteps 200000`` trains the task's
configured PPO for the given number of env steps with each layout and prints env
steps per second of wall time, PPO updates included (no evaluation, no checkpoints):

* ``sb3-subproc-N``: Stable-Baselines3's ``SubprocVecEnv``, one environment per process;
* ``multi-N/W``: :class:`~agents.vec_env.MultiEnvSubprocVecEnv`, N environments in W
  worker processes (the layout ``wall-inspector train`` uses).

The update work per env step is kept equal across layouts by holding
``n_envs * n_steps`` (the rollout size) at the configured value.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import Any

from agents.config import apply_overrides, default_config

__all__ = ["measure"]


def measure(task: str, layout: str, n_envs: int, n_workers: int, timesteps: int, overrides: Sequence[str] = ()) -> float:
    """Env steps per second of ``timesteps`` PPO training steps with one layout."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from agents.envs import env_factory, make_vec_env

    config = apply_overrides(default_config(task), list(overrides))
    rollout = config["n_envs"] * config["ppo"]["n_steps"]
    ppo = {**config["ppo"], "n_steps": max(rollout // n_envs, 1)}
    torch.set_num_threads(int(config["torch_threads"]))
    venv: Any
    if layout == "sb3":
        venv = SubprocVecEnv([env_factory(config) for _ in range(n_envs)])
    else:
        venv = make_vec_env(config, n_envs, n_workers)
    env = VecNormalize(venv, gamma=float(ppo["gamma"]))
    model = PPO("MlpPolicy", env, device="cpu", seed=0, verbose=0,
                policy_kwargs={"net_arch": list(config["policy"]["net_arch"]), "log_std_init": config["policy"]["log_std_init"]},
                **ppo)
    try:
        start = time.perf_counter()
        model.learn(total_timesteps=timesteps)
        return model.num_timesteps / (time.perf_counter() - start)
    finally:
        env.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m agents.throughput", description=__doc__.split("\n")[0])
    parser.add_argument("--env", default="WallSweep-v0")
    parser.add_argument("--timesteps", type=int, default=100_000)
    parser.add_argument("--layouts", nargs="*", default=["sb3-2", "sb3-8", "multi-8/2", "multi-16/2", "multi-32/2"],
                        help="sb3-N or multi-N/W")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args(argv)
    print(f"{'layout':14s} {'env steps/s':>12s}")
    for name in args.layouts:
        kind, _, size = name.partition("-")
        n_envs, _, workers = size.partition("/")
        rate = measure(args.env, kind, int(n_envs), int(workers or n_envs), args.timesteps, args.set)
        print(f"{name:14s} {rate:12.0f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
