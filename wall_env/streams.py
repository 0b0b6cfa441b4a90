"""Per-environment random streams drawn for a whole batch with a few NumPy operations.

Every environment of a batch (and the single environment, the batch of one) owns a
stream: a 64-bit key set from its seed and a counter. Draw ``j`` of a stream is the
SplitMix64 output ``mix(key + (counter + j + 1) * 0x9E3779B97F4A7C15)`` (Steele, Lea and
Flood, 2014; the generator NumPy's ``SeedSequence`` documentation cites for seeding), so
a draw depends only on the stream's key and how many numbers it has used, never on
which batch it sits in or on its neighbours. That is what makes an env of a batch
fly exactly like a single env with the same seed, and it lets a reset of 1,000 envs
draw all their numbers at once: NumPy's ``Generator`` objects would cost a Python call
per env per draw, about a microsecond each.

Keys come from :class:`numpy.random.SeedSequence` (``seed`` or fresh entropy).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["RandomStreams", "stream_key"]

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 2.0**-53
_BLOCK_SIZE = 256  # normals a stream of one draws ahead (64 steps of command noise)


def stream_key(seed: int | None) -> np.uint64:
    """The 64-bit stream key for ``seed`` (``None``: fresh entropy from the operating system)."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
    return np.random.SeedSequence(None if seed is None else int(seed)).generate_state(1, np.uint64)[0]


def _mix(z: np.ndarray) -> np.ndarray:
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


class RandomStreams:
    """``n`` independent streams; draws return arrays of shape ``(len(rows), count)``."""

    def __init__(self, n: int):
        self.keys = np.zeros(n, dtype=np.uint64)
        self.counters = np.zeros(n, dtype=np.uint64)
        self._offsets: dict[int, np.ndarray] = {}
        # a stream of one (the single env) draws its step noise from a block of future normals:
        # the draws depend only on key and counter, so the block holds exactly what drawing them
        # one step at a time would give (until the key changes, which clears it)
        self._block: np.ndarray | None = None
        self._block_start = 0

    def seed(self, rows: Sequence[int] | np.ndarray, seeds: Sequence[int | None]) -> None:
        """Restart the streams of ``rows`` from ``seeds`` (one per row, ``None`` for entropy)."""
        rows = np.asarray(rows, dtype=np.intp)
        self.keys[rows] = [stream_key(s) for s in seeds]
        self.counters[rows] = 0
        self._block = None

    def _steps(self, count: int) -> np.ndarray:
        steps = self._offsets.get(count)
        if steps is None:
            steps = self._offsets[count] = np.arange(1, count + 1, dtype=np.uint64)
        return steps

    def bits(self, rows: np.ndarray | slice, count: int, advance: bool = True) -> np.ndarray:
        """``count`` raw 64-bit draws per row; ``advance=False`` leaves the counters as they were."""
        counters = self.counters[rows]
        z = self.keys[rows][:, None] + (counters[:, None] + self._steps(count)) * _GOLDEN
        if advance:
            self.counters[rows] = counters + np.uint64(count)
        return _mix(z)

    def uniform(self, rows: np.ndarray | slice, count: int, advance: bool = True) -> np.ndarray:
        """``count`` uniform numbers in [0, 1) per row (53-bit resolution)."""
        return (self.bits(rows, count, advance) >> _S11).astype(np.float64) * _TO_UNIT

    def normal(self, rows: np.ndarray | slice, count: int, advance: bool = True) -> np.ndarray:
        """``count`` standard normal numbers per row (``count`` even), by the Box-Muller transform
        of ``count`` uniforms."""
        if count % 2:
            raise ValueError(f"normal draws come in pairs, got count={count}")
        u = self.uniform(rows, count, advance)
        radius = np.sqrt(-2.0 * np.log1p(-u[:, 0::2]))  # 1 - u in (0, 1]: log is finite
        angle = 2.0 * np.pi * u[:, 1::2]
        out = np.empty_like(u)
        out[:, 0::2] = radius * np.cos(angle)
        out[:, 1::2] = radius * np.sin(angle)
        return out

    def step_normals(self, count: int, active: np.ndarray | None = None) -> np.ndarray:
        """``count`` standard normals for every row (``(n, count)``, as :meth:`normal` draws them),
        advancing the counters of the ``active`` rows only (a bool mask; default all)."""
        if active is None and len(self.keys) == 1:
            start = int(self.counters[0])
            offset = start - self._block_start
            block = self._block
            if block is None or offset < 0 or offset % 2 or offset + count > len(block):
                block = self._block = self.normal(slice(None), _BLOCK_SIZE, advance=False)[0]
                self._block_start, offset = start, 0
            self.counters[0] = start + count
            return block[None, offset:offset + count]
        out = self.normal(slice(None), count, advance=False)
        if active is None:
            self.counters += np.uint64(count)
        else:
            self.counters[active] += np.uint64(count)
        return out
