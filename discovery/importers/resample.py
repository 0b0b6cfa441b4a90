"""Put signals logged on different clocks onto one clock, keeping gaps as gaps.

Each :class:`Signal` is a topic's sample times (s) and values. :func:`common_clock`
lays a uniform clock over the span every required signal covers; :func:`valid_mask`
drops the ticks where some signal has a gap (two consecutive samples further apart
than ``gap_factor`` times its median period), so the written log has a time jump
there and the reader splits it into segments. States are interpolated linearly
(attitudes by spherical linear interpolation); commands are held from their time
to the next (:func:`hold`), as the log format defines them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

__all__ = ["Signal", "common_clock", "valid_mask", "interpolate", "interpolate_attitude", "hold"]

GAP_FACTOR = 3.0


@dataclass
class Signal:
    """One topic's samples: strictly increasing times ``(n,)`` s and values ``(n, k)``."""

    name: str
    t: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        values = np.asarray(self.values, dtype=float).reshape(len(t), -1)
        keep = np.all(np.isfinite(values), axis=1) & np.isfinite(t)
        t, values = t[keep], values[keep]
        order = np.argsort(t, kind="stable")
        t, values = t[order], values[order]
        unique = np.concatenate([[True], np.diff(t) > 0]) if len(t) else np.zeros(0, dtype=bool)
        self.t, self.values = t[unique], values[unique]

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t))) if len(self.t) > 1 else 0.0


def common_clock(signals: list[Signal], rate_hz: float) -> np.ndarray:
    """Uniform times at ``rate_hz`` over the span all ``signals`` cover."""
    for s in signals:
        if len(s.t) < 2:
            raise ValueError(f"signal {s.name!r} has {len(s.t)} usable sample(s); at least 2 are needed")
    start = max(float(s.t[0]) for s in signals)
    stop = min(float(s.t[-1]) for s in signals)
    if stop <= start:
        raise ValueError("the signals " + ", ".join(repr(s.name) for s in signals) + " do not overlap in time")
    return start + np.arange(int(np.floor((stop - start) * rate_hz)) + 1) / rate_hz


def valid_mask(signal: Signal, t: np.ndarray, gap_factor: float = GAP_FACTOR, hold_s: float = 0.0) -> np.ndarray:
    """Ticks ``t`` that fall between two samples of ``signal`` no more than ``gap_factor`` median periods apart.

    ``hold_s``: a held command also stays valid this long after its last sample.
    """
    period = float(np.median(np.diff(signal.t)))
    index = np.searchsorted(signal.t, t, side="right")
    inside = (index > 0) & (index < len(signal.t))
    ok = np.zeros(len(t), dtype=bool)
    spacing = signal.t[np.clip(index, 1, len(signal.t) - 1)] - signal.t[np.clip(index - 1, 0, len(signal.t) - 2)]
    ok[inside] = spacing[inside] <= gap_factor * period
    on_sample = np.isin(t, signal.t)
    ok |= on_sample
    if hold_s > 0:
        after = (index == len(signal.t)) & (t - signal.t[-1] <= hold_s)
        ok |= after
    return ok


def interpolate(signal: Signal, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of every column at ``t`` ``(n, k)``."""
    return np.column_stack([np.interp(t, signal.t, column) for column in signal.values.T])


def interpolate_attitude(signal: Signal, t: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of quaternions ``[w, x, y, z]`` at ``t`` (clamped to the span)."""
    q = signal.values
    rotations = Rotation.from_quat(q[:, [1, 2, 3, 0]])
    slerp = Slerp(signal.t, rotations)
    xyzw = slerp(np.clip(t, signal.t[0], signal.t[-1])).as_quat()
    wxyz = xyzw[:, [3, 0, 1, 2]]
    return wxyz * np.where(wxyz[:, :1] < 0, -1.0, 1.0)


def hold(signal: Signal, t: np.ndarray) -> np.ndarray:
    """The latest sample at or before each ``t`` (the first sample before the signal starts)."""
    index = np.clip(np.searchsorted(signal.t, t, side="right") - 1, 0, len(signal.t) - 1)
    return signal.values[index]
