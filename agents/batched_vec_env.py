"""Stable-Baselines3's ``VecEnv`` on the batched Wall Inspector env: one process, one compiled call per step.

:class:`BatchedVecEnv` puts the rows of a :class:`~wall_env.vector_env.WallInspectorVectorEnv`
(the same physics, observation, reward and info code as the single env) behind SB3's
``VecEnv`` interface, so PPO, ``VecNormalize``, ``VecMonitor``, ``EvalCallback`` and
``evaluate_policy`` take it like any vector env::

    venv = VecMonitor(BatchedVecEnv("WallInspector/WallSweep-v0", 256), info_keywords=("collisions",))

SB3's semantics differ from Gymnasium's next-step autoreset: an env that ends an episode
is reset in the same step, its last observation goes to ``info["terminal_observation"]``
and ``info["TimeLimit.truncated"]`` tells a time-limit end from a termination. Infos
are empty dicts except at episode ends, where they also carry ``info_keys`` from the
env's info (default ``collisions``), because SB3 wants one dict per env and building
the full info for every env would cost more than the step.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

import wall_env  # noqa: F401  (registers the tasks)
from wall_env.batch import check_actions
from wall_env.env import check_reset_options
from wall_env.vector_env import WallInspectorVectorEnv

__all__ = ["BatchedVecEnv"]


class BatchedVecEnv(VecEnv):
    """``n_envs`` rows of the batched env ``env_id`` (built with ``env_kwargs``) as an SB3 ``VecEnv``."""

    def __init__(self, env_id: str, n_envs: int, info_keys: Sequence[str] = ("collisions",), **env_kwargs: Any):
        vector_env = gym.make_vec(env_id, num_envs=n_envs, vectorization_mode="vector_entry_point", **env_kwargs)
        if not isinstance(vector_env, WallInspectorVectorEnv):
            raise ValueError(f"{env_id} is not a Wall Inspector task (its vector env is {type(vector_env).__name__})")
        self.vector_env = vector_env
        self.batch = vector_env.batch
        self.info_keys = tuple(info_keys)
        self._max_steps = vector_env.max_episode_steps
        self._actions: np.ndarray | None = None
        self._seeded = False
        self.step_time_s = 0.0  # time spent in step_wait (for agents.timing.TimeSplit)
        super().__init__(n_envs, self.vector_env.single_observation_space, self.vector_env.single_action_space)

    # ------------------------------------------------------------------ stepping
    def reset(self):
        batch = self.batch
        everyone = np.arange(self.num_envs)
        seeded = [k for k, s in enumerate(self._seeds) if s is not None]
        if seeded:
            batch.streams.seed(seeded, [self._seeds[k] for k in seeded])
        if not self._seeded:
            fresh = [k for k in everyone if self._seeds[k] is None]
            if fresh:
                batch.streams.seed(fresh, [None] * len(fresh))
            self._seeded = True
        spread = np.array([check_reset_options(o or None) for o in self._options])
        batch.reset(everyone, spread)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return batch.observations()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = check_actions(actions, self.num_envs)

    def step_wait(self) -> VecEnvStepReturn:
        start = time.perf_counter()
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async(): call step(actions)")
        batch = self.batch
        reward, terminated, truncated = batch.step(self._actions)
        if self._max_steps is not None:
            truncated |= ~terminated & (batch.step_index >= self._max_steps)
        dones = terminated | truncated
        obs = batch.observations()
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            rows = np.flatnonzero(dones)
            ended = batch.infos() if self.info_keys else {}
            last = obs[rows].copy()
            for j, k in enumerate(rows):
                info = {key: ended[key][k].item() if ended[key].ndim == 1 else ended[key][k]
                        for key in self.info_keys}
                info["terminal_observation"] = last[j]
                info["TimeLimit.truncated"] = bool(truncated[k] and not terminated[k])
                infos[k] = info
            batch.reset(rows)
            obs[rows] = batch.observations(rows)
        self.step_time_s += time.perf_counter() - start
        return obs, reward.astype(np.float32), dones, infos

    def close(self) -> None:
        self.vector_env.close()

    # ------------------------------------------------------------------ attributes (shared by every row)
    def _count(self, indices: VecEnvIndices) -> int:
        return len(list(self._get_indices(indices)))

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self.vector_env.unwrapped, attr_name)
        return [value] * self._count(indices)

    def scene_and_reference(self, index: int):
        """Scene and reference of env ``index``'s current episode (controllers read them at episode starts)."""
        return self.vector_env.unwrapped.scene_and_reference(index)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        if self._count(indices) != self.num_envs:
            raise ValueError("the rows of a batched env share their attributes: set them for all envs at once")
        setattr(self.vector_env.unwrapped, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        method = getattr(self.vector_env.unwrapped, method_name)
        return [method(*method_args, **method_kwargs) for _ in range(self._count(indices))]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * self._count(indices)

    def get_images(self) -> Sequence[np.ndarray | None]:
        raise NotImplementedError("the batched env does not render; render a single env (render_mode='rgb_array')")
