"""Evaluating a policy on a wall task: returns, tracking error, collisions.

Works with anything that has the Stable-Baselines3 ``predict`` protocol (a loaded
agent, a residual agent, a controller). Each episode is one seed: the environment is
reset with that seed, so two policies evaluated with the same seeds meet the same
start perturbations and command noise draws (as long as they survive equally long).

Metrics (SI units) pooled over all steps of all episodes:

* ``position_rmse_m``: RMS of ``|p - p_ref|``;
* ``wall_normal_rmse_m`` / ``wall_normal_mae_m``: RMS / mean absolute position error
  along the normal of the nearest wall (the paper's x for a wall in the y-z plane);
* ``collisions``: contacts summed over episodes, ``episodes_with_collision``;
* ``completed``: fraction of episodes that ran to the reference's end;
* ``mean_return``, ``std_return``, ``mean_length_s``.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import gymnasium as gym
import numpy as np

from wall_env.observation import OBSERVATION_FIELDS

__all__ = ["evaluate_policy_on_env", "evaluate_policy"]

_NORMAL = OBSERVATION_FIELDS["wall_normal"]


def evaluate_policy_on_env(policy: Any, env: gym.Env, seeds: Iterable[int], deterministic: bool = True) -> dict[str, Any]:
    """Run one episode per seed on ``env`` (plain wall env, 48-entry observations)."""
    returns, lengths, completed, collisions = [], [], [], []
    sq_pos, sq_normal, abs_normal, n_steps = 0.0, 0.0, 0.0, 0
    dt = float(env.unwrapped.control_dt)
    for seed in seeds:
        obs, info = env.reset(seed=int(seed))
        state, start = None, np.array([True])
        total, steps, done, truncated = 0.0, 0, False, False
        while not done:
            action, state = policy.predict(obs, state=state, episode_start=start, deterministic=deterministic)
            start = np.array([False])
            normal = np.asarray(obs[_NORMAL], dtype=float)
            obs, reward, terminated, truncated, info = env.step(np.asarray(action).reshape(4))
            error = np.asarray(info["p_world"]) - np.asarray(info["p_ref"])
            sq_pos += float(error @ error)
            e_n = float(error @ normal)
            sq_normal += e_n * e_n
            abs_normal += abs(e_n)
            n_steps += 1
            total += float(reward)
            steps += 1
            done = terminated or truncated
        returns.append(total)
        lengths.append(steps * dt)
        completed.append(bool(truncated))
        collisions.append(int(info["collisions"]))
    n = max(n_steps, 1)
    return {
        "episodes": len(returns),
        "mean_return": float(np.mean(returns)),
        "std_return": float(np.std(returns)),
        "mean_length_s": float(np.mean(lengths)),
        "completed": float(np.mean(completed)),
        "collisions": int(np.sum(collisions)),
        "episodes_with_collision": int(np.sum(np.asarray(collisions) > 0)),
        "position_rmse_m": float(np.sqrt(sq_pos / n)),
        "wall_normal_rmse_m": float(np.sqrt(sq_normal / n)),
        "wall_normal_mae_m": float(abs_normal / n),
    }


def evaluate_policy(policy: Any, env_id: str, env_kwargs: dict[str, Any] | None = None, seeds: Iterable[int] = range(10),
                    deterministic: bool = True) -> dict[str, Any]:
    """:func:`evaluate_policy_on_env` on a fresh ``gym.make(env_id, **env_kwargs)``."""
    import wall_env  # noqa: F401  (registers the tasks)

    env = gym.make(env_id, **(env_kwargs or {}))
    try:
        return evaluate_policy_on_env(policy, env, seeds, deterministic)
    finally:
        env.close()
