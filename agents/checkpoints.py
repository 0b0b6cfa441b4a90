"""Saving and loading trained agents, and their model cards.

A checkpoint is a folder that Stable-Baselines3 alone can load::

    model = PPO.load("agents/pretrained/wall_sweep/model.zip")
    env = VecNormalize.load("agents/pretrained/wall_sweep/vecnormalize.pkl", make_vec_env("WallInspector/WallSweep-v0"))

``model.zip``
    the Stable-Baselines3 PPO model (network weights, optimiser state, hyperparameters,
    step count).
``vecnormalize.pkl``
    the ``VecNormalize`` the policy was trained with, written by ``VecNormalize.save``:
    observation running mean/variance/count, the return statistics that scale rewards,
    ``clip_obs``, ``epsilon``, ``gamma``. It is saved in evaluation mode
    (``training=False``, ``norm_reward=False``), so the environment from
    ``VecNormalize.load`` normalises observations with the frozen statistics and returns
    raw rewards; resuming training switches both back on.
``policy.json``
    what the policy is: environment id, step count, the residual base controller (if any)
    and its correction scale, and a *check*: a few observations and the deterministic
    actions the in-memory model gave for them when it was saved. Loading recomputes
    those actions and refuses a checkpoint whose model and statistics do not reproduce
    them (mismatched or damaged files).

A training run's folder holds the final checkpoint at its top level, the best one
(by the evaluation callback) in ``best/``, periodic and interrupted ones in
``checkpoints/<steps>/``, plus ``config.yaml``, TensorBoard logs in ``tb/`` and the model
card (``model_card.json`` and ``model_card.md``).

Every failure to load names the file: :class:`CheckpointNotFoundError` (also a
``FileNotFoundError``) for a missing file, :class:`CheckpointError` for one that is
unreadable or inconsistent. Like any pickle, ``vecnormalize.pkl`` should only be loaded
from a source you trust.
"""

from __future__ import annotations

import json
import math
import pickle
import shutil
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from agents.learning_curve import LEARNING_CURVE_PNG, card_curve, plot_learning_curve, shipped_timesteps

__all__ = [
    "MODEL_FILE",
    "POLICY_FILE",
    "VECNORMALIZE_FILE",
    "CheckpointError",
    "CheckpointNotFoundError",
    "checkpoint_files",
    "copy_checkpoint",
    "load_model",
    "read_json",
    "read_vecnormalize",
    "save_checkpoint",
    "save_vecnormalize",
    "training_env_steps",
    "upgrade_checkpoint",
    "vecnormalize_from_json",
    "write_model_card",
]

MODEL_FILE = "model.zip"
VECNORMALIZE_FILE = "vecnormalize.pkl"
POLICY_FILE = "policy.json"
LEGACY_NORMALIZATION_FILE = "normalization.json"  # earlier format: the statistics as JSON
CARD_JSON = "model_card.json"
CARD_MD = "model_card.md"
FORMAT_VERSION = 2


class CheckpointError(RuntimeError):
    """A checkpoint file exists but cannot be used; the message names the file."""


class CheckpointNotFoundError(CheckpointError, FileNotFoundError):
    """A checkpoint file (or folder) does not exist; the message names it."""


# ---------------------------------------------------------------------- normalisation statistics
def save_vecnormalize(vec_normalize: Any, path: str | Path) -> None:
    """``VecNormalize.save`` in evaluation mode (``training`` and ``norm_reward`` off in
    the file); ``vec_normalize`` itself is left as it was."""
    training, norm_reward = vec_normalize.training, vec_normalize.norm_reward
    vec_normalize.training, vec_normalize.norm_reward = False, False
    try:
        vec_normalize.save(str(path))
    finally:
        vec_normalize.training, vec_normalize.norm_reward = training, norm_reward


def read_vecnormalize(path: str | Path) -> Any:
    """The ``VecNormalize`` saved at ``path``, without an environment attached.

    It can normalise observations (``normalize_obs``) but not step; ``VecNormalize.load``
    attaches an environment. Raises :class:`CheckpointNotFoundError` / :class:`CheckpointError`.
    """
    from stable_baselines3.common.vec_env import VecNormalize

    path = Path(path)
    try:
        with path.open("rb") as handle:
            loaded: Any = pickle.load(handle)
    except FileNotFoundError:
        raise CheckpointNotFoundError(f"checkpoint file {path} does not exist") from None
    except Exception as exc:  # noqa: BLE001 - any unpickling failure means the file is unusable
        raise CheckpointError(f"{path}: corrupted or not a VecNormalize pickle ({type(exc).__name__}: {exc})") from None
    if not isinstance(loaded, VecNormalize):
        raise CheckpointError(f"{path}: not a VecNormalize pickle (holds a {type(loaded).__name__})")
    obs_rms: Any = loaded.obs_rms
    mean, var = np.asarray(obs_rms.mean), np.asarray(obs_rms.var)
    if mean.ndim != 1 or mean.shape != var.shape or not np.all(np.isfinite(mean)) or not np.all(var >= 0):
        raise CheckpointError(f"{path}: observation statistics are malformed (mean shape {mean.shape}, var shape {var.shape})")
    return loaded


