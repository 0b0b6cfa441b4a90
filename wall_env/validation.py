"""Argument checks that fail early with a message naming the argument and its allowed range."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["check_range", "check_positive", "check_vector", "check_finite_array", "read_json_object"]


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


def read_json_object(path: str | Path, kind: str) -> dict[str, Any]:
    """The JSON object in ``path``; errors say which ``kind`` of file (e.g. "model file") is wrong."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{kind} {path} does not exist") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{kind} {path} is not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{kind} {path} must hold a JSON object")
    return data
