"""Latency: commands take effect late, and the state estimate reaches the controller late.

Both delays are whole physics steps (``control_dt / physics_substeps``, 1 ms by default):

``command`` (s)
    from the controller's command to the rotors acting on it (transport, ESC update). A
    command delay of ``D = q S + r`` physics steps (``S`` substeps per control step) means
    that during control step ``t`` the first ``r`` substeps still fly the command issued at
    step ``t - q - 1`` and the others the one issued at step ``t - q``.
``observation`` (s)
    from the state being true to the estimate of it arriving (estimator and transport).
    An observation delay of ``D = q S + r`` physics steps means that the observation after
    control step ``t`` carries the state of physics step ``t S - D``: the state after
    ``S - r`` substeps of the control step that ended ``q`` steps ago. The controller's
    clock (the observation's time and its reference entries) is not delayed: it compares
    a stale state with the reference of now, as a flight controller does.

:class:`DelayLine` keeps what each row needs of the past, one entry per control step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wall_env.validation import check_range

__all__ = ["Latency", "MAX_LATENCY", "DelayLine", "split_delay"]

MAX_LATENCY = 0.2  # s, the longest delay of either kind


@dataclass(frozen=True)
class Latency:
    """Command and observation delays (s); see the module docstring."""

    command: float = 0.0
    observation: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "command", check_range("latency.command (s)", self.command, 0.0, MAX_LATENCY))
        object.__setattr__(self, "observation",
                           check_range("latency.observation (s)", self.observation, 0.0, MAX_LATENCY))

    @classmethod
    def total(cls, seconds: float) -> Latency:
        """A round trip of ``seconds`` split evenly between the command and the observation."""
        seconds = check_range("latency (s)", seconds, 0.0, 2 * MAX_LATENCY)
        return cls(command=seconds / 2, observation=seconds / 2)

    @classmethod
    def from_spec(cls, spec: Any) -> Latency:
        """``None`` (none), a number (the round trip, split evenly), a dict of ``command`` and ``observation``
        or an instance."""
        if spec is None:
            return cls()
        if isinstance(spec, Latency):
            return spec
        if isinstance(spec, dict):
            unknown = sorted(set(spec) - {"command", "observation"})
            if unknown:
                raise ValueError(f"latency takes 'command' and 'observation' (s); unknown {unknown}")
            return cls(**spec)
        if isinstance(spec, (int, float, np.integer, np.floating)) and not isinstance(spec, bool):
            return cls.total(float(spec))
        raise ValueError(f"latency must be seconds, a dict of 'command' and 'observation' or a Latency, got {spec!r}")

    @property
    def seconds(self) -> float:
        return self.command + self.observation

    def physics_steps(self, physics_dt: float) -> tuple[int, int]:
        """``(command, observation)`` in whole physics steps of ``physics_dt`` seconds, or a ``ValueError``."""
        return (whole_steps("latency.command", self.command, physics_dt),
                whole_steps("latency.observation", self.observation, physics_dt))


def whole_steps(name: str, seconds: float, physics_dt: float) -> int:
    """``seconds`` as a whole number of physics steps, or a ``ValueError`` naming ``name``."""
    steps = seconds / physics_dt
    if abs(steps - round(steps)) > 1e-6 * max(1.0, steps):
        raise ValueError(f"{name} must be a whole number of physics steps of {physics_dt * 1e3:g} ms "
                         f"(control_dt / physics_substeps), got {seconds * 1e3:g} ms")
    return int(round(steps))


def split_delay(steps: np.ndarray, substeps: int) -> tuple[np.ndarray, np.ndarray]:
    """``(q, r)`` with ``steps = q substeps + r``, ``0 <= r < substeps`` (whole control steps and the rest)."""
    steps = np.asarray(steps, dtype=np.int64)
    return steps // substeps, steps % substeps


class DelayLine:
    """The latest ``depth`` values of a signal of ``width`` numbers per row, one pushed per control step.

    ``read(lag)`` gives each row the value pushed ``lag[row]`` pushes ago (0: the latest).
    """

    def __init__(self, n: int, depth: int, width: int):
        self.depth = max(1, int(depth))
        self.buffer = np.zeros((n, self.depth, width))
        self._latest = 0
        self._rows = np.arange(n)

    def fill(self, rows: np.ndarray | slice, value: np.ndarray) -> None:
        """Every entry of ``rows`` set to ``value`` (``(k, width)``; a new episode's past)."""
        self.buffer[rows] = np.asarray(value)[:, None, :]

    def push(self, values: np.ndarray) -> None:
        self._latest = (self._latest + 1) % self.depth
        self.buffer[:, self._latest] = values

    def read(self, lag: np.ndarray) -> np.ndarray:
        return self.buffer[self._rows, (self._latest - lag) % self.depth]