def vecnormalize_from_json(state: dict[str, Any], observation_space: Any, action_space: Any) -> Any:
    """A ``VecNormalize`` in evaluation mode holding statistics that the earlier checkpoint
    format saved as JSON (``normalization.json``); see :func:`upgrade_checkpoint`."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    class SpacesOnly(gym.Env):
        """Only the spaces: enough to build, save and normalise with a VecNormalize."""

        def __init__(self) -> None:
            self.observation_space, self.action_space = observation_space, action_space

    vec: Any = VecNormalize(DummyVecEnv([SpacesOnly]), training=False, norm_obs=bool(state["norm_obs"]), norm_reward=False,
                       clip_obs=float(state["clip_obs"]), clip_reward=float(state["clip_reward"]),
                       gamma=float(state["gamma"]), epsilon=float(state["epsilon"]))
    vec.obs_rms.mean = np.asarray(state["obs_mean"], dtype=np.float64)
    vec.obs_rms.var = np.asarray(state["obs_var"], dtype=np.float64)
    vec.obs_rms.count = float(state["obs_count"])
    vec.ret_rms.mean = np.float64(state["ret_mean"])
    vec.ret_rms.var = np.float64(state["ret_var"])
    vec.ret_rms.count = float(state["ret_count"])
    return vec


def upgrade_checkpoint(folder: str | Path) -> Path:
    """Write ``vecnormalize.pkl`` into a checkpoint folder of the earlier format, from its
    ``normalization.json`` (nothing else is changed); returns the new file's path.

    The statistics are copied exactly, so the policy acts as before: the actions recorded
    in ``policy.json`` are checked on the result.
    """
    from stable_baselines3 import PPO

    folder = Path(folder)
    state = read_json(folder / LEGACY_NORMALIZATION_FILE)
    model = PPO.load(folder / MODEL_FILE, device="cpu")
    vec = vecnormalize_from_json(state, model.observation_space, model.action_space)
    target = folder / VECNORMALIZE_FILE
    save_vecnormalize(vec, target)
    vec.close()
    load_model(folder)  # the recorded actions must be reproduced
    return target


# ---------------------------------------------------------------------- files
def read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise CheckpointNotFoundError(f"checkpoint file {path} does not exist") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: corrupted or not JSON ({exc})") from None


def checkpoint_files(folder: str | Path) -> dict[str, Path]:
    """Paths of the checkpoint files in ``folder`` (which must exist)."""
    folder = Path(folder)
    if not folder.exists():
        raise CheckpointNotFoundError(f"checkpoint folder {folder} does not exist")
    if not folder.is_dir():
        raise CheckpointError(f"{folder} is not a checkpoint folder (expected {MODEL_FILE}, {VECNORMALIZE_FILE}, "
                              f"{POLICY_FILE})")
    return {"model": folder / MODEL_FILE, "normalization": folder / VECNORMALIZE_FILE, "policy": folder / POLICY_FILE}


def _check_actions(model: Any, vec_normalize: Any, observations: np.ndarray) -> np.ndarray:
    actions, _ = model.predict(vec_normalize.normalize_obs(np.asarray(observations, dtype=np.float32)), deterministic=True)
    return np.asarray(actions, dtype=np.float64)


_ADAM_STATE = frozenset({"step", "exp_avg", "exp_avg_sq"})


def drop_half_made_optimizer_state(optimizer: Any) -> list[int]:
    """Forget a parameter's optimiser state that a Ctrl-C left half made; the indices of such parameters.

    Adam makes a parameter's state at its first step, ``step`` before ``exp_avg`` and ``exp_avg_sq``:
    interrupted between them, the state saved with the checkpoint lacks its moments, and the run resumed
    from it fails in its first update (``KeyError: 'exp_avg'``). Such a state is dropped, and the
    optimiser makes it afresh at its next step, as it does for a parameter it has not yet stepped.
    For optimisers other than Adam's family, a state with fewer entries than the fullest is half made.
    """
    if optimizer is None or not getattr(optimizer, "state", None):
        return []
    import torch

    made = [set(state) for state in optimizer.state.values() if state]
    if not made:
        return []
    if isinstance(optimizer, (torch.optim.Adam, torch.optim.AdamW)):
        required = set(_ADAM_STATE) | ({"max_exp_avg_sq"} if any(g.get("amsgrad") for g in optimizer.param_groups) else set())
    else:
        required = max(made, key=len)
    dropped = []
    for index, p in enumerate(p for group in optimizer.param_groups for p in group["params"]):
        state = optimizer.state.get(p)
        if state and not required <= set(state):
            del optimizer.state[p]
            dropped.append(index)
    return dropped


def save_checkpoint(folder: str | Path, model: Any, vec_normalize: Any, policy_info: dict[str, Any],
                    check_observations: np.ndarray | None = None) -> Path:
    """Write ``model.zip``, ``vecnormalize.pkl`` and ``policy.json`` into ``folder``.

    ``check_observations`` (raw, un-normalised, ``(n, obs_size)``) are stored with the
    deterministic actions the model gives for them now, for :func:`load_model` to verify.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    drop_half_made_optimizer_state(getattr(getattr(model, "policy", None), "optimizer", None))
    model.save(folder / MODEL_FILE)
    save_vecnormalize(vec_normalize, folder / VECNORMALIZE_FILE)
    info = {"format": FORMAT_VERSION, **policy_info}
    if check_observations is not None and len(check_observations):
        obs = np.asarray(check_observations, dtype=np.float32)
        info["check"] = {"observations": obs.tolist(), "actions": _check_actions(model, vec_normalize, obs).tolist()}
    (folder / POLICY_FILE).write_text(json.dumps(info, indent=1))
    return folder


