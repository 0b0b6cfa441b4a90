"""What an agent remembers: the last observations and a leaky integral of its position error.

A memoryless policy sees one observation and cannot tell a wall that pulls harder than
usual, a steady push or a late estimate from its own tracking error: they differ only in how
the state answered the last commands. :class:`ObservationHistory` turns the env's observation
into the agent's input, per env row:

- the last ``frames`` observations, ``stride`` control steps apart (newest last; before an
  episode has that many, the first observation of the episode stands in for the missing ones),
- optionally a leaky integral of the observation's position error ``p_error`` (m s), with time
  constant ``integral_time`` (s): ``I <- exp(-dt / T) I + dt p_error``, the integral action a
  controller uses against a steady force, here for the policy to use or not.

The same object serves training (:class:`VecObservationHistory`, a Stable-Baselines3 ``VecEnv``
wrapper) and flying (:class:`~agents.policy.TrainedPolicy` applies it before the network, with
memory per batch row cleared at each episode start), so a loaded agent sees exactly what it
was trained on. Its settings travel in the checkpoint's ``policy.json`` (``history``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from wall_env.observation import OBSERVATION_FIELDS, OBSERVATION_SIZE
from wall_env.validation import check_range

__all__ = ["FlightMemory", "HistorySettings", "ObservationHistory", "VecObservationHistory"]

_P_ERROR = OBSERVATION_FIELDS["p_error"]


@dataclass(frozen=True)
class HistorySettings:
    """``frames`` observations ``stride`` steps apart, and a position-error integral of time constant
    ``integral_time`` (s; 0: none) at a control period of ``control_dt`` (s)."""

    frames: int = 1
    stride: int = 1
    integral_time: float = 0.0
    control_dt: float = 0.01

    def __post_init__(self) -> None:
        for name, high in (("frames", 64), ("stride", 100)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= high:
                raise ValueError(f"history.{name} must be an integer in [1, {high}], got {value!r}")
        check_range("history.integral_time (s)", self.integral_time, 0.0, 1000.0)
        check_range("history.control_dt (s)", self.control_dt, 1e-4, 1.0)

    @classmethod
    def from_spec(cls, spec: Any) -> HistorySettings:
        if spec is None:
            return cls()
        if isinstance(spec, HistorySettings):
            return spec
        if isinstance(spec, dict):
            unknown = sorted(map(str, set(spec) - set(cls.__dataclass_fields__)))
            if unknown:
                raise ValueError(f"history takes {sorted(cls.__dataclass_fields__)}; unknown {unknown}")
            return cls(**spec)
        raise ValueError(f"history must be a dict of {sorted(cls.__dataclass_fields__)}, got {spec!r}")

    @property
    def trivial(self) -> bool:
        """The observation as it is: nothing remembered."""
        return self.frames == 1 and self.integral_time == 0.0

    @property
    def size(self) -> int:
        """The network's inputs for the env's observation (:data:`OBSERVATION_SIZE` entries)."""
        return self.input_size(OBSERVATION_SIZE)

    def input_size(self, observation_size: int) -> int:
        """The network's inputs for observations of ``observation_size`` entries (a residual agent's
        observation carries its base controller's command too)."""
        return self.frames * observation_size + (3 if self.integral_time > 0 else 0)

    def observation_size(self, input_size: int) -> int:
        """The observation width that gives a network of ``input_size`` inputs (inverse of :meth:`input_size`)."""
        return (input_size - (3 if self.integral_time > 0 else 0)) // self.frames

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def observation_width(space: spaces.Space) -> int:
    """Entries of a flat observation space (a history stacks flat observations only)."""
    shape = space.shape
    if shape is None or len(shape) != 1:
        raise ValueError(f"an observation history needs flat observations (a 1-D Box), got the space {space}")
    return int(shape[0])


