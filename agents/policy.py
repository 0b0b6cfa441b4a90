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

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agents.checkpoints import CheckpointNotFoundError, load_model
from agents.config import task_env_id, task_name, task_slug

__all__ = ["PRETRAINED_DIR", "TaskMismatchError", "TrainedPolicy", "check_task", "load_policy", "policy_factory", "pretrained_path"]

PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"


class TaskMismatchError(ValueError):
    """An agent was loaded for an environment of another task than the one it was trained on."""


class TrainedPolicy:
    """A PPO model together with the ``VecNormalize`` statistics it was trained with.

    A non-finite observation gives the hover action (all zeros: hover thrust of the
    env's vehicle, zero body rates) for that row instead of a network output, increments
    :attr:`failures`, records the reason in :attr:`failure_log` and issues a
    ``RuntimeWarning``, as the controllers do; the action is never NaN.

    An agent trained with an observation history (``policy.json``'s ``history``,
    :mod:`agents.history`) takes the env's observations and keeps the history itself, one
    memory per batch row, begun afresh where ``episode_start`` says so or, when it is not
    given, where the observation's time goes back (a reset), as the controllers do.
    """

    def __init__(self, model: Any, vec_normalize: Any, info: dict[str, Any], path: Path | None = None):
        self.model = model
        self.vec_normalize = vec_normalize
        self.info = info
        self.path = path
        self.env_id: str | None = info.get("env_id")  # None for a plain Stable-Baselines3 save
        self.observation_space = model.observation_space
        self.action_space = model.action_space
        self.failures = 0
        self.failure_log: list[str] = []
        self.history: Any = None
        if info.get("history"):
            from agents.history import FlightMemory, HistorySettings

            settings = HistorySettings.from_spec(info["history"])
            width = settings.observation_size(int(self.observation_space.shape[0]))
            self.history = FlightMemory(settings, width)

    @property
    def observation_size(self) -> int:
        """Entries of the observation ``predict`` takes (the env's; the network may take more, with a history)."""
        if self.history is not None:
            return self.history.observation_size
        return int(self.observation_space.shape[0])

    def normalize(self, observation: np.ndarray) -> np.ndarray:
        """The observation as the network sees it (float32, normalised and clipped)."""
        obs = np.asarray(observation, dtype=np.float32)
        if self.vec_normalize is None:  # a model trained without VecNormalize
            return obs
        return np.asarray(self.vec_normalize.normalize_obs(obs), dtype=np.float32)

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """Actions for one observation ``(obs_size,)`` or a batch ``(n, obs_size)``."""
        try:
            obs = np.asarray(observation, dtype=np.float32)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"observation must be an array of numbers, got {type(observation).__name__} ({exc})") from None
        expected = self.observation_size
        if obs.shape[-1:] != (expected,) or obs.ndim > 2:
            raise ValueError(f"observation must have shape ({expected},) or (n, {expected}), got {obs.shape}")
        bad = ~np.all(np.isfinite(obs), axis=-1)
        inputs = obs if self.history is None else self.history(obs.reshape(-1, expected), episode_start).reshape(
            *obs.shape[:-1], -1)
        if not np.any(bad):
            actions, state = self.model.predict(self.normalize(inputs), state=state, episode_start=episode_start,
                                                deterministic=deterministic)
            return actions, state
        batch = inputs.reshape(-1, inputs.shape[-1])
        bad_rows = np.atleast_1d(bad)
        actions = np.zeros((len(batch), *self.action_space.shape), dtype=np.float32)
        good = ~bad_rows
        if np.any(good):
            actions[good], _ = self.model.predict(self.normalize(batch[good]), deterministic=deterministic)
        for row in np.flatnonzero(bad_rows):
            self.failures += 1
            reason = f"non-finite observation (batch row {row})"
            self.failure_log.append(reason)
            warnings.warn(f"{self}: {reason}; commanding hover (failure {self.failures})", RuntimeWarning, stacklevel=2)
        return (actions[0] if obs.ndim == 1 else actions), state

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


def _plain_sb3_model(source: str | Path) -> TrainedPolicy | None:
    """A model saved by Stable-Baselines3 itself (a ``.zip`` with no ``policy.json`` beside it),
    with the ``vecnormalize.pkl`` beside it if there is one; ``None`` for anything else."""
    path = Path(source)
    if not (path.is_file() and path.suffix == ".zip") or (path.parent / "policy.json").exists():
        return None
    from stable_baselines3 import PPO

    from agents.checkpoints import CheckpointError, read_vecnormalize

    try:
        model = PPO.load(path, device="cpu")
    except Exception as exc:
        raise CheckpointError(f"{path}: corrupted or not a Stable-Baselines3 PPO model ({type(exc).__name__}: {exc})") from exc
    statistics = path.parent / "vecnormalize.pkl"
    vec_normalize = read_vecnormalize(statistics) if statistics.is_file() else None
    if vec_normalize is None:
        warnings.warn(f"{path}: no vecnormalize.pkl beside it, so the policy sees raw observations (right only for an "
                      "agent trained without VecNormalize)", RuntimeWarning, stacklevel=3)
    return TrainedPolicy(model, vec_normalize, {"env_id": None, "algorithm": "PPO", "residual": None}, path.parent)


