"""Argument checks that fail early with a message naming the argument and its allowed range."""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["check_range", "check_positive", "check_vector", "check_finite_array", "read_mapping",
           "read_json_object", "check_output_folder"]


def _as_float(name: str, value: Any) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return number


def check_range(name: str, value: Any, low: float, high: float) -> float:
    """Return ``value`` as a float if ``low <= value <= high``, else raise ``ValueError``."""
    number = _as_float(name, value)
    if not low <= number <= high:
        raise ValueError(f"{name} must be in [{low:g}, {high:g}], got {number:g}")
    return number


def check_positive(name: str, value: Any, high: float = math.inf) -> float:
    """Return ``value`` as a float if ``0 < value <= high``, else raise ``ValueError``."""
    number = _as_float(name, value)
    if not 0.0 < number <= high:
        raise ValueError(f"{name} must be in (0, {high:g}], got {number:g}")
    return number


def check_vector(name: str, value: Any, size: int, low: float = -math.inf, high: float = math.inf) -> tuple[float, ...]:
    """Return ``value`` as a tuple of ``size`` floats, each within ``[low, high]``."""
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {size} numbers, got {value!r}") from None
    if array.size != size:
        raise ValueError(f"{name} must be {size} numbers, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if np.any(array < low) or np.any(array > high):
        raise ValueError(f"each entry of {name} must be in [{low:g}, {high:g}], got {array.tolist()}")
    return tuple(float(v) for v in array)


def check_finite_array(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Return ``value`` as a float array of ``shape`` with finite entries."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric with shape {shape}, got {value!r}") from None
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite (no NaN or inf), got {array.tolist()}")
    return array


def read_mapping(path: str | Path, kind: str, fmt: str | None = None, empty_is_mapping: bool = False) -> dict[str, Any]:
    """The mapping held by the JSON or YAML file at ``path``.

    ``fmt``: ``"json"``, ``"yaml"``, or ``None`` to go by the suffix (``.json``, ``.yaml``,
    ``.yml``). ``empty_is_mapping``: an empty YAML document reads as ``{}``. Errors say
    which ``kind`` of file (e.g. "model file") is wrong, and where.
    """
    path = Path(path)
    if fmt is None:
        suffix = path.suffix.lower()
        if suffix not in (".json", ".yaml", ".yml"):
            raise ValueError(f"{kind} {path} must end in .json, .yaml or .yml")
        fmt = "json" if suffix == ".json" else "yaml"
    loads: Any
    syntax_errors: tuple[type[Exception], ...]
    if fmt == "json":
        loads, syntax_errors = json.loads, (json.JSONDecodeError,)
    else:
        import yaml

        loads, syntax_errors = yaml.safe_load, (yaml.YAMLError,)
    try:
        data = loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{kind} {path} does not exist") from None
    except syntax_errors as exc:
        raise ValueError(f"{kind} {path} is not valid {fmt.upper()}: {exc}") from None
    if data is None and empty_is_mapping:
        data = {}
    if not isinstance(data, dict):
        what = "a JSON object" if fmt == "json" else "a mapping"
        raise ValueError(f"{kind} {path} must hold {what}, got {type(data).__name__}")
    return data


def read_json_object(path: str | Path, kind: str) -> dict[str, Any]:
    """The JSON object in ``path`` (whatever its suffix); errors name the ``kind`` of file."""
    return read_mapping(path, kind, "json")


def check_output_folder(path: str | Path, name: str = "--out") -> Path:
    """Check that ``path`` is a folder we can write into, or one we can create, without
    creating it; ``ValueError`` naming ``name`` and the reason otherwise.

    Commands call this before doing any work, so a bad output path fails at once.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{name} {path}: exists and is not a folder")
    existing = path if path.exists() else next((p for p in path.absolute().parents if p.exists()), Path("/"))
    if not existing.is_dir():
        raise ValueError(f"{name} {path}: {existing} is not a folder")
    try:  # the only sure test (root passes permission checks, virtual file systems refuse anyway)
        os.rmdir(tempfile.mkdtemp(prefix=".write-test-", dir=existing))
    except OSError as exc:
        raise ValueError(f"{name} {path}: cannot create files in {existing} ({exc.strerror or exc})") from None
    return path