def load_model(folder: str | Path, verify: bool = True) -> tuple[Any, Any, dict[str, Any]]:
    """Load a checkpoint folder: ``(model, vec_normalize, policy_info)``.

    ``vec_normalize`` has no environment attached (see :func:`read_vecnormalize`).
    Raises :class:`CheckpointNotFoundError` or :class:`CheckpointError` naming the file.
    """
    from stable_baselines3 import PPO

    files = checkpoint_files(folder)
    if not files["normalization"].is_file() and (Path(folder) / LEGACY_NORMALIZATION_FILE).is_file():
        raise CheckpointError(f"{folder} is a checkpoint of the earlier format ({LEGACY_NORMALIZATION_FILE}, no "
                              f"{VECNORMALIZE_FILE}); convert it once with: python -c \"from agents.checkpoints import "
                              f"upgrade_checkpoint; upgrade_checkpoint('{folder}')\"")
    for path in files.values():
        if not path.is_file():
            raise CheckpointNotFoundError(f"checkpoint file {path} does not exist")
    info = read_json(files["policy"])
    if not isinstance(info, dict) or "env_id" not in info:
        raise CheckpointError(f"{files['policy']}: not a policy description (no env_id)")
    vec_normalize = read_vecnormalize(files["normalization"])
    if not zipfile.is_zipfile(files["model"]):
        raise CheckpointError(f"{files['model']}: corrupted or not a Stable-Baselines3 model archive (not a zip file)")
    try:
        model = PPO.load(files["model"], device="cpu")
    except Exception as exc:
        raise CheckpointError(f"{files['model']}: corrupted or not a Stable-Baselines3 PPO model "
                              f"({type(exc).__name__}: {exc})") from exc
    obs_size = int(np.prod(model.observation_space.shape or ()))
    stats_size = int(np.prod(np.shape(vec_normalize.obs_rms.mean)))
    if stats_size != obs_size:
        raise CheckpointError(f"{files['normalization']}: statistics for {stats_size} observation entries, "
                              f"but {files['model']} expects {obs_size}")
    if verify and "check" in info:
        obs = np.asarray(info["check"]["observations"], dtype=np.float32)
        expected = np.asarray(info["check"]["actions"], dtype=np.float64)
        actions = _check_actions(model, vec_normalize, obs)
        if not np.allclose(actions, expected, rtol=1e-5, atol=1e-6):
            worst = float(np.max(np.abs(actions - expected)))
            raise CheckpointError(f"{files['model']} with {files['normalization']} does not reproduce the actions recorded "
                                  f"in {files['policy']} (largest difference {worst:.3g}): the files do not belong together "
                                  "or one is damaged")
    return model, vec_normalize, info


