"""Training callbacks: progress bar, periodic checkpoints (by env steps and by wall time),
evaluations on the same episodes every time, saving the best model.

Each checkpoint is written with :func:`agents.checkpoints.save_checkpoint`, so the
normalisation statistics always travel with the model and every checkpoint (periodic,
best, final) can be loaded by :func:`agents.load_policy` or resumed from.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

from agents.checkpoints import save_checkpoint

__all__ = ["ProgressBar", "PeriodicCheckpoint", "SameEpisodesEval", "SaveBestCheckpoint", "TrainingClock", "CollisionLog", "TorchThreads",
           "policy_info", "rollout_thread_cap", "ROLLOUT_ROWS_PER_THREAD"]


class TrainingClock:
    """Cumulative training wall time (s) and timesteps, carried across resumed runs."""

    def __init__(self, previous_wall_time_s: float = 0.0):
        self.previous = float(previous_wall_time_s)
        self.start = time.perf_counter()

    @property
    def this_run_s(self) -> float:
        return time.perf_counter() - self.start

    @property
    def total_s(self) -> float:
        return self.previous + self.this_run_s


class ProgressBar(BaseCallback):
    """A tqdm bar over environment steps, showing the current throughput."""

    def __init__(self, total_timesteps: int, initial: int = 0):
        super().__init__()
        self.total, self.initial = int(total_timesteps), int(initial)
        self.bar: Any = None

    def _on_training_start(self) -> None:
        from tqdm.auto import tqdm

        self.bar = tqdm(total=self.total, initial=self.initial, unit="step", unit_scale=True, dynamic_ncols=True,
                        desc="PPO")

    def _on_step(self) -> bool:
        if self.bar is not None:
            self.bar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()


def policy_info(model, clock: TrainingClock, base_info: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """``base_info`` (the policy description) with the model's step count and the training wall time so far:
    what a checkpoint's ``policy.json`` holds."""
    return {**base_info, "num_timesteps": int(model.num_timesteps), "wall_time_s": round(clock.total_s, 3), **extra}