def _env_task_or_none(env: Any) -> str | None:
    inner = env.envs[0] if hasattr(env, "envs") and env.envs else env  # a DummyVecEnv: its first env
    task = getattr(getattr(inner, "unwrapped", inner), "task", None)
    return getattr(task, "name", None)


def check_task(info: dict[str, Any], env: Any, folder: Path, allow_other_task: bool = False) -> None:
    """Refuse (``TaskMismatchError``) an ``env`` of another task than ``info["env_id"]``;
    with ``allow_other_task`` warn instead."""
    task = _env_task_or_none(env)
    if task is None or not info.get("env_id") or task == task_name(info["env_id"]):
        return
    message = (f"{folder} holds an agent trained on {info['env_id']}, but the environment is {task_env_id(task)}")
    if not allow_other_task:
        raise TaskMismatchError(message + "; load the agent of that task, or pass allow_other_task=True to fly it anyway")
    warnings.warn(message + " (allow_other_task=True)", RuntimeWarning, stacklevel=3)


def load_policy(source: str | Path, env: Any = None, verify: bool = True, base_kwargs: dict[str, Any] | None = None,
                allow_other_task: bool = False) -> Any:
    """Load a trained agent.

    ``source``: a task name (``"WallSweep-v0"``, ``"WallInspector/WallSweep-v0"``) for the
    shipped checkpoint, a checkpoint folder (a run folder, its ``best/``, a pretrained
    folder) or the ``model.zip`` inside one. ``env``: needed only for residual agents, to
    build the base controller; ``base_kwargs`` replace the saved keywords of that base
    (e.g. the true ``k_s``/``d_thr`` for SC-MPC). ``verify``: recompute the actions
    recorded at save time. A ``.zip`` saved by Stable-Baselines3 itself (no ``policy.json``
    beside it) loads too, with the ``vecnormalize.pkl`` beside it if present (without one
    the policy sees raw observations, and a ``RuntimeWarning`` says so). An ``env`` of another task than the agent's raises
    :class:`TaskMismatchError` (``allow_other_task=True``: a ``RuntimeWarning`` instead).

    The files are Stable-Baselines3's own: ``PPO.load(folder / "model.zip")`` and
    ``VecNormalize.load(folder / "vecnormalize.pkl", venv)`` read them without this package.
    """
    plain = _plain_sb3_model(source)
    if plain is not None:
        return plain
    folder = _resolve(source)
    model, vec_normalize, info = load_model(folder, verify=verify)
    if env is not None:
        check_task(info, env, folder, allow_other_task)
    policy = TrainedPolicy(model, vec_normalize, info, folder)
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


def _env_task(env: Any) -> str:
    task = getattr(getattr(env, "unwrapped", env), "task", None)
    if task is None:
        raise ValueError(f"cannot tell which task {env!r} is; pass the checkpoint to policy_factory explicitly")
    return task.name


def policy_factory(source: str | Path | None = None, *, variant: str = "", verify: bool = True,
                   allow_other_task: bool = False) -> Callable[..., Any]:
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

    def factory(env: Any, scenario: Any = None) -> Any:
        if source is not None:
            folder = _resolve(source)
        else:
            folder = pretrained_path(_env_task(env), variant)
            if not folder.is_dir():
                raise CheckpointNotFoundError(f"no shipped agent for {_env_task(env)}: {folder} does not exist")
        if folder not in cache:
            cache[folder] = load_policy(folder, env=env, verify=verify, allow_other_task=allow_other_task)
        loaded = cache[folder]
        if isinstance(loaded, TrainedPolicy):
            check_task(loaded.info, env, folder, allow_other_task)
            return loaded
        base_kwargs = None
        if scenario is not None and loaded.base_name == "scmpc":
            base_kwargs = {"k_s": float(scenario.k_s), "d_thr": float(scenario.d_thr)}
        # residual: the base controller belongs to this env
        return load_policy(folder, env=env, verify=False, base_kwargs=base_kwargs, allow_other_task=allow_other_task)

    factory.__name__ = f"ppo_policy_factory({source or 'shipped'}{', ' + variant if variant else ''})"
    return factory