def copy_checkpoint(source: str | Path, target: str | Path, extra_files: tuple[str, ...] = ()) -> Path:
    """Copy a checkpoint folder's files (and ``extra_files`` from ``source`` or its parent, if present)."""
    files = checkpoint_files(source)
    target = Path(target)
    target.mkdir(parents=True, exist_ok=True)
    for path in files.values():
        shutil.copy2(path, target / path.name)
    for name in extra_files:
        for candidate in (Path(source) / name, Path(source).parent / name):
            if candidate.is_file():
                shutil.copy2(candidate, target / name)
                break
    return target


# ---------------------------------------------------------------------- model cards
def _fmt(value: Any) -> str:
    if isinstance(value, (list, tuple)):
        return ", ".join(_fmt(v) for v in value)
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        if math.isnan(value):
            return "n/a"
        return f"{value:.4g}"
    return str(value)


def _git_text(training: dict[str, Any]) -> str | None:
    """The commit the run started from, and what differed from it (``git_uncommitted``: a
    list of files, or a sentence for cards that could only say that something did)."""
    commit, uncommitted = training.get("git_commit"), training.get("git_uncommitted")
    if not commit or not uncommitted:
        return commit
    if isinstance(uncommitted, str):
        return f"{commit} plus uncommitted changes: {uncommitted}"
    return f"{commit} plus uncommitted changes to {', '.join(uncommitted)}"


def write_model_card(folder: str | Path, card: dict[str, Any]) -> tuple[Path, Path]:
    """Write ``model_card.json`` (everything) and ``model_card.md`` (for people) into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    json_path, md_path = folder / CARD_JSON, folder / CARD_MD
    json_path.write_text(json.dumps(card, indent=2, default=_jsonable))
    training, evaluation = card.get("training", {}), card.get("evaluation", {})
    lines = [
        f"# {'Distilled' if training.get('teacher') else 'PPO'} agent for {card.get('env_id', '?')}",
        "",
        card.get("summary", ""),
        "",
        "## How it was trained",
        "",
        "```",
        card.get("command", "?"),
        "```",
        "",
        "| quantity | value |",
        "| --- | --- |",
    ]
    rows = [
        ("total timesteps (env steps)", training.get("total_timesteps")),
        ("timesteps in this run", training.get("timesteps_this_run")),
        ("wall-clock time of this run (s)", training.get("wall_time_s")),
        ("training throughput (env steps/s, incl. PPO updates)", training.get("steps_per_s")),
        ("wall-clock time of the whole command (s, incl. start-up and final evaluation)",
         training.get("command_wall_time_s")),
        ("environments / worker processes", f"{training.get('n_envs')} / {training.get('n_workers')}"),
        ("residual base controller", card.get("residual") or "none"),
        *((("warm start (behaviour cloning, included in the wall-clock time)", _warm_start_text(training["warm_start"])),)
          if training.get("warm_start") else ()),
        *((("teacher (DAgger, included in the wall-clock time)", _teacher_text(training["teacher"])),)
          if training.get("teacher") else ()),
        *((("time split (env steps / rest of the rollouts / updates and callbacks)", _split_text(training["time_split"])),)
          if training.get("time_split") else ()),
        *((("PyTorch threads (controllers.threads)", _threads_text(training["threads"])),)
          if training.get("threads") else ()),
        ("domain randomisation (per episode, uniform)", card.get("randomize") or "off"),
        *((("flight conditions (sensing error, turbulence)", card["conditions"]),) if card.get("conditions") else ()),
        *((("observation history", card["history"]),) if card.get("history") else ()),
        ("seed", training.get("seed")),
        ("machine", training.get("machine")),
        ("git commit", _git_text(training)),
        ("checkpoint evaluated below (the one to ship)", card.get("checkpoint")),
    ]
    lines += [f"| {name} | {_fmt(value)} |" for name, value in rows]
    lines += ["", "## Evaluation", "", evaluation.get("scenario", ""), ""]
    metrics = evaluation.get("metrics", {})
    if metrics:
        lines += ["| metric | value |", "| --- | --- |"]
        lines += [f"| {name} | {_fmt(value)} |" for name, value in metrics.items()]
    development = card.get("development") or {}
    if development.get("runs"):
        lines += ["", "## Development runs", "", development.get("note", ""), "",
                  "| run | env steps | wall time (s) |", "| --- | ---: | ---: |"]
        lines += [f"| {r.get('what')} | {int(r['env_steps']):,} | {_fmt(r.get('wall_time_s'))} |" for r in development["runs"]]
    curve = card_curve(card)
    if curve is not None:
        randomized = bool(card.get("randomize"))
        episodes = ((card.get("config") or {}).get("eval") or {}).get("episodes")
        note = (f"{episodes or 'the'} evaluation episodes at each point, deterministic actions, "
                + ("drawn like the training's (its randomisation included)" if randomized
                   else "on the training's settings"))
        plot_learning_curve(curve, folder / LEARNING_CURVE_PNG, title=f"Learning curve: {card.get('env_id', '?')}",
                            shipped_at=shipped_timesteps(card.get("checkpoint")), note=note)
        lines += ["", "## Learning curve", "",
                  f"![Mean evaluation return and episode length against env steps]({LEARNING_CURVE_PNG})", "",
                  f"Mean return and length of the evaluations during training ({note}); the green line is the "
                  "shipped checkpoint. The figures of the evaluation above are the model card's own flights.", ""]
    robustness = card.get("robustness")
    if robustness:
        lines += ["", "## Robustness", "", robustness.get("text", "")]
    lines += ["", "Hyperparameters and every other setting: `model_card.json` (`config`).", ""]
    md_path.write_text("\n".join(lines))
    return json_path, md_path


def set_robustness(folder: str | Path, text: str, data: dict[str, Any]) -> Path:
    """Put a robustness measurement (``text``: Markdown; ``data``: its figures) into the model card in
    ``folder`` (``robustness`` in ``model_card.json``, a section of ``model_card.md``), replacing any earlier."""
    folder = Path(folder)
    card = read_json(folder / CARD_JSON)
    if not isinstance(card, dict):
        raise ValueError(f"{folder / CARD_JSON}: not a model card")
    card["robustness"] = {"text": text, **data}
    write_model_card(folder, card)
    return folder / CARD_MD


def training_env_steps(training: dict[str, Any]) -> int:
    """Env steps a model card's ``training`` section spent: PPO's, plus a warm start's demonstrations and
    a teacher's labelled flights (``--algo dagger``)."""
    return (int(training["total_timesteps"]) + int((training.get("warm_start") or {}).get("demo_env_steps", 0))
            + int((training.get("teacher") or {}).get("labels", 0)))


