"""Demonstrations: a controller flies the batched env and its (observation, action) pairs are recorded.

::

    venv = BatchedVecEnv("WallInspector/WallSweep-v0", 128)
    expert = SCMPC.from_env(venv, preset="tuned")
    demos = record_demonstrations(venv, expert, steps=1700, noise=0.1, seed=0)

The controller answers for the whole batch with one ``predict`` call per step (its
per-env memory is cleared at each env's episode start, as in
:class:`~agents.residual.ResidualVecEnv`). Exploration is DART-style (Laskey et al.,
2017): the env is flown with the controller's action plus Gaussian noise, but the
*clean* action is what gets recorded, so a policy cloned from the data also sees how the
controller recovers from the deviations the noise causes. Each env gets its own noise
level, spread evenly from 0 (the controller's own flight) to ``noise`` (in units of the
normalised action range ``[-1, 1]``).

The rewards, terminations and time-limit ends are recorded too, for fitting a critic
(:func:`discounted_returns`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

__all__ = ["Demonstrations", "record_demonstrations", "discounted_returns"]


@dataclass
class Demonstrations:
    """What a controller did, step by step, in ``n_envs`` envs side by side (arrays ``(steps, n_envs, ...)``).

    ``actions`` are the controller's clean actions (what a policy should learn), ``applied``
    the noisy ones the env was flown with; ``dones`` mark episode ends after a step
    (``truncated`` those that were time limits, not failures). ``wall_time_s``: time spent recording.
    """

    observations: np.ndarray
    actions: np.ndarray
    applied: np.ndarray
    rewards: np.ndarray
    dones: np.ndarray
    truncated: np.ndarray
    noise: np.ndarray  # (n_envs,) std of the noise added in each env
    wall_time_s: float

    @property
    def n_samples(self) -> int:
        return int(self.observations.shape[0] * self.observations.shape[1])

    def flat(self) -> tuple[np.ndarray, np.ndarray]:
        """Observations ``(n_samples, obs_size)`` and clean actions ``(n_samples, act_size)``."""
        return (self.observations.reshape(self.n_samples, -1), self.actions.reshape(self.n_samples, -1))

    def join(self, other: Demonstrations) -> Demonstrations:
        """These flights and ``other``'s side by side (as more envs; both must have the same number of steps)."""
        if other.observations.shape[0] != self.observations.shape[0]:
            raise ValueError(f"demonstrations of {self.observations.shape[0]} and {other.observations.shape[0]} steps "
                             "cannot be joined env by env")
        def side_by_side(name: str) -> np.ndarray:
            return np.concatenate([getattr(self, name), getattr(other, name)], axis=1)

        return Demonstrations(side_by_side("observations"), side_by_side("actions"), side_by_side("applied"),
                              side_by_side("rewards"), side_by_side("dones"), side_by_side("truncated"),
                              np.concatenate([self.noise, other.noise]), self.wall_time_s + other.wall_time_s)


def record_demonstrations(venv: VecEnv, controller: Any, steps: int, noise: float = 0.0, seed: int = 0,
                          pilot: Callable[[np.ndarray], np.ndarray] | None = None) -> Demonstrations:
    """Fly ``controller`` (SB3-style ``predict`` over a batch) for ``steps`` steps of ``venv``
    (an SB3 ``VecEnv`` that resets finished envs itself); see the module docstring.

    ``pilot``: another policy flies instead (``pilot(observations) -> actions`` for the batch, plus
    the noise), and ``controller`` labels the states it reaches, answering every step so that its
    memory follows the flight (DAgger: the expert relabels the student's states).

    ``noise``: the largest per-env std of the Gaussian noise added to the applied action
    (normalised units, >= 0); ``seed`` seeds the env (env ``k`` resets with seed ``seed + k``, as
    SB3's ``VecEnv.seed``) and the noise.
    """
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    if isinstance(noise, bool) or not isinstance(noise, (int, float)) or not 0.0 <= noise <= 1.0:
        raise ValueError(f"noise must be a number in [0, 1] (std in normalised action units), got {noise!r}")
    start = time.perf_counter()
    n = venv.num_envs
    rng = np.random.default_rng(seed)
    sigma = np.linspace(0.0, float(noise), n) if n > 1 else np.array([float(noise)])
    obs_space, act_space = venv.observation_space, venv.action_space
    if not (isinstance(obs_space, spaces.Box) and isinstance(act_space, spaces.Box)):
        raise ValueError(f"demonstrations need Box observation and action spaces, got {obs_space} and {act_space}")
    obs_size, act_size = obs_space.shape[0], act_space.shape[0]
    observations = np.empty((steps, n, obs_size), dtype=np.float32)
    actions = np.empty((steps, n, act_size), dtype=np.float32)
    applied = np.empty((steps, n, act_size), dtype=np.float32)
    rewards = np.empty((steps, n), dtype=np.float32)
    dones = np.empty((steps, n), dtype=bool)
    truncated = np.zeros((steps, n), dtype=bool)
    low, high = act_space.low, act_space.high

    venv.seed(seed)
    obs = np.asarray(venv.reset())
    episode_start = np.ones(n, dtype=bool)
    for t in range(steps):
        clean, _ = controller.predict(obs, state=None, episode_start=episode_start, deterministic=True)
        clean = np.asarray(clean, dtype=np.float32).reshape(n, act_size)
        flown = clean if pilot is None else np.asarray(pilot(obs), dtype=np.float32).reshape(n, act_size)
        noisy = np.clip(flown + sigma[:, None] * rng.standard_normal((n, act_size)), low, high).astype(np.float32)
        observations[t], actions[t], applied[t] = obs, clean, noisy
        next_obs, reward, done, infos = venv.step(noisy)
        obs = np.asarray(next_obs)
        rewards[t], dones[t] = reward, done
        for k in np.flatnonzero(done):
            truncated[t, k] = bool(infos[k].get("TimeLimit.truncated", False))
        episode_start = np.asarray(done, dtype=bool)
    return Demonstrations(observations, actions, applied, rewards, dones, truncated, sigma.astype(np.float32),
                          time.perf_counter() - start)


def discounted_returns(rewards: np.ndarray, dones: np.ndarray, truncated: np.ndarray, gamma: float,
                       tail_value: float | None = None) -> np.ndarray:
    """Discounted returns ``G_t = r_t + gamma G_{t+1}`` of ``(steps, n_envs)`` rewards, as PPO's critic
    should predict them.

    A termination ends the sum (``G`` of its step is its reward). A time-limit end and the
    end of the recording cut a flight that would have gone on; there the sum goes on with
    ``tail_value`` (``G_t = r_t + gamma * tail_value``, as PPO bootstraps a time-limit end
    with the critic's value). Default: the mean reward over ``1 - gamma``, the return of a
    flight that goes on as the recorded ones did on average.
    """
    rewards = np.asarray(rewards, dtype=np.float64)
    if not 0.0 < gamma < 1.0:
        raise ValueError(f"gamma must be in (0, 1), got {gamma!r}")
    tail = float(np.mean(rewards)) / (1.0 - gamma) if tail_value is None else float(tail_value)
    steps = rewards.shape[0]
    returns = np.empty_like(rewards)
    following = np.full(rewards.shape[1], tail)
    for t in range(steps - 1, -1, -1):
        cut = np.asarray(truncated[t], dtype=bool) | (t == steps - 1)
        ended = np.asarray(dones[t], dtype=bool) & ~cut
        following = np.where(cut, tail, np.where(ended, 0.0, following))
        following = rewards[t] + gamma * following
        returns[t] = following
    return returns
