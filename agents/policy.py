"""Loaded agents: one call from a checkpoint (or a task name) to a policy with ``predict``.

::

    import agents
    policy = agents.load_policy("WallSweep-v0")          # shipped checkpoint
    policy = agents.load_policy("out/sweep/best")         # any checkpoint folder
    action, _ = policy.predict(obs)                       # obs (48,) or (n, 48)

:class:`TrainedPolicy` applies the saved observation normalisation and then the PPO
network; its ``predict`` follows Stable-Baselines3's ``PolicyPredictor`` protocol
(``predict(obs, state=None, episode_start=None, deterministic=True) -> (actions,
state)``). A residual agent needs the environment to build its base controller:
``load_policy(path, env=env)`` returns a :class:`~agents.residual.ResidualPolicy`.

:func:`policy_factory` gives the ``env -> policy`` function that the comparison
tables (``controllers.paper_tables``, ``wall-inspector compare``) take for every
controller, so PPO runs through the same evaluation as PID, MPC and SC-MPC.

Shipped checkpoints live in ``agents/pretrained/<task_slug>/`` (e.g.
``agents/pretrained/wall_sweep/``), each with its model card.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agents.checkpoints import CheckpointNotFoundError, load_model, normalize_observation
from agents.config import task_name, task_slug

__all__ = ["PRETRAINED_DIR", "TrainedPolicy", "load_policy", "policy_factory", "pretrained_path"]

PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"


class TrainedPolicy:
    """A PPO model together with the observation statistics it was trained with."""

    def __init__(self, model, normalization: dict[str, Any], info: dict[str, Any], path: Path | None = None):
        self.model = model
        self.normalization = normalization
        self.info = info
        self.path = path
        self.env_id: str = info["env_id"]
        self.observation_space = model.observation_space
        self.action_space = model.action_space

    def normalize(self, observation: np.ndarray) -> np.ndarray:
        """The observation as the network sees it (float32, normalised and clipped)."""
        return normalize_observation(self.normalization, observation)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """Actions for one observation ``(obs_size,)`` or a batch ``(n, obs_size)``."""
        obs = np.asarray(observation, dtype=np.float32)
        expected = self.observation_space.shape[0]
        if obs.shape[-1:] != (expected,) or obs.ndim > 2:
            raise ValueError(f"observation must have shape ({expected},) or (n, {expected}), got {obs.shape}")
        return self.model.predict(self.normalize(obs), state=state, episode_start=episode_start,
                                  deterministic=deterministic)

    def __repr__(self) -> str:
        return f"TrainedPolicy({self.env_id}, {self.path})"


def pretrained_path(task: str, variant: str = "") -> Path:
    """Folder of the shipped checkpoint for ``task`` (it may not exist).

    ``variant`` names a second agent of the same task, e.g. ``"residual_scmpc"`` for the
    residual agent on top of SC-MPC: ``agents/pretrained/<task_slug>_<variant>/``.
    """
    return PRETRAINED_DIR / (task_slug(task) + (f"_{variant}" if variant else ""))


def _resolve(source: str | Path) -> Path:
    """Checkpoint folder for an existing path (folder or its ``model.zip``) or a task name."""
    path = Path(source)
    if path.exists():
        return path.parent if path.is_file() and path.suffix == ".zip" else path
    try:
        folder = pretrained_path(str(source))
    except ValueError:  # not a task name either: report the missing path
        return path.parent if path.suffix == ".zip" else path
    if not folder.is_dir():
        raise CheckpointNotFoundError(f"no shipped checkpoint for {task_name(str(source))}: {folder} does not exist "
                                      "(train one with `wall-inspector train` and pass its folder)")
    return folder


def load_policy(source: str | Path, env=None, verify: bool = True, base_kwargs: dict[str, Any] | None = None):
    """Load a trained agent.

    ``source``: a task name (``"WallSweep-v0"``, ``"WallInspector/WallSweep-v0"``) for the
    shipped checkpoint, a checkpoint folder (a run folder, its ``best/``, a pretrained
    folder) or the ``model.zip`` inside one. ``env``: needed only for residual agents, to
    build the base controller; ``base_kwargs`` replace the saved keywords of that base
    (e.g. the true ``k_s``/``d_thr`` for SC-MPC). ``verify``: recompute the actions
    recorded at save time.
    """
    folder = _resolve(source)
    model, normalization, info = load_model(folder, verify=verify)
    policy = TrainedPolicy(model, normalization, info, folder)
    residual = info.get("residual")
    if not residual:
        return policy
    if env is None:
        raise ValueError(f"{folder} holds a residual agent on top of {residual['base']!r}; pass env= so that "
                         "load_policy can build the base controller for that environment")
    from agents.residual import ResidualPolicy, make_base_controller

    # agents saved before controller presets existed were trained on the authors' settings
    kwargs = {"preset": "paper", **residual.get("base_kwargs", {}), **(base_kwargs or {})}
    base = make_base_controller(residual["base"], env, **kwargs)
    return ResidualPolicy(base, policy, residual["scale"], name=f"PPO residual on {residual['base']}",
                          base_name=residual["base"])


def _env_task(env) -> str:
    task = getattr(getattr(env, "unwrapped", env), "task", None)
    if task is None:
        raise ValueError(f"cannot tell which task {env!r} is; pass the checkpoint to policy_factory explicitly")
    return task.name


def policy_factory(source: str | Path | None = None, *, variant: str = "", verify: bool = True) -> Callable[[Any], Any]:
    """``env -> policy`` for comparison tables (``controllers.paper_tables``).

    With ``source`` (task name or checkpoint folder) every env gets that checkpoint.
    Without it, each env gets the shipped agent of its own task,
    ``agents/pretrained/<task_slug>[_<variant>]/`` (e.g. ``variant="residual_pid"``),
    so one factory serves Table I (circle) and Table II (sweep)::

        policies = {**paper_policies(), "PPO": agents.policy_factory()}

    Checkpoints are read once per source; a residual agent gets a fresh base controller
    for every env. When the table passes its scenario (``factory(env, scenario)``), a
    residual agent's SC-MPC base is told the scenario's ``k_s`` and ``d_thr``, as the
    table's own SC-MPC is.
    """
    cache: dict[Path, Any] = {}

    def factory(env, scenario=None):
        if source is not None:
            folder = _resolve(source)
        else:
            folder = pretrained_path(_env_task(env), variant)
            if not folder.is_dir():
                raise CheckpointNotFoundError(f"no shipped agent for {_env_task(env)}: {folder} does not exist")
        if folder not in cache:
            cache[folder] = load_policy(folder, env=env, verify=verify)
        loaded = cache[folder]
        if isinstance(loaded, TrainedPolicy):
            return loaded
        base_kwargs = None
        if scenario is not None and loaded.base_name == "scmpc":
            base_kwargs = {"k_s": float(scenario.k_s), "d_thr": float(scenario.d_thr)}
        # residual: the base controller belongs to this env
        return load_policy(folder, env=env, verify=False, base_kwargs=base_kwargs)

    factory.__name__ = f"ppo_policy_factory({source or 'shipped'}{', ' + variant if variant else ''})"
    return factory
