"""Residual control: PPO learns a bounded correction on top of a base controller.

The base controller (PID or SC-MPC from :mod:`controllers`) already flies the task;
the agent only has to learn what the base gets wrong near the wall. Applied action::

    a = clip(a_base(obs) + scale * clip(c, -1, 1), -1, 1)

with ``a_base`` the base controller's normalised action, ``c`` the agent's action
(``Box(-1, 1, (4,))``) and ``scale`` the largest correction per entry (default 0.2 of
the normalised range: 3.4 N of thrust, 0.6 rad/s of body rate). An untrained agent
(``c`` near 0) therefore flies like the base controller, which is why residual agents
learn quickly.

The agent observes the environment's 48 entries followed by the base action (4
entries), so it can tell what it is correcting. The training wrappers
(:class:`ResidualActionWrapper` around one env, one base controller per env, built
inside the worker process; :class:`ResidualVecEnv` around the batched env, one base
controller answering for the whole batch with one ``predict`` call per step) and the
deployed policy (:class:`ResidualPolicy`) use :func:`combine` and
:func:`augment_observation`, so training and deployment apply the same arithmetic.

Base controllers follow the Stable-Baselines3 predict protocol:
``predict(obs, state=None, episode_start=None, deterministic=True) -> (action, state)``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

__all__ = [
    "BASE_CONTROLLERS",
    "make_base_controller",
    "combine",
    "augment_observation",
    "ResidualActionWrapper",
    "ResidualVecEnv",
    "ResidualPolicy",
]

BASE_CONTROLLERS = ("pid", "scmpc")


def make_base_controller(name: str, env: gym.Env | VecEnv, **kwargs: Any):
    """Build base controller ``name`` (``"pid"`` or ``"scmpc"``) for ``env`` with the
    :mod:`controllers` package's ``from_env`` constructors. ``threads="auto"`` (SC-MPC's threads
    over a batch's rows) becomes the number :func:`controllers.threads.choose_threads` gives now."""
    if name not in BASE_CONTROLLERS:
        raise ValueError(f"residual base must be one of {BASE_CONTROLLERS}, got {name!r}")
    try:
        import controllers
    except ImportError as exc:  # pragma: no cover - controllers ships with this repository
        raise ImportError(f"residual base {name!r} needs the controllers package: {exc}") from exc
    class_name = {"pid": "PID", "scmpc": "SCMPC"}[name]
    cls = getattr(controllers, class_name, None)
    if cls is None and name == "pid":  # before the package exports it at the top level
        try:
            from controllers.pid import PID as cls
        except ImportError:
            cls = None
    if cls is None:
        raise ImportError(f"controllers.{class_name} is not available; residual base {name!r} cannot be built")
    if kwargs.get("threads") == "auto":  # SC-MPC's solver threads for a batch: the cores free now (controllers.threads)
        from controllers.threads import choose_threads

        kwargs = {**kwargs, "threads": choose_threads().threads}
    return cls.from_env(env.unwrapped, **kwargs)


