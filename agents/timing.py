"""Where a training run's time goes: env steps, the rest of the rollouts, and the PPO updates.

:class:`TimeSplit` is a callback that times each rollout (``on_rollout_start`` to
``on_rollout_end``) and takes the time the vector env spent inside ``step`` from the env
itself when it counts it (:class:`~agents.batched_vec_env.BatchedVecEnv` does, and
:class:`~agents.residual.ResidualVecEnv` adds its base controller's time); the
remainder of the training time is the learner's updates (and callbacks such as
evaluations). ``split()`` gives seconds and shares for the model card.

With a :class:`~agents.rollout_worker.RolloutWorker` (rollouts in a second process, beside the updates) the
env steps and the rest of the rollouts are the worker's time, which overlaps the learner's; the split then
adds ``waiting_for_rollouts_s`` (the learner idle until a rollout arrived), and the learner's own time
(updates, replaying the rollouts to the callbacks, evaluations) is the rest. The shares are of the
training time each, and add up to more than 1 by the overlap.
"""

from __future__ import annotations

import time
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

__all__ = ["TimeSplit", "step_seconds"]


def _counting_env(env: Any) -> Any:
    """The outermost env of a vector-env wrapper chain (``.venv`` links) that keeps ``step_time_s``
    itself (SB3's wrappers forward attribute lookups, but refuse names found on two levels)."""
    while env is not None:
        if "step_time_s" in vars(env) or any("step_time_s" in vars(cls) for cls in type(env).__mro__):
            return env
        env = vars(env).get("venv")
    return None


def step_seconds(env: Any) -> float:
    """Seconds the vector env ``env`` (a wrapper chain) has spent inside ``step`` so far, as the env that counts
    them keeps it; 0 when none does."""
    counting = _counting_env(env)
    return float(getattr(counting, "step_time_s", 0.0)) if counting is not None else 0.0


class TimeSplit(BaseCallback):
    """Times rollouts and updates; see the module docstring."""

    def __init__(self, env: Any = None):
        super().__init__()
        self.env = _counting_env(env)  # the outermost env of the wrapper chain that counts its step time
        self.rollout_s = 0.0
        self._training_start = 0.0
        self._rollout_start = 0.0
        self.total_s = 0.0
        self._env_time_at_start = 0.0
        self.worker: Any = None

    def _env_time(self) -> float:
        return step_seconds(self.env)

    def _on_training_start(self) -> None:
        self.worker = getattr(self.model, "rollout_worker", None)  # its figures are read after it has been closed
        self._training_start = time.perf_counter()
        self._env_time_at_start = self._env_time()

    def _on_rollout_start(self) -> None:
        self._rollout_start = time.perf_counter()

    def _on_rollout_end(self) -> None:
        self.rollout_s += time.perf_counter() - self._rollout_start

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        self.total_s = time.perf_counter() - self._training_start

    def split(self) -> dict[str, float]:
        """Seconds and shares of the training time: env steps, the rest of the rollouts (policy
        inference, buffers, wrappers), and updates plus callbacks (module docstring)."""
        total = self.total_s or (time.perf_counter() - self._training_start)
        worker = self.worker
        if worker is not None:
            parts = {"env_step_s": worker.env_step_s, "rollout_other_s": max(worker.fly_s - worker.env_step_s, 0.0),
                     "waiting_for_rollouts_s": worker.waited_s,
                     "update_and_callbacks_s": max(total - worker.waited_s, 0.0)}
        else:
            env_s = self._env_time() - self._env_time_at_start
            parts = {"env_step_s": env_s, "rollout_other_s": max(self.rollout_s - env_s, 0.0),
                     "update_and_callbacks_s": max(total - self.rollout_s, 0.0)}
        out = {k: round(v, 2) for k, v in parts.items()}
        out.update({k[:-2] + "_share": round(v / total, 3) if total > 0 else 0.0 for k, v in parts.items()})
        out["total_s"] = round(total, 2)
        return out
