"""Many vehicles in one Gymnasium ``VectorEnv``: one compiled call steps them all.

::

    envs = gym.make_vec("WallInspector/WallSweep-v0", num_envs=1024,
                        vectorization_mode="vector_entry_point")
    obs, info = envs.reset(seed=0)              # env k seeded with 0 + k
    obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())

:class:`WallInspectorVectorEnv` takes the single env's keywords (checked by the same
:class:`~wall_env.config.EnvConfig`) and runs ``num_envs`` episodes in an
:class:`~wall_env.batch.EnvBatch`: the same compiled control step, contact response,
observation, reward and info code as :class:`~wall_env.env.WallInspectorEnv`, on rows.
Env ``k`` reset with seed ``s`` flies exactly as a single env reset with seed ``s``
given the same actions. Domain randomisation (``randomize=...``) is drawn per env at
each of its resets.

Autoreset: Gymnasium 1.x's default, next-step (``metadata["autoreset_mode"]``). The step
that ends an episode returns its last observation; the env's next ``step`` ignores
its action, starts a new episode and returns the first observation with reward 0
and ``terminated = truncated = False``. ``reset(options={"reset_mask": mask})`` resets
only the envs where ``mask`` is true.

Infos are a dict of arrays (one row per env, Gymnasium's vector layout) with the
single env's keys, each with its ``_key`` mask (all true: every env reports every key).
No rendering (``render_mode`` must be None): render a single env for pictures.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from wall_env.batch import EnvBatch, check_actions
from wall_env.config import EnvConfig
from wall_env.env import check_reset_options
from wall_env.observation import OBSERVATION_SIZE, observation_bounds
from wall_env.streams import stream_key

__all__ = ["WallInspectorVectorEnv"]

_MAX_ENVS = 1_000_000


def _with_masks(info: dict[str, Any], n: int) -> dict[str, Any]:
    """Gymnasium's vector info layout: each key beside a ``_key`` boolean mask."""
    out: dict[str, Any] = {}
    everyone = np.ones(n, dtype=bool)
    for key, value in info.items():
        out[key] = _with_masks(value, n) if isinstance(value, dict) else value
        out[f"_{key}"] = everyone
    return out


class WallInspectorVectorEnv(VectorEnv):
    """``num_envs`` Wall Inspector episodes stepped together; see the module docstring.

    Parameters: ``num_envs``, ``task``, ``max_episode_steps`` (episodes are truncated at
    this many steps or at the reference's end, whichever comes first) and every keyword
    of :class:`~wall_env.env.WallInspectorEnv`.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": [], "render_fps": 100}

    def __init__(self, num_envs: int = 1, task: str = "WallHover", *, max_episode_steps: int | None = None,
                 **kwargs: Any):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or not 1 <= num_envs <= _MAX_ENVS:
            raise ValueError(f"num_envs must be an integer in [1, {_MAX_ENVS}], got {num_envs!r}")
        if max_episode_steps is not None and (isinstance(max_episode_steps, bool) or not isinstance(
                max_episode_steps, (int, np.integer)) or max_episode_steps < 1):
            raise ValueError(f"max_episode_steps must be a positive integer or None, got {max_episode_steps!r}")
        if kwargs.get("render_mode") is not None:
            raise ValueError("the vector env does not render (render_mode must be None); "
                             "make a single env with render_mode='rgb_array' for pictures")
        self.config = EnvConfig.from_kwargs(task, **kwargs)
        self.num_envs = int(num_envs)
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.config.control_dt}
        self.render_mode = None
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self.single_observation_space = spaces.Box(*observation_bounds(), shape=(OBSERVATION_SIZE,),
                                                   dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.batch = EnvBatch(self.config, self.num_envs)
        self._all = np.arange(self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._seeded = False

    # ------------------------------------------------------------------ public settings (as the single env's)
    @property
    def vehicle(self):
        return self.config.vehicle

    @property
    def action_mapping(self):
        return self.config.action_mapping

    @property
    def control_dt(self) -> float:
        return self.config.control_dt

    @property
    def nominal_model(self):
        return self.config.nominal_model

    @property
    def task(self):
        return self.config.task

    @property
    def scene(self):
        """The configured scene (each env's current one: :meth:`scene_and_reference`)."""
        return self.batch.configured[0]

    @property
    def reference(self):
        """The configured reference (each env's current one: :meth:`scene_and_reference`)."""
        return self.batch.configured[1]

    def scene_and_reference(self, index: int):
        """Scene and reference of env ``index``'s current episode, as the single env rebuilds them at
        its reset (a randomised stand-off moves both); what controllers read at episode starts."""
        standoff = self.batch.episode_parameters.get("standoff")
        if standoff is None:
            return self.batch.configured
        return self.config.build(float(standoff[index]))

    @property
    def episode_parameters(self) -> dict[str, np.ndarray]:
        """The randomised settings of each env's current episode (arrays of ``num_envs``)."""
        return {k: v.copy() for k, v in self.batch.episode_parameters.items()}

    # ------------------------------------------------------------------ Gymnasium API
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        if self.closed:
            raise RuntimeError("reset() after close(): this vector env is closed; make a new one")
        spread = check_reset_options(options, ("perturb_start", "reset_mask"))
        rows: np.ndarray | slice = slice(None)
        if options and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"])
            if mask.dtype != bool or mask.shape != (self.num_envs,):
                raise ValueError(f"reset option reset_mask must be a bool array of shape ({self.num_envs},), "
                                 f"got {mask.dtype} {mask.shape}")
            rows = np.flatnonzero(mask)
        seeds = self._seeds(seed)
        if seeds is not None:
            self.batch.streams.seed(self._all[rows], [seeds[k] for k in self._all[rows]])
            self._np_random, self._np_random_seed = seeding.np_random(seeds[0] if seeds[0] is not None else None)
        elif not self._seeded:
            self.batch.streams.seed(self._all, [None] * self.num_envs)
        self._seeded = True
        self.batch.reset(rows, spread)
        self._autoreset[rows] = False
        return self.batch.observations(), _with_masks(self.batch.infos(), self.num_envs)

    def step(self, actions):
        if self.closed:
            raise RuntimeError("step() after close(): this vector env is closed; make a new one")
        if not self._seeded:
            raise RuntimeError("step() before reset(): call reset() first")
        a = check_actions(actions, self.num_envs)
        restarting = self._autoreset
        batch = self.batch
        reward, terminated, truncated = batch.step(a, ~restarting if restarting.any() else None)
        if self.max_episode_steps is not None:
            truncated |= ~terminated & (batch.step_index >= self.max_episode_steps)
        if restarting.any():
            rows = np.flatnonzero(restarting)
            batch.reset(rows)
            reward[rows] = 0.0
            terminated[rows] = False
            truncated[rows] = False
        self._autoreset = terminated | truncated
        return (batch.observations(), reward, terminated, truncated,
                _with_masks(batch.infos(), self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        self._seeded = False
        self.batch.close()

    # ------------------------------------------------------------------ internals
    def _seeds(self, seed: int | list[int | None] | None) -> list[int | None] | None:
        if seed is None:
            return None
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            stream_key(seed)  # checks it
            return [int(seed) + k for k in range(self.num_envs)]
        if isinstance(seed, (list, tuple)) and len(seed) == self.num_envs:
            for s in seed:
                if s is not None:
                    stream_key(s)
            return list(seed)
        raise ValueError(f"seed must be None, a non-negative integer or a list of {self.num_envs} of them, "
                         f"got {seed!r}")