def _warm_start_text(warm: dict[str, Any]) -> str:
    cloning = warm.get("cloning", {})
    return (f"{warm.get('controller')} flew {warm.get('demo_env_steps')} env steps of demonstrations in "
            f"{warm.get('demo_wall_time_s')} s; cloned in {cloning.get('wall_time_s')} s ({cloning.get('epochs')} epochs, "
            f"RMS action error on held-out flights {cloning.get('heldout_action_rmse')}); PPO then "
            f"{warm.get('ppo_wall_time_s')} s")


def _teacher_text(teacher: dict[str, Any]) -> str:
    steps = "; ".join(f"{it['pilot']} flew {it['labels']} labelled steps in {it['flight_and_labels_s']} s, fitted in "
                      f"{it['fit'].get('wall_time_s')} s (held-out action RMS error {it['fit'].get('heldout_action_rmse')})"
                      for it in teacher.get("iterations", []))
    return f"{teacher.get('controller')}: {steps}; {teacher.get('wall_time_s')} s in all"


def _split_text(split: dict[str, Any]) -> str:
    return (f"{split.get('env_step_s')} s / {split.get('rollout_other_s')} s / {split.get('update_and_callbacks_s')} s "
            f"({100 * split.get('env_step_share', 0):.0f} / {100 * split.get('rollout_other_share', 0):.0f} / "
            f"{100 * split.get('update_and_callbacks_share', 0):.0f} %)")


def _threads_text(threads: dict[str, Any]) -> str:
    start = threads.get("at_start") or {}
    if not threads.get("updates_on_threads"):  # no PPO updates (a distillation): the threads it ran on
        return f"{start.get('threads')} (setting {start.get('setting')}): {start.get('reason')}"
    first = (threads.get("first_choice") or {}).get("update") or start
    updates = ", ".join(f"{n} on {k}" for k, n in threads["updates_on_threads"].items())
    busy = threads.get("busy_elsewhere_cores")
    return (f"setting {threads.get('settings', {}).get('update', start.get('setting'))}; "
            f"updates: {updates} thread(s); first choice: {first.get('reason')}"
            + (f"; others' load seen: median {busy['median']}, max {busy['max']} cores" if busy else ""))


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return str(value)
