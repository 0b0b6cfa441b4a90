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
MAX_MAGNITUDE = 1e15


@dataclass
class Signal:
    """One topic's samples: strictly increasing times ``(n,)`` s and values ``(n, k)``.

    Rows with a missing value (NaN, inf, or a magnitude of :data:`MAX_MAGNITUDE` or
    more) are dropped, then the rows are sorted by time and repeated times dropped.
    """

    name: str
    t: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float).reshape(-1)
        values = np.asarray(self.values, dtype=float)
        if values.ndim == 1:
            values = values[:, None]
        if values.ndim != 2 or len(values) != len(t):
            raise ValueError(f"signal {self.name!r}: {len(t)} times but values of shape {values.shape}")
        # NaN, inf and absurd magnitudes (no logged quantity reaches 1e15) are missing samples
        keep = np.all(np.abs(values) < MAX_MAGNITUDE, axis=1) & (np.abs(t) < MAX_MAGNITUDE)
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


def gap_free_clock(states: list[Signal], commands: list[Signal], rate_hz: float) -> tuple[np.ndarray, int]:
    """Ticks at ``rate_hz`` where every state is sampled without a gap and every command is held,
    and how many ticks of the common span fell in gaps.

    A command stays valid for three of its own sample periods after its last sample; no
    ticks at all means the topics never overlap without a gap.
    """
    t = common_clock(states + commands, rate_hz)
    ok = np.ones(len(t), dtype=bool)
    for signal in states:
        ok &= valid_mask(signal, t)
    for signal in commands:
        ok &= valid_mask(signal, t, hold_s=3.0 / max(signal.rate_hz, 1e-9))
    return t[ok], int((~ok).sum())


def interpolate(signal: Signal, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of every column at ``t`` ``(n, k)``."""
    return np.column_stack([np.interp(t, signal.t, column) for column in signal.values.T])


def interpolate_attitude(signal: Signal, t: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of quaternions ``[w, x, y, z]`` at ``t`` (clamped to the span).

    Samples whose quaternion has no direction (zero) are skipped; fewer than two usable
    samples is a ValueError naming the signal.
    """
    q = signal.values
    if q.shape[1] != 4:
        raise ValueError(f"signal {signal.name!r}: a quaternion has 4 values, got {q.shape[1]}")
    scaled = q / np.maximum(np.max(np.abs(q), axis=1, keepdims=True), 1e-300)  # no overflow in the norm
    norms = np.linalg.norm(scaled, axis=1)
    usable = norms > 1e-9
    if usable.sum() < 2:
        raise ValueError(f"signal {signal.name!r}: fewer than 2 usable (non-zero) quaternions")
    unit = scaled[usable] / norms[usable, None]
    rotations = Rotation.from_quat(unit[:, [1, 2, 3, 0]])
    slerp = Slerp(signal.t[usable], rotations)
    t = np.clip(t, signal.t[usable][0], signal.t[usable][-1])
    xyzw = slerp(t).as_quat()
    wxyz = xyzw[:, [3, 0, 1, 2]]
    return wxyz * np.where(wxyz[:, :1] < 0, -1.0, 1.0)


def hold(signal: Signal, t: np.ndarray) -> np.ndarray:
    """The latest sample at or before each ``t`` (the first sample before the signal starts).

    A signal without samples is a ValueError naming it.
    """
    if len(signal.t) == 0:
        raise ValueError(f"signal {signal.name!r} has no usable samples to hold")
    index = np.clip(np.searchsorted(signal.t, t, side="right") - 1, 0, len(signal.t) - 1)
    return signal.values[index]
