"""Building the training and evaluation environments from a configuration.

:func:`env_kwargs` turns a configuration (:mod:`agents.config`) into ``gym.make``
keywords: the task's ``env_kwargs`` plus, when ``randomize`` is on, the env's own
``randomize`` keyword with the configured ranges (k_s, d_thr, standoff, mass drawn
per episode by the environment). :func:`make_env` builds one environment, wrapped
for a residual agent when the configuration names a base controller, and in a
``Monitor`` so Stable-Baselines3 logs episode returns and lengths.
:func:`make_vec_env` builds the vector env (:func:`make_training_env`: under the training ``VecNormalize``): the batched env
(:class:`~agents.batched_vec_env.BatchedVecEnv` under ``VecMonitor``, all envs stepped by
one compiled call in this process) or a :class:`~agents.vec_env.MultiEnvSubprocVecEnv`
(``vector="subprocess"``); with ``n_workers=0`` a ``DummyVecEnv`` (evaluation, one
process). A residual agent on the batched env is a :class:`~agents.residual.ResidualVecEnv`
over it: one base controller predicts for the whole batch per step.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecMonitor, VecNormalize

import wall_env  # noqa: F401  (registers the WallInspector tasks)
from agents.config import base_controller_kwargs
from agents.residual import ResidualActionWrapper, ResidualVecEnv, make_base_controller
from agents.vec_env import MultiEnvSubprocVecEnv

__all__ = ["env_kwargs", "evaluation_config", "make_env", "env_factory", "make_vec_env", "make_training_env",
           "history_settings", "vector_kind", "VECTOR_KINDS", "CURRICULUM_RANGES"]

VECTOR_KINDS = ("batched", "subprocess")

# randomised quantities that shape training only (a start-state curriculum: episodes starting along the
# reference), never the task an evaluation judges: an evaluation flies the whole path from its start
CURRICULUM_RANGES = ("start_time",)

# info entries that Monitor copies into each finished episode's record (info["episode"])
MONITOR_INFO_KEYS = ("collisions",)


def env_kwargs(config: dict[str, Any], randomize: bool | None = None) -> dict[str, Any]:
    """``gym.make`` keywords for ``config``; ``randomize`` overrides ``config["randomize"]``."""
    kwargs = dict(config["env_kwargs"])
    if config["randomize"] if randomize is None else randomize:
        kwargs["randomize"] = {k: tuple(float(b) for b in v) for k, v in config["randomize_ranges"].items()}
    return kwargs


def evaluation_config(config: dict[str, Any]) -> dict[str, Any]:
    """``config`` for the evaluations during training: the curriculum's ranges (:data:`CURRICULUM_RANGES`)
    left out, so that every evaluation flies the task from its start and returns compare across checkpoints."""
    ranges = {k: v for k, v in config["randomize_ranges"].items() if k not in CURRICULUM_RANGES}
    if len(ranges) == len(config["randomize_ranges"]):
        return config
    return {**config, "randomize_ranges": ranges, "randomize": bool(config["randomize"] and ranges)}


def make_env(config: dict[str, Any], randomize: bool | None = None, monitor: bool = True) -> gym.Env:
    """One environment for ``config`` (residual-wrapped if ``config["residual"]``)."""
    try:
        env = gym.make(config["env_id"], **env_kwargs(config, randomize))
    except TypeError as exc:  # an unknown keyword: a configuration error, not a crash
        reason = str(exc).split(" was raised from the environment creator")[0]
        raise ValueError(f"env_kwargs for {config['env_id']}: {reason}") from exc
    if config["residual"]:
        name = config["residual"]
        base_kwargs = base_controller_kwargs(config, name)
        env = ResidualActionWrapper(env, lambda e: make_base_controller(name, e, **base_kwargs),
                                    scale=config["residual_scale"])
    if monitor:
        env = Monitor(env, info_keywords=MONITOR_INFO_KEYS)
    return env


def env_factory(config: dict[str, Any], randomize: bool | None = None) -> Callable[[], gym.Env]:
    """A picklable function that builds :func:`make_env` ``(config, randomize)``."""
    frozen = dict(config)

    def build() -> gym.Env:
        return make_env(frozen, randomize)

    return build


def history_settings(config: dict[str, Any]) -> Any:
    """The configuration's :class:`~agents.history.HistorySettings` at its env's control period."""
    from agents.history import HistorySettings

    spec = {**config.get("history", {}), "control_dt": float(config["env_kwargs"].get("control_dt", 0.01))}
    return HistorySettings.from_spec(spec)


def make_vec_env(config: dict[str, Any], n_envs: int, n_workers: int = 0, randomize: bool | None = None,
                 vector: str = "subprocess") -> VecEnv:
    """``n_envs`` environments: ``vector="batched"``, the batched env in this process (residual
    agents: wrapped in :class:`~agents.residual.ResidualVecEnv`); otherwise in ``n_workers``
    processes, or in this process if ``n_workers`` is 0."""
    if vector not in VECTOR_KINDS:
        raise ValueError(f"vector must be one of {VECTOR_KINDS}, got {vector!r}")
    if vector == "batched":
        from agents.batched_vec_env import BatchedVecEnv

        venv: VecEnv = BatchedVecEnv(config["env_id"], n_envs, info_keys=MONITOR_INFO_KEYS,
                                     **env_kwargs(config, randomize))
        if config["residual"]:
            name = config["residual"]
            venv = ResidualVecEnv(venv, make_base_controller(name, venv, **base_controller_kwargs(config, name)),
                                  scale=config["residual_scale"])
        return _remembering(VecMonitor(venv, info_keywords=MONITOR_INFO_KEYS), config)
    fns = [env_factory(config, randomize) for _ in range(n_envs)]
    if n_workers <= 0:
        return _remembering(DummyVecEnv(fns), config)
    return _remembering(MultiEnvSubprocVecEnv(fns, n_workers=n_workers), config)


def vector_kind(config: dict[str, Any]) -> str:
    """The vector env a run uses: the configured one (residual agents too: on the batched env
    their base controller predicts for the whole batch in one call)."""
    return config.get("vector", "batched")


def make_training_env(config: dict[str, Any]) -> VecNormalize:
    """The run's training env: ``n_envs`` envs of the configured vector kind under ``VecNormalize`` with the
    configured normalisation (the learner's, and a :class:`~agents.rollout_worker.RolloutWorker`'s alike)."""
    norm = config["normalize"]
    venv = make_vec_env(config, config["n_envs"], config["n_workers"], vector=vector_kind(config))
    return VecNormalize(venv, norm_obs=norm["norm_obs"], norm_reward=norm["norm_reward"], clip_obs=float(norm["clip_obs"]),
                        clip_reward=float(norm["clip_reward"]), gamma=float(config["ppo"]["gamma"]))


def _remembering(venv: VecEnv, config: dict[str, Any]) -> VecEnv:
    """``venv`` with the configuration's observation history (:mod:`agents.history`), if it has one."""
    settings = history_settings(config)
    if settings.trivial:
        return venv
    from agents.history import VecObservationHistory

    return VecObservationHistory(venv, settings)
