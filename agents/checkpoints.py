"""Saving and loading trained agents, and their model cards.

A checkpoint is a folder with three files:

``model.zip``
    the Stable-Baselines3 PPO model (network weights, optimiser, hyperparameters).
``normalization.json``
    the ``VecNormalize`` statistics the policy was trained with: observation running
    mean/variance/count, the return statistics that scale rewards, ``clip_obs``,
    ``clip_reward``, ``epsilon``, ``gamma``. JSON rather than a pickle, so that the
    file is readable, small, safe to load and independent of library versions; floats
    round-trip exactly.
``policy.json``
    what the policy is: environment id, observation size, the residual base controller
    (if any) and its correction scale, and a *check*: a few observations and the
    deterministic actions the in-memory model gave for them when it was saved. Loading
    recomputes those actions and refuses a checkpoint whose model and statistics do
    not reproduce them (mismatched or damaged files).

A training run's folder holds the final checkpoint at its top level, the best one
(by the evaluation callback) in ``best/``, periodic ones in ``checkpoints/<steps>/``,
plus ``config.yaml``, TensorBoard logs in ``tb/`` and the model card
(``model_card.json`` and ``model_card.md``).

Every failure to load names the file: :class:`CheckpointNotFoundError` (also a
``FileNotFoundError``) for a missing file, :class:`CheckpointError` for one that is
unreadable or inconsistent.
"""

from __future__ import annotations

import json
import math
import shutil
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "MODEL_FILE",
    "NORMALIZATION_FILE",
    "POLICY_FILE",
    "CheckpointError",
    "CheckpointNotFoundError",
    "normalization_state",
    "restore_normalization",
    "normalize_observation",
    "save_checkpoint",
    "read_json",
    "load_model",
    "checkpoint_files",
    "write_model_card",
    "copy_checkpoint",
]

MODEL_FILE = "model.zip"
NORMALIZATION_FILE = "normalization.json"
POLICY_FILE = "policy.json"
CARD_JSON = "model_card.json"
CARD_MD = "model_card.md"
FORMAT_VERSION = 1


class CheckpointError(RuntimeError):
    """A checkpoint file exists but cannot be used; the message names the file."""


class CheckpointNotFoundError(CheckpointError, FileNotFoundError):
    """A checkpoint file (or folder) does not exist; the message names it."""


# ---------------------------------------------------------------------- normalisation statistics
def normalization_state(vec_normalize) -> dict[str, Any]:
    """The statistics of a ``VecNormalize`` as a JSON-ready dict."""
    return {
        "format": FORMAT_VERSION,
        "norm_obs": bool(vec_normalize.norm_obs),
        "norm_reward": bool(vec_normalize.norm_reward),
        "clip_obs": float(vec_normalize.clip_obs),
        "clip_reward": float(vec_normalize.clip_reward),
        "epsilon": float(vec_normalize.epsilon),
        "gamma": float(vec_normalize.gamma),
        "obs_mean": vec_normalize.obs_rms.mean.tolist(),
        "obs_var": vec_normalize.obs_rms.var.tolist(),
        "obs_count": float(vec_normalize.obs_rms.count),
        "ret_mean": float(vec_normalize.ret_rms.mean),
        "ret_var": float(vec_normalize.ret_rms.var),
        "ret_count": float(vec_normalize.ret_rms.count),
    }


def restore_normalization(vec_normalize, state: dict[str, Any]) -> None:
    """Put saved statistics into a ``VecNormalize`` (e.g. to resume training)."""
    vec_normalize.norm_obs = state["norm_obs"]
    vec_normalize.norm_reward = state["norm_reward"]
    vec_normalize.clip_obs = state["clip_obs"]
    vec_normalize.clip_reward = state["clip_reward"]
    vec_normalize.epsilon = state["epsilon"]
    vec_normalize.gamma = state["gamma"]
    vec_normalize.obs_rms.mean = np.asarray(state["obs_mean"], dtype=np.float64)
    vec_normalize.obs_rms.var = np.asarray(state["obs_var"], dtype=np.float64)
    vec_normalize.obs_rms.count = state["obs_count"]
    vec_normalize.ret_rms.mean = np.float64(state["ret_mean"])
    vec_normalize.ret_rms.var = np.float64(state["ret_var"])
    vec_normalize.ret_rms.count = state["ret_count"]


def normalize_observation(state: dict[str, Any], obs: np.ndarray) -> np.ndarray:
    """The observation the network sees: ``clip((obs - mean) / sqrt(var + eps), +-clip_obs)``,
    float32, exactly as ``VecNormalize.normalize_obs`` computes it."""
    obs = np.asarray(obs, dtype=np.float32)
    if not state["norm_obs"]:
        return obs
    mean, var = state["_mean"], state["_var"]
    out = np.clip((obs - mean) / np.sqrt(var + state["epsilon"]), -state["clip_obs"], state["clip_obs"])
    return out.astype(np.float32)


