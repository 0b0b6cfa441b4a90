"""The Stable-Baselines3 ``PolicyPredictor`` interface shared by every controller, and its safety net.

``predict(observation, state=None, episode_start=None, deterministic=True)``
takes one observation ``(48,)`` or a batch ``(n, 48)`` from a vector env and
returns ``(actions, state)`` with normalised actions ``(4,)`` or ``(n, 4)``
(float32, as the action space). ``state`` is passed through untouched: the
controllers keep their memory (warm starts, filters) themselves, one slot per
batch index, and clear a slot when ``episode_start`` marks that env as new, or,
when ``episode_start`` is not given, when the observation's time goes backwards
(a reset). ``stable_baselines3.common.evaluation.evaluate_policy`` therefore takes
them unchanged.

Controllers follow the env they fly: a policy made by ``from_env(env)`` reads the
scene (walls) and the reference of each sub-env again at each of its episode starts
(:func:`~controllers.env_description.read_scene_and_reference`), because an env
with a randomised stand-off rebuilds both at reset. A scene whose structure changed
(another number of walls, a ground or ceiling added) cannot be followed by the
compiled model and raises ``ValueError``. A policy made from an
:class:`~controllers.env_description.EnvDescription` keeps that description's scene.

Subclasses implement :meth:`ControllerPolicy._command`, which returns the
physical command ``[T (N), wx, wy, wz (rad/s)]`` for one parsed observation; the
base class maps it through the env's :class:`~wall_env.actions.ActionMapping`.

Safety: a non-finite observation, a solver failure (:class:`SolverFailure`,
``FloatingPointError``, ``numpy.linalg.LinAlgError``) or a non-finite command
yields the hover command of :func:`hover_command` (hover thrust, body rates that
level the vehicle), increments :attr:`ControllerPolicy.failures`, records the
reason in :attr:`ControllerPolicy.failure_log` and issues a ``RuntimeWarning``.
The failing env's memory is cleared so the next step starts afresh. A policy
never returns a NaN action.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from controllers.env_description import EnvDescription, describe_env, read_scene_and_reference
from controllers.flatness import attitude_error, level_attitude
from wall_env.observation import OBSERVATION_FIELDS, OBSERVATION_SIZE, parse_observation
from wall_env.references import Reference
from wall_env.scene import Scene
from wall_env.vehicle import GRAVITY

__all__ = ["ControllerPolicy", "SolverFailure", "hover_command", "LEVELLING_GAIN"]

_TIME_INDEX = OBSERVATION_FIELDS["time"].start
LEVELLING_GAIN = np.array([6.0, 6.0, 4.0])  # 1/s, attitude gain of the hover fallback (the PID's)


class SolverFailure(RuntimeError):
    """An optimisation-based controller could not produce a usable command."""


def hover_command(mass: float, R_body_to_world: np.ndarray | None, body_rate_max: float) -> np.ndarray:
    """``[m g, rates]``: hover thrust and body rates that turn the vehicle level (keeping its heading).

    If the attitude is unknown (non-finite), the rates are zero.
    """
    command = np.zeros(4)
    command[0] = mass * GRAVITY
    if R_body_to_world is not None and np.all(np.isfinite(R_body_to_world)):
        try:
            R = np.asarray(R_body_to_world, dtype=float).reshape(1, 3, 3)
            rates = LEVELLING_GAIN * attitude_error(R, level_attitude(R))[0]
            command[1:] = np.clip(rates, -body_rate_max, body_rate_max)
        except ValueError:  # a degenerate matrix (e.g. all zeros) has no attitude
            pass
    return command


class ControllerPolicy:
    """Base class: batching, per-env memory, action mapping and the hover fallback."""

    name = "controller"

    def __init__(self, description: EnvDescription):
        self.description = description
        self.vehicle = description.vehicle
        self.action_mapping = description.action_mapping
        self.control_dt = description.control_dt
        self.failures = 0
        self.failure_log: list[str] = []
        self._memory: list[Any] = []
        self._last_time = np.zeros(0)
        self._missing = True  # some batch slot has no memory yet
        self._env_source: Any = None

    @classmethod
    def _description(cls, env: Any) -> EnvDescription:
        return env if isinstance(env, EnvDescription) else describe_env(env)

    def follow(self, env: Any) -> None:
        """Read the scene and reference of ``env``'s sub-envs at each episode start (``from_env`` calls this)."""
        self._env_source = None if isinstance(env, EnvDescription) else env

    # ------------------------------------------------------------------ SB3 interface
    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """Actions for one observation ``(48,)`` or a batch ``(n, 48)``; see the module docstring."""
        obs = np.asarray(observation, dtype=float)
        if obs.shape[-1:] != (OBSERVATION_SIZE,) or obs.ndim not in (1, 2):
            raise ValueError(f"observation must have shape ({OBSERVATION_SIZE},) or (n, {OBSERVATION_SIZE}), "
                             f"got {obs.shape}")
        single = obs.ndim == 1
        batch = obs.reshape(-1, OBSERVATION_SIZE)
        n = batch.shape[0]
        self._resize_memory(n)
        times = batch[:, _TIME_INDEX]
        new = times < self._last_time  # time went back: a reset (NaN compares false)
        if episode_start is not None:
            new |= np.broadcast_to(np.asarray(episode_start, dtype=bool).reshape(-1), (n,))
        if new.any():
            for row in np.flatnonzero(new).tolist():
                self._memory[row] = self._episode_memory(row)
        if self._missing:
            for i in range(n):
                if self._memory[i] is None:
                    self._memory[i] = self._episode_memory(i)
            self._missing = False
        np.copyto(self._last_time, times, where=np.isfinite(times))
        self._before_batch(n)
        commands = self._commands(batch)
        actions = self.action_mapping.to_normalised(commands).astype(np.float32)
        return (actions[0] if single else actions), state

    def reset(self) -> None:
        """Forget every env's memory (the next call starts new episodes)."""
        self._memory = []
        self._last_time = np.zeros(0)
        self._missing = True

    # ------------------------------------------------------------------ for subclasses
    def _command(self, fields: dict[str, np.ndarray], memory: Any, index: int) -> np.ndarray:
        """Physical command ``[T, wx, wy, wz]`` for one parsed observation (subclasses implement this
        or :meth:`_commands`)."""
        raise NotImplementedError(f"{type(self).__name__} implements neither _command nor _commands")

    def _new_memory(self, scene: Scene, reference: Reference) -> dict[str, Any]:
        """Fresh per-env memory at an episode start, for that episode's scene and reference."""
        return {"scene": scene, "reference": reference}

    def _episode_memory(self, index: int) -> dict[str, Any]:
        scene, reference = self.description.scene, self.description.reference
        if self._env_source is not None:
            scene, reference = read_scene_and_reference(self._env_source, index)
            if scene.structure != self.description.scene.structure:
                raise ValueError(f"{self.name}: env {index} now has a scene of another structure "
                                 f"({scene.structure} instead of {self.description.scene.structure}); "
                                 "build the controller again for it")
            if scene.bodies != self.description.scene.bodies:
                raise ValueError(f"{self.name}: env {index} now has other bodies in its scene than the controller "
                                 "was built for; build the controller again for it")
        return self._new_memory(scene, reference)

    def _before_batch(self, n: int) -> None:
        """Hook called once per :meth:`predict` with the batch size."""

    def _commands(self, batch: np.ndarray) -> np.ndarray:
        """Physical commands ``(n, 4)`` for a batch of observations ``(n, 48)``: by default one
        :meth:`_command` per row behind the safety net; a controller that solves the whole
        batch at once (the MPCs) overrides this and calls :meth:`_fail` for rows that failed."""
        return np.stack([self._safe_command(row, i) for i, row in enumerate(batch)])

    # ------------------------------------------------------------------ internals
    def _resize_memory(self, n: int) -> None:
        if len(self._memory) != n:
            self._memory = [None] * n
            self._last_time = np.full(n, -np.inf)
            self._missing = True

    def _safe_command(self, observation: np.ndarray, index: int) -> np.ndarray:
        fields = parse_observation(observation)
        R = fields["R_body_to_world"]
        if not np.all(np.isfinite(observation)):
            return self._fail(index, R, "non-finite observation")
        try:
            command = np.asarray(self._command(fields, self._memory[index], index), dtype=float)
        except (SolverFailure, FloatingPointError, np.linalg.LinAlgError) as exc:
            return self._fail(index, R, f"{type(exc).__name__}: {exc}")
        if command.shape != (4,) or not np.all(np.isfinite(command)):
            return self._fail(index, R, f"non-finite command {command.tolist()}")
        return command

    def _fail(self, index: int, R: np.ndarray, reason: str) -> np.ndarray:
        self.failures += 1
        self.failure_log.append(reason)
        self._memory[index] = self._new_memory(self._memory[index]["scene"], self._memory[index]["reference"])
        warnings.warn(f"{self.name}: {reason}; commanding hover (failure {self.failures})", RuntimeWarning,
                      stacklevel=4)
        return hover_command(self.vehicle.mass, R, self.vehicle.body_rate_max)