class PeriodicCheckpoint(BaseCallback):
    """Save a checkpoint into ``folder/<steps>/`` every ``every`` env steps and whenever
    ``every_s`` seconds of wall time have passed since the last one (0 turns either off),
    so that a long run loses little however it ends."""

    def __init__(self, folder: Path, every: int, policy_info: dict[str, Any], clock: TrainingClock,
                 check_observations: np.ndarray, every_s: float = 0.0, on_save: Callable[[Path], object] | None = None):
        super().__init__()
        self.on_save = on_save  # called with each checkpoint folder written (e.g. to hand it to Ray Tune)
        self.folder, self.every, self.every_s = Path(folder), int(every), float(every_s)
        self.policy_info, self.clock, self.check_observations = policy_info, clock, check_observations
        self._next_steps = 0
        self._last_save = 0.0
        self.saved: list[Path] = []

    def _on_training_start(self) -> None:
        if self.every > 0:
            self._next_steps = (self.model.num_timesteps // self.every + 1) * self.every
        self._last_save = time.perf_counter()

    def _on_step(self) -> bool:
        by_steps = self.every > 0 and self.model.num_timesteps >= self._next_steps
        by_time = self.every_s > 0 and time.perf_counter() - self._last_save >= self.every_s
        if by_steps or by_time:
            self.save()
            while self.every > 0 and self._next_steps <= self.model.num_timesteps:
                self._next_steps += self.every
        return True

    def save(self) -> Path:
        """Write a checkpoint now, into ``folder/<steps>/``."""
        folder = self.folder / f"{self.model.num_timesteps:09d}"
        vec_normalize = self.model.get_vec_normalize_env()
        save_checkpoint(folder, self.model, vec_normalize, policy_info(self.model, self.clock, self.policy_info),
                        self.check_observations)
        self._last_save = time.perf_counter()
        self.saved.append(folder)
        if self.on_save is not None:
            self.on_save(folder)
        return folder


class SameEpisodesEval(EvalCallback):
    """``EvalCallback`` whose every evaluation flies the same episodes: its env is seeded with
    ``episode_seed`` before each, so a checkpoint is judged on the starts and noise the others met,
    not on luckier ones (``EvalCallback`` alone seeds once and draws on)."""

    def __init__(self, eval_env: Any, episode_seed: int, **kwargs: Any):
        super().__init__(eval_env, **kwargs)
        self.episode_seed = int(episode_seed)

    def rewind(self) -> None:
        """Seed the env so that its next evaluation flies the episodes every evaluation flies."""
        self.eval_env.seed(self.episode_seed)

    def _on_step(self) -> bool:
        if self.eval_freq > 0 and self.n_calls % self.eval_freq == 0:
            self.rewind()
        return super()._on_step()


class SaveBestCheckpoint(BaseCallback):
    """Child of ``EvalCallback``: on a new best mean evaluation return, save into ``folder``."""

    def __init__(self, folder: Path, policy_info: dict[str, Any], clock: TrainingClock, check_observations: np.ndarray,
                 on_save: Callable[[], None] | None = None):
        super().__init__()
        self.folder = Path(folder)
        self.policy_info, self.clock, self.check_observations = policy_info, clock, check_observations
        self.on_save = on_save

    def _on_step(self) -> bool:
        best = float(getattr(self.parent, "best_mean_reward", np.nan))
        save_checkpoint(self.folder, self.model, self.model.get_vec_normalize_env(),
                        policy_info(self.model, self.clock, self.policy_info, eval_mean_return=best),
                        self.check_observations)
        if self.on_save is not None:
            self.on_save()
        return True


class CollisionLog(BaseCallback):
    """Logs ``rollout/collisions_per_episode`` and ``rollout/collision_episode_fraction``
    (over Stable-Baselines3's buffer of recent episodes) to TensorBoard at each rollout end."""

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        counts = [info["collisions"] for info in self.model.ep_info_buffer or () if "collisions" in info]
        if counts:
            self.logger.record("rollout/collisions_per_episode", float(np.mean(counts)))
            self.logger.record("rollout/collision_episode_fraction", float(np.mean(np.asarray(counts) > 0)))


ROLLOUT_ROWS_PER_THREAD = 512  # below this many observations per thread, the policy's forward pass is no faster split


def rollout_thread_cap(n_envs: int) -> int:
    """The most PyTorch threads that help while rollouts are collected: the policy acts on ``n_envs``
    observations at a time, and on a few hundred rows one thread is faster than two (the sweep's 32:
    measured with the earlier fixed settings)."""
    return max(1, int(n_envs) // ROLLOUT_ROWS_PER_THREAD)


class TorchThreads(BaseCallback):
    """PyTorch's threads for each phase of training, by the rule of :mod:`controllers.threads`.

    ``rollout`` and ``update``: ``"auto"`` or an explicit number (which wins). With ``"auto"`` the
    cores free to this process are measured again at the end of every rollout, over the time since
    the previous one (a :class:`~controllers.threads.CpuWatch`, no waiting), so a run that meets a
    busy machine halfway drops to one thread for its next update and takes two again when the
    neighbour has gone. Rollouts use at most :func:`rollout_thread_cap` threads. :meth:`report`
    says what was chosen and why, for the model card.
    """

    def __init__(self, rollout: int | str, update: int | str, n_envs: int, most: int | None = None):
        super().__init__()
        from controllers.threads import check_thread_setting

        self.rollout = check_thread_setting(rollout, "rollout_torch_threads")
        self.update = check_thread_setting(update, "torch_threads")
        self.n_envs, self.most = int(n_envs), most
        self.watch: Any = None
        self.first: dict[str, Any] = {}
        self.counts: dict[str, dict[int, int]] = {"rollout": {}, "update": {}}
        self.busy_seen: list[float] = []

    def _choice(self, phase: str, setting: int | str, most: int | None) -> int:
        from controllers.threads import choose_threads

        choice = choose_threads(setting, most=most, watch=self.watch)
        if choice.busy_elsewhere is not None:
            self.busy_seen.append(choice.busy_elsewhere)
        self.first.setdefault(phase, choice.as_dict())
        self.counts[phase][choice.threads] = self.counts[phase].get(choice.threads, 0) + 1
        return choice.threads

    def _set(self, threads: int) -> None:
        import torch

        if torch.get_num_threads() != threads:
            torch.set_num_threads(threads)

    def _on_training_start(self) -> None:
        from controllers.threads import CpuWatch

        self.watch = CpuWatch()

    def _on_rollout_start(self) -> None:
        cap = rollout_thread_cap(self.n_envs) if self.most is None else min(rollout_thread_cap(self.n_envs), self.most)
        threads = self.rollout if self.rollout != "auto" else 1 if cap == 1 else None
        if threads is None:  # several threads could help: what is free? (measured over the last update)
            threads = self._choice("rollout", "auto", cap)
        else:
            self.counts["rollout"][int(threads)] = self.counts["rollout"].get(int(threads), 0) + 1
            self.first.setdefault("rollout", {"threads": int(threads), "setting": self.rollout, "reason": (
                "set explicitly" if self.rollout != "auto" else
                f"the policy acts on {self.n_envs} observations at a time: one thread is faster below "
                f"{ROLLOUT_ROWS_PER_THREAD} per thread")})
        self._set(int(threads))

    def _on_rollout_end(self) -> None:
        self._set(self._choice("update", self.update, self.most))

    def _on_step(self) -> bool:
        return True

    def report(self) -> dict[str, Any]:
        """For the model card: the settings, the first choice of each phase with its reason, how many
        rollouts and updates ran on each number of threads, and the others' load seen (cores)."""
        out: dict[str, Any] = {"settings": {"rollout": self.rollout, "update": self.update}, "first_choice": self.first,
                               "rollouts_on_threads": {str(k): v for k, v in sorted(self.counts["rollout"].items())},
                               "updates_on_threads": {str(k): v for k, v in sorted(self.counts["update"].items())}}
        if self.busy_seen:
            out["busy_elsewhere_cores"] = {"median": round(float(np.median(self.busy_seen)), 2),
                                           "max": round(float(np.max(self.busy_seen)), 2)}
        return out