class ObservationHistory:
    """The per-row memory of :class:`HistorySettings` for a batch of ``n`` rows (resized on demand)."""

    def __init__(self, settings: HistorySettings, observation_size: int = OBSERVATION_SIZE):
        self.settings = settings
        self.observation_size = int(observation_size)
        self._span = (settings.frames - 1) * settings.stride + 1  # observations kept per row
        self._decay = math.exp(-settings.control_dt / settings.integral_time) if settings.integral_time > 0 else 0.0
        self._picks = np.arange(0, self._span, settings.stride)  # oldest kept .. newest
        self._buffer = np.zeros((0, self._span, self.observation_size), dtype=np.float32)
        self._integral = np.zeros((0, 3))

    def _resize(self, n: int) -> None:
        if self._buffer.shape[0] != n:
            self._buffer = np.zeros((n, self._span, self.observation_size), dtype=np.float32)
            self._integral = np.zeros((n, 3))

    def start(self, rows: np.ndarray, observations: np.ndarray) -> None:
        """New episodes in the bool mask ``rows``, whose first observations are ``observations`` (all rows)."""
        self._buffer[rows] = observations[rows, None, :]
        self._integral[rows] = 0.0

    def __call__(self, observations: np.ndarray, episode_start: np.ndarray | None = None) -> np.ndarray:
        """The agent's inputs ``(n, size)`` for the env's observations ``(n, 48)``; rows marked in
        ``episode_start`` (or every row, the first time) begin a new memory."""
        obs = np.asarray(observations, dtype=np.float32)
        if obs.ndim != 2 or obs.shape[1] != self.observation_size:
            raise ValueError(f"observations must have shape (n, {self.observation_size}), got {obs.shape}")
        n = obs.shape[0]
        fresh = self._buffer.shape[0] != n
        self._resize(n)
        starts = np.ones(n, dtype=bool) if fresh else np.zeros(n, dtype=bool)
        if episode_start is not None:
            starts |= np.broadcast_to(np.asarray(episode_start, dtype=bool).reshape(-1), (n,))
        if starts.any():
            self.start(starts, obs)
        if self._span > 1:
            self._buffer[:, :-1] = self._buffer[:, 1:]
        self._buffer[:, -1] = obs
        parts = [self._buffer[:, self._picks].reshape(n, -1)]
        if self.settings.integral_time > 0:
            error = np.nan_to_num(obs[:, _P_ERROR].astype(float))
            self._integral = self._decay * self._integral + self.settings.control_dt * error
            self._integral[starts] = self.settings.control_dt * error[starts]
            parts.append(self._integral.astype(np.float32))
        return np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0]


class FlightMemory:
    """A flying policy's :class:`ObservationHistory`: it takes the env's observations as they come
    and finds the episode starts itself (a batch of another size, time going back, a row after a
    non-finite observation, or ``episode_start``). A non-finite row is remembered as zeros and
    begins afresh at its next finite observation. :class:`~agents.policy.TrainedPolicy` and
    :class:`~agents.export.OnnxPolicy` keep one each, so both give the network the same inputs."""

    def __init__(self, settings: HistorySettings, observation_size: int = OBSERVATION_SIZE):
        self.history = ObservationHistory(settings, observation_size)
        self._last_time = np.zeros(0)
        self._restart = np.zeros(0, dtype=bool)

    @property
    def settings(self) -> HistorySettings:
        return self.history.settings

    @property
    def observation_size(self) -> int:
        return self.history.observation_size

    def __call__(self, observations: np.ndarray, episode_start: Any = None) -> np.ndarray:
        """The network's inputs ``(n, size)`` for env observations ``(n, observation_size)``."""
        obs = np.asarray(observations, dtype=np.float32)
        n = obs.shape[0]
        if self._last_time.shape[0] != n:
            self._last_time = np.full(n, -np.inf)
            self._restart = np.ones(n, dtype=bool)
        times = obs[:, OBSERVATION_FIELDS["time"].start].astype(float)
        starts = self._restart | (times < self._last_time)  # time going back: a reset (NaN compares false)
        if episode_start is not None:
            starts |= np.broadcast_to(np.asarray(episode_start, dtype=bool).reshape(-1), (n,))
        finite = np.all(np.isfinite(obs), axis=1)
        self._restart = ~finite  # a row that broke begins afresh at its next finite observation
        np.copyto(self._last_time, times, where=np.isfinite(times))
        clean = np.where(finite[:, None], obs, 0.0).astype(np.float32)
        return self.history(clean, starts)


class VecObservationHistory(VecEnvWrapper):
    """A Stable-Baselines3 vector env whose observations are :class:`ObservationHistory`'s inputs."""

    def __init__(self, venv: VecEnv, settings: HistorySettings):
        width = observation_width(venv.observation_space)
        self.history = ObservationHistory(settings, width)
        size = settings.input_size(width)
        space = spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float32)
        super().__init__(venv, observation_space=space)
        self._ended = np.ones(venv.num_envs, dtype=bool)

    def reset(self) -> np.ndarray:
        obs = self.venv.reset()
        self._ended[:] = True
        return self.history(np.asarray(obs), self._ended)

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        # SB3 resets an ended env in the same step: its observation is the next episode's first one,
        # and the ended episode's last is in its info, which gets the episode's own memory
        for k in np.flatnonzero(dones):
            terminal = infos[k].get("terminal_observation")
            if terminal is not None:
                infos[k]["terminal_observation"] = self._terminal(k, terminal)
        features = self.history(np.asarray(obs), dones)
        return features, rewards, dones, infos

    def _terminal(self, row: int, terminal: np.ndarray) -> np.ndarray:
        """The inputs the ended episode's last observation would have given (its memory, one more step)."""
        saved = (self.history._buffer[row].copy(), self.history._integral[row].copy())
        buffer, integral = saved
        single = ObservationHistory(self.history.settings, self.history.observation_size)
        single._resize(1)
        single._buffer[0], single._integral[0] = buffer, integral
        return single(np.asarray(terminal, dtype=np.float32)[None, :], np.zeros(1, dtype=bool))[0]
