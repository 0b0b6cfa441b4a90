"""Evaluating an agent with the same function and seeds as the controllers' tables.

:func:`evaluate_agent` runs :func:`controllers.evaluation.evaluate` (one episode per
seed, ``env.reset(seed=seed)``; the function ``wall-inspector compare`` uses for PID,
MPC and SC-MPC) and adds the episode returns, which that function does not record,
through Gymnasium's ``RecordEpisodeStatistics`` wrapper. The result is one flat dict for the model
card, lengths in metres:

* ``mean_return``, ``std_return``, ``mean_length_s``, ``completed`` (fraction of
  episodes that reached the reference's end);
* ``position_rmse_m`` (RMS of ``|p - p_ref|``), ``rmse_xyz_m``, ``mae_xyz_m``;
* ``wall_normal_rmse_m``, ``wall_normal_mae_m`` (error along the normal of the wall
  nearest to the reference, the paper's x for the wall tasks);
* ``collisions`` (contact steps), ``episodes_with_collision``, ``min_wall_clearance_m``;
* ``action_change_rms`` (smoothness of the normalised action).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import RecordEpisodeStatistics

__all__ = ["evaluate_agent"]


def evaluate_agent(policy: Any, env_id: str, env_kwargs: dict[str, Any] | None = None,
                   seeds: Iterable[int] = range(10), deterministic: bool = True) -> dict[str, Any]:
    """Fly ``policy`` (an object with ``predict`` or a factory ``env -> policy``) one
    episode per seed on ``gym.make(env_id, **env_kwargs)``; flat metrics (module docstring)."""
    import wall_env  # noqa: F401  (registers the tasks)
    from controllers.evaluation import evaluate

    seeds = list(seeds)
    recorders: list[RecordEpisodeStatistics] = []

    def make() -> gym.Env:
        recorders.append(RecordEpisodeStatistics(gym.make(env_id, **(env_kwargs or {})), buffer_length=len(seeds) + 1))
        return recorders[-1]

    result = evaluate(policy, make, seeds, deterministic=deterministic)
    m = result.metrics()
    recorder = recorders[-1]
    returns, lengths = np.asarray(recorder.return_queue, dtype=float), np.asarray(recorder.length_queue, dtype=float)
    dt = float(recorder.get_wrapper_attr("control_dt"))
    return {
        "episodes": m["episodes"],
        "mean_return": float(np.mean(returns)),
        "std_return": float(np.std(returns)),
        "mean_length_s": float(np.mean(lengths)) * dt,
        "completed": 1.0 - m["terminated_early"] / m["episodes"],
        "position_rmse_m": m["rmse_norm"],
        "rmse_xyz_m": m["rmse"],
        "mae_xyz_m": m["mae"],
        "wall_normal_rmse_m": m["wall_normal_rmse"],
        "wall_normal_mae_m": m["wall_normal_mae"],
        "collisions": m["collisions"],
        "episodes_with_collision": m["collision_episodes"],
        "min_wall_clearance_m": m["min_wall_clearance"],
        "action_change_rms": m["action_change_rms"],
    }