def _check_normalization(state: Any, path: Path) -> dict[str, Any]:
    required = ("norm_obs", "clip_obs", "epsilon", "obs_mean", "obs_var")
    if not isinstance(state, dict) or any(k not in state for k in required):
        raise CheckpointError(f"{path}: not a normalisation file (needs keys {list(required)})")
    mean = np.asarray(state["obs_mean"], dtype=np.float64)
    var = np.asarray(state["obs_var"], dtype=np.float64)
    if mean.ndim != 1 or mean.shape != var.shape or not np.all(np.isfinite(mean)) or not np.all(var >= 0):
        raise CheckpointError(f"{path}: observation statistics are malformed (mean shape {mean.shape}, var shape {var.shape})")
    return {**state, "_mean": mean, "_var": var}


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
        raise CheckpointError(f"{folder} is not a checkpoint folder (expected {MODEL_FILE}, {NORMALIZATION_FILE}, {POLICY_FILE})")
    return {"model": folder / MODEL_FILE, "normalization": folder / NORMALIZATION_FILE, "policy": folder / POLICY_FILE}


def save_checkpoint(folder: str | Path, model, vec_normalize, policy_info: dict[str, Any],
                    check_observations: np.ndarray | None = None) -> Path:
    """Write ``model.zip``, ``normalization.json`` and ``policy.json`` into ``folder``.

    ``check_observations`` (raw, un-normalised, ``(n, obs_size)``) are stored with the
    deterministic actions the model gives for them now, for :func:`load_model` to verify.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model.save(folder / MODEL_FILE)
    state = normalization_state(vec_normalize)
    (folder / NORMALIZATION_FILE).write_text(json.dumps(state))
    info = {"format": FORMAT_VERSION, **policy_info}
    if check_observations is not None and len(check_observations):
        obs = np.asarray(check_observations, dtype=np.float32)
        normalized = normalize_observation(_check_normalization(state, folder / NORMALIZATION_FILE), obs)
        actions, _ = model.predict(normalized, deterministic=True)
        info["check"] = {"observations": obs.tolist(), "actions": np.asarray(actions, dtype=np.float64).tolist()}
    (folder / POLICY_FILE).write_text(json.dumps(info, indent=1))
    return folder


def load_model(folder: str | Path, verify: bool = True):
    """Load a checkpoint folder: ``(model, normalization_state, policy_info)``.

    Raises :class:`CheckpointNotFoundError` or :class:`CheckpointError` naming the file.
    """
    from stable_baselines3 import PPO

    files = checkpoint_files(folder)
    for path in files.values():
        if not path.is_file():
            raise CheckpointNotFoundError(f"checkpoint file {path} does not exist")
    info = read_json(files["policy"])
    if not isinstance(info, dict) or "env_id" not in info:
        raise CheckpointError(f"{files['policy']}: not a policy description (no env_id)")
    state = _check_normalization(read_json(files["normalization"]), files["normalization"])
    if not zipfile.is_zipfile(files["model"]):
        raise CheckpointError(f"{files['model']}: corrupted or not a Stable-Baselines3 model archive (not a zip file)")
    try:
        model = PPO.load(files["model"], device="cpu")
    except Exception as exc:  # noqa: BLE001 - any failure here means the file is unusable
        raise CheckpointError(f"{files['model']}: corrupted or not a Stable-Baselines3 PPO model ({type(exc).__name__}: {exc})") from exc
    obs_size = int(np.prod(model.observation_space.shape))
    if state["_mean"].shape != (obs_size,):
        raise CheckpointError(f"{files['normalization']}: statistics for {state['_mean'].shape[0]} observation entries, "
                              f"but {files['model']} expects {obs_size}")
    if verify and "check" in info:
        obs = np.asarray(info["check"]["observations"], dtype=np.float32)
        expected = np.asarray(info["check"]["actions"], dtype=np.float64)
        actions, _ = model.predict(normalize_observation(state, obs), deterministic=True)
        if not np.allclose(actions, expected, rtol=1e-5, atol=1e-6):
            worst = float(np.max(np.abs(np.asarray(actions) - expected)))
            raise CheckpointError(f"{files['model']} with {files['normalization']} does not reproduce the actions recorded "
                                  f"in {files['policy']} (largest difference {worst:.3g}): the files do not belong together "
                                  "or one is damaged")
    return model, state, info


def copy_checkpoint(source: str | Path, target: str | Path, extra_files: tuple[str, ...] = ()) -> Path:
    """Copy a checkpoint folder's files (and ``extra_files`` from ``source``'s parent, if present)."""
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


def write_model_card(folder: str | Path, card: dict[str, Any]) -> tuple[Path, Path]:
    """Write ``model_card.json`` (everything) and ``model_card.md`` (for people) into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    json_path, md_path = folder / CARD_JSON, folder / CARD_MD
    json_path.write_text(json.dumps(card, indent=2, default=_jsonable))
    training, evaluation = card.get("training", {}), card.get("evaluation", {})
    lines = [
        f"# PPO agent for {card.get('env_id', '?')}",
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
        ("domain randomisation", card.get("randomize") or "off"),
        ("seed", training.get("seed")),
        ("machine", training.get("machine")),
        ("git commit", training.get("git_commit")),
        ("checkpoint evaluated below (the one to ship)", card.get("checkpoint")),
    ]
    lines += [f"| {name} | {_fmt(value)} |" for name, value in rows]
    lines += ["", "## Evaluation", "", evaluation.get("scenario", ""), ""]
    metrics = evaluation.get("metrics", {})
    if metrics:
        lines += ["| metric | value |", "| --- | --- |"]
        lines += [f"| {name} | {_fmt(value)} |" for name, value in metrics.items()]
    lines += ["", "Hyperparameters and every other setting: `model_card.json` (`config`).", ""]
    md_path.write_text("\n".join(lines))
    return json_path, md_path


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return str(value)