def combine(base_action: np.ndarray, correction: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``clip(base + scale * clip(correction, -1, 1), -1, 1)``, for one action or a batch."""
    c = np.clip(np.asarray(correction, dtype=np.float64), -1.0, 1.0)
    return np.clip(np.asarray(base_action, dtype=np.float64) + np.asarray(scale, dtype=np.float64) * c, -1.0, 1.0)


def augment_observation(obs: np.ndarray, base_action: np.ndarray) -> np.ndarray:
    """The residual agent's observation: the env's observation followed by the base action."""
    return np.concatenate([np.asarray(obs, dtype=np.float32), np.asarray(base_action, dtype=np.float32)], axis=-1)


def _augmented_space(inner: gym.Space) -> spaces.Box:
    if not isinstance(inner, spaces.Box):
        raise ValueError(f"a residual agent needs a Box observation space, got {inner}")
    low = np.concatenate([inner.low, -np.ones(4, dtype=np.float32)])
    high = np.concatenate([inner.high, np.ones(4, dtype=np.float32)])
    return spaces.Box(low, high, dtype=np.float32)


def _scale(scale: float | np.ndarray) -> np.ndarray:
    out = np.broadcast_to(np.asarray(scale, dtype=np.float64), (4,)).copy()
    if not np.all(out > 0):
        raise ValueError(f"scale must be positive, got {out.tolist()}")
    return out


def _base_predict(base, obs, state, episode_start):
    action, state = base.predict(obs, state=state, episode_start=episode_start, deterministic=True)
    return np.asarray(action, dtype=np.float64).reshape(np.shape(obs)[:-1] + (4,)), state


class ResidualActionWrapper(gym.Wrapper):
    """Environment whose action is a correction to ``base``'s action (see module docstring).

    Parameters
    ----------
    env: a wall environment (``Box(-1, 1, (4,))`` actions).
    base: the base controller, or a function ``env -> controller`` called here (so that
        inside a subprocess the controller is built in that process).
    scale: largest correction per action entry, a number or 4 numbers.

    ``info`` gains ``base_action``, ``residual_correction`` (the clipped agent action)
    and ``applied_action``.
    """

    def __init__(self, env: gym.Env, base: Any | Callable[[gym.Env], Any], scale: float | np.ndarray = 0.2):
        super().__init__(env)
        self.base = base(env) if callable(base) and not hasattr(base, "predict") else base
        self.scale = _scale(scale)
        self.observation_space = _augmented_space(env.observation_space)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self._base_state = None
        self._base_action = np.zeros(4)

    def _observe(self, obs: np.ndarray, episode_start: bool) -> np.ndarray:
        self._base_action, self._base_state = _base_predict(
            self.base, obs, self._base_state, np.array([episode_start]))
        return augment_observation(obs, self._base_action)

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._base_state = None
        return self._observe(obs, True), info

    def step(self, action):
        correction = np.clip(np.asarray(action, dtype=np.float64).reshape(4), -1.0, 1.0)
        base_action = self._base_action
        applied = combine(base_action, correction, self.scale)
        obs, reward, terminated, truncated, info = self.env.step(applied)
        info["base_action"] = base_action.copy()
        info["residual_correction"] = correction
        info["applied_action"] = applied
        return self._observe(obs, False), reward, terminated, truncated, info


class ResidualVecEnv(VecEnvWrapper):
    """A Stable-Baselines3 ``VecEnv`` whose actions are corrections to ``base``'s actions, for a whole batch.

    The vector-env counterpart of :class:`ResidualActionWrapper` for the batched env
    (:class:`~agents.batched_vec_env.BatchedVecEnv`): after each step the base controller
    predicts for all ``n`` envs in one call (SC-MPC solves them in one compiled call), with
    ``episode_start`` set for the envs that were just reset. Observations are augmented
    with the base action as in the single-env wrapper.

    ``base``: the base controller, or a function ``venv -> controller`` called here.
    The ``terminal_observation`` of an env that ended an episode carries the base action
    chosen at the step before (the env has already been reset, and asking the base
    controller about the last state of the old episode would disturb its memory of the
    others); it only enters PPO's value bootstrap at time-limit ends.
    """

    def __init__(self, venv: VecEnv, base: Any | Callable[[VecEnv], Any], scale: float | np.ndarray = 0.2):
        super().__init__(venv, observation_space=_augmented_space(venv.observation_space),
                         action_space=spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32))
        self.base = base(venv) if callable(base) and not hasattr(base, "predict") else base
        self.scale = _scale(scale)
        self._base_action = np.zeros((self.num_envs, 4))
        self.base_time_s = 0.0  # time spent in the base controller's predict

    @property
    def step_time_s(self) -> float:
        """Seconds spent stepping: the wrapped env's own count (if it keeps one) plus the base controller's."""
        return float(getattr(self.venv, "step_time_s", 0.0)) + self.base_time_s

    def _observe(self, obs: np.ndarray, episode_start: np.ndarray) -> np.ndarray:
        start = time.perf_counter()
        self._base_action, _ = _base_predict(self.base, obs, None, episode_start)
        self.base_time_s += time.perf_counter() - start
        return augment_observation(obs, self._base_action)

    def reset(self) -> np.ndarray:
        obs = np.asarray(self.venv.reset())
        return self._observe(obs, np.ones(self.num_envs, dtype=bool))

    def step_async(self, actions: np.ndarray) -> None:
        applied = combine(self._base_action, np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 4),
                          self.scale)
        self.venv.step_async(applied.astype(np.float32))

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        previous = self._base_action
        for k in np.flatnonzero(dones):
            if "terminal_observation" in infos[k]:
                infos[k]["terminal_observation"] = augment_observation(infos[k]["terminal_observation"], previous[k])
        return self._observe(np.asarray(obs), dones), rewards, dones, infos


class ResidualPolicy:
    """A deployed residual agent: base controller plus the trained correction policy.

    ``predict`` takes the environment's plain observation (one ``(48,)`` or a batch
    ``(n, 48)``), asks the base controller, feeds the augmented observation to
    ``correction`` (an object with SB3-style ``predict``) and returns the combined
    action. The base controller's recurrent state travels in ``state``.
    """

    def __init__(self, base: Any, correction: Any, scale: float | np.ndarray, name: str = "residual",
                 base_name: str | None = None):
        self.base = base
        self.base_name = base_name  # "pid" or "scmpc" when loaded from a checkpoint
        self.correction = correction
        self.scale = np.broadcast_to(np.asarray(scale, dtype=np.float64), (4,)).copy()
        self.name = name

    @property
    def failures(self) -> int:
        """Hover fallbacks so far (non-finite observations, solver failures) of base and correction."""
        return int(getattr(self.base, "failures", 0)) + int(getattr(self.correction, "failures", 0))

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """The combined action for one observation or a batch; a non-finite observation
        gives the base controller's hover fallback with no correction (both count it)."""
        obs = np.asarray(observation, dtype=np.float32)
        base_action, state = _base_predict(self.base, obs, state, episode_start)
        correction, _ = self.correction.predict(augment_observation(obs, base_action), deterministic=deterministic)
        return combine(base_action, correction, self.scale).astype(np.float32), state

    def __repr__(self) -> str:
        return f"ResidualPolicy({self.name}, scale={self.scale.tolist()})"
