"""Evaluate any policy on any Wall Inspector task over given seeds: tracking, wall-normal error, collisions, effort.

:func:`evaluate` runs one episode per seed (``env.reset(seed=seed)``, so every
policy meets the same start perturbations and the same command-noise sequence as
long as its actions lead to the same number of noise draws, which they do: one
per step) and records, per step, from the env's ``info``: the true position
``p_world``, the reference ``p_ref``, ``collision``, ``wall_clearance``; and from the
policy the action it returned.

``policy`` is anything with SB3's ``predict(observation, state, episode_start,
deterministic)`` -- the controllers of this package, a Stable-Baselines3 model or
policy -- or a factory ``policy(env)`` returning one, called once per evaluation
with the env it will fly.

Metrics (:meth:`EvaluationResult.metrics`, pooled over all steps of all episodes;
:meth:`EpisodeRecord.metrics` per episode; lengths in m, forces in N, rates in rad/s):

``mae``, ``rmse``
    per axis (x, y, z) of ``p_world - p_ref``; ``rmse_norm`` of its length.
``wall_normal_rmse``, ``wall_normal_mae``
    of the error along the outward normal of the wall nearest to the *reference*
    position at that step (``env.scene``; positive = away from the wall). The
    reference, not the vehicle, picks the wall, so a vehicle that strays does not
    switch the axis it is judged on. Among bodies (a facade, a pier) the nearest surface
    of the scene's walls and bodies (PyBullet's closest-point query,
    :mod:`wall_env.surfaces`) gives the normal: the facade's, the ledge's above it, the
    pier's radial direction. NaN without walls or bodies.
``collisions``, ``collision_episodes``
    steps with a contact (the env counts each contact step) and episodes with at
    least one; ``min_wall_clearance``: smallest duct-to-wall distance seen.
``thrust_effort_rms``, ``body_rate_effort_rms``
    RMS of the commanded collective thrust minus hover thrust ``m g``, and of the
    commanded body rates (the policy's action through the env's action mapping,
    before command noise).
``action_change_rms``, ``thrust_change_rms``, ``body_rate_change_rms``
    smoothness: RMS of the step-to-step change of the normalised action, of the
    thrust command (N per step) and of the body-rate command (rad/s per step).
``solve_ms``
    for policies exposing ``solve_times`` (seconds per solve, as the MPCs do):
    median, mean, p99, p99.8 and max in milliseconds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

import wall_env  # registers the environments
from controllers.threads import choose_threads, limit_threads
from wall_env import interrupts
from wall_env.vehicle import GRAVITY

__all__ = ["evaluate", "evaluate_batched", "EvaluationResult", "EpisodeRecord", "solve_time_stats"]


def solve_time_stats(seconds: Sequence[float]) -> dict[str, float]:
    """Median, mean, p99, p99.8 and max of solve times, in milliseconds (NaN if empty)."""
    ms = 1e3 * np.asarray(seconds, dtype=float)
    if ms.size == 0:
        return dict.fromkeys(("median", "mean", "p99", "p99_8", "max"), math.nan) | {"count": 0}
    return {
        "median": float(np.median(ms)),
        "mean": float(ms.mean()),
        "p99": float(np.percentile(ms, 99.0)),
        "p99_8": float(np.percentile(ms, 99.8)),
        "max": float(ms.max()),
        "count": int(ms.size),
    }


@dataclass
class EpisodeRecord:
    """One flight: per-step arrays (``n`` control steps) and episode facts."""

    seed: int
    time: np.ndarray  # (n,) s
    p_world: np.ndarray  # (n, 3) m
    p_ref: np.ndarray  # (n, 3) m
    wall_normal: np.ndarray  # (n, 3) outward normal of the wall nearest to p_ref (zeros without walls)
    collision: np.ndarray  # (n,) bool
    wall_clearance: np.ndarray  # (n,) m
    action: np.ndarray  # (n, 4) normalised, as the policy returned it
    command: np.ndarray  # (n, 4) [T, wx, wy, wz] of the action, before noise
    hover_thrust: float  # N
    terminated: bool
    solve_times: list[float] = field(default_factory=list)  # s

    @property
    def error(self) -> np.ndarray:
        return self.p_world - self.p_ref

    @property
    def wall_normal_error(self) -> np.ndarray:
        return np.sum(self.error * self.wall_normal, axis=1)

    def metrics(self) -> dict[str, Any]:
        return _metrics([self])


def _rms(x: np.ndarray, axis=None) -> Any:
    return np.sqrt(np.mean(np.square(x), axis=axis)) if np.size(x) else math.nan


def _metrics(episodes: Sequence[EpisodeRecord]) -> dict[str, Any]:
    error = np.concatenate([e.error for e in episodes])
    has_walls = all(np.any(e.wall_normal) for e in episodes)
    normal_error = np.concatenate([e.wall_normal_error for e in episodes])
    command = [e.command for e in episodes]
    thrust_dev = np.concatenate([c[:, 0] - e.hover_thrust for c, e in zip(command, episodes)])
    rates = np.concatenate([c[:, 1:] for c in command])
    d_action = np.concatenate([np.diff(e.action, axis=0) for e in episodes])
    d_command = np.concatenate([np.diff(c, axis=0) for c in command])
    solve = [t for e in episodes for t in e.solve_times]
    collisions = [int(e.collision.sum()) for e in episodes]
    out: dict[str, Any] = {
        "episodes": len(episodes),
        "steps": int(error.shape[0]),
        "terminated_early": int(sum(e.terminated for e in episodes)),
        "mae": np.mean(np.abs(error), axis=0).tolist(),
        "rmse": _rms(error, axis=0).tolist(),
        "rmse_norm": float(_rms(np.linalg.norm(error, axis=1))),
        "wall_normal_rmse": float(_rms(normal_error)) if has_walls else math.nan,
        "wall_normal_mae": float(np.mean(np.abs(normal_error))) if has_walls else math.nan,
        "collisions": int(sum(collisions)),
        "collision_episodes": int(sum(c > 0 for c in collisions)),
        "min_wall_clearance": float(min(e.wall_clearance.min() for e in episodes)),
        "thrust_effort_rms": float(_rms(thrust_dev)),
        "body_rate_effort_rms": float(_rms(rates)),
        "action_change_rms": float(_rms(d_action)),
        "thrust_change_rms": float(_rms(d_command[:, 0])),
        "body_rate_change_rms": float(_rms(d_command[:, 1:])),
    }
    if solve:
        out["solve_ms"] = solve_time_stats(solve)
    return out


@dataclass
class EvaluationResult:
    """Every episode of one policy on one task."""

    policy: str
    env_id: str
    env_kwargs: dict[str, Any]
    seeds: list[int]
    episodes: list[EpisodeRecord]

    def metrics(self) -> dict[str, Any]:
        """Pooled metrics over all episodes (see the module docstring)."""
        return _metrics(self.episodes)

    def per_episode(self) -> list[dict[str, Any]]:
        return [{"seed": e.seed, **e.metrics()} for e in self.episodes]


def _policy_name(policy: Any) -> str:
    return str(getattr(policy, "name", type(policy).__name__))


def _wall_normals(scene, p_ref: np.ndarray) -> np.ndarray:
    if not scene.walls and not scene.has_bodies:
        return np.zeros_like(p_ref)
    normals = np.zeros_like(p_ref)
    nearest = np.full(len(p_ref), np.inf)
    if scene.walls:
        distances = np.abs(scene.wall_distances(p_ref))  # (n_walls, n)
        wall_normals = np.array([w.normal for w in scene.walls])
        nearest = distances.min(axis=0)
        normals = wall_normals[np.argmin(distances, axis=0)]
    if scene.has_bodies:
        from wall_env.surfaces import SurfaceQuery

        query = SurfaceQuery(scene, wall_env.VehicleParams(), reach=5.0)
        try:
            _, body_normals, body_distance = query.nearest(p_ref)
        finally:
            query.close()
        closer = body_distance < nearest
        normals = np.where(closer[:, None], body_normals, normals)
    return normals


def evaluate(
    policy: Any,
    env: str | Callable[[], gym.Env],
    seeds: Sequence[int],
    env_kwargs: dict[str, Any] | None = None,
    *,
    deterministic: bool = True,
    reset_options: dict[str, Any] | None = None,
    on_episode: Callable[[EpisodeRecord], object] | None = None,
) -> EvaluationResult:
    """Fly ``policy`` for one episode per seed on ``env`` (an env id such as
    ``"WallInspector/WallSweep-v0"`` made with ``env_kwargs``, or a zero-argument env
    factory) and return every step's record; see the module docstring.

    ``on_episode`` is called with each finished :class:`EpisodeRecord` (for progress bars).

    The flights run with PyTorch (if imported) and BLAS held at the threads that
    :func:`controllers.threads.choose_threads` gives work of one observation per call: one. A
    second thread cannot speed up a policy acting on one observation, and spinning threads slow
    everything else on a busy machine (a learner's PPO update, the other flights of a study).
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must name at least one seed")
    env_kwargs = dict(env_kwargs or {})
    if isinstance(env, str):
        env_id = env
        environment = gym.make(env, **env_kwargs)
    elif callable(env):
        if env_kwargs:
            raise ValueError("env_kwargs only apply to an env id; put them into the env factory instead")
        environment = env()
        env_id = getattr(getattr(environment, "spec", None), "id", None) or type(environment.unwrapped).__name__
    else:
        raise ValueError(f"env must be an env id or an env factory, got {type(env).__name__}")
    if not hasattr(policy, "predict"):
        if not callable(policy):
            raise ValueError("policy must have a predict() method or be a factory policy(env)")
        policy = policy(environment)
    base: Any = environment.unwrapped
    mapping = base.action_mapping
    hover_thrust = base.vehicle.mass * GRAVITY
    episodes = []
    threads = choose_threads(most=1).threads  # one observation per step
    try:
        with limit_threads(threads):
            for seed in seeds:
                episodes.append(_fly(policy, environment, seed, deterministic, reset_options, mapping, hover_thrust))
                if on_episode is not None:
                    on_episode(episodes[-1])
    finally:
        environment.close()
    return EvaluationResult(_policy_name(policy), env_id, env_kwargs, seeds, episodes)


def evaluate_batched(
    policy: Any,
    env_id: str,
    seeds: Sequence[int],
    env_kwargs: dict[str, Any] | None = None,
    *,
    deterministic: bool = True,
    reset_options: dict[str, Any] | None = None,
) -> EvaluationResult:
    """:func:`evaluate` with every seed a row of one batched env (``gym.make_vec(env_id, num_envs=len(seeds),
    vectorization_mode="vector_entry_point")``) and the policy answering the whole batch at each step.

    Row ``k`` seeded with ``seeds[k]`` flies exactly as the single env does (:mod:`wall_env.vector_env`),
    so the records equal :func:`evaluate`'s for a policy whose rows do not depend on each other (the
    controllers of this package, SB3 policies); only ``solve_times`` are not split per episode. ``policy``:
    anything with ``predict``, or a factory ``policy(envs)`` called with the vector env.
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must name at least one seed")
    envs = gym.make_vec(env_id, num_envs=len(seeds), vectorization_mode="vector_entry_point", **dict(env_kwargs or {}))
    try:
        if not hasattr(policy, "predict"):
            if not callable(policy):
                raise ValueError("policy must have a predict() method or be a factory policy(envs)")
            policy = policy(envs)
        base: Any = envs.unwrapped
        mapping = base.action_mapping
        n = len(seeds)
        observation, _ = envs.reset(seed=seeds, options=reset_options)  # type: ignore[arg-type]  # one seed a row
        scenes = [base.scene_and_reference(k)[0] for k in range(n)]
        rows: dict[str, list] = {k: [] for k in ("time", "p_world", "p_ref", "collision", "wall_clearance", "action")}
        steps = np.zeros(n, dtype=np.int64)
        running = np.ones(n, dtype=bool)
        terminated_early = np.zeros(n, dtype=bool)
        state, episode_start = None, np.ones(n, dtype=bool)
        with limit_threads(choose_threads(most=1).threads):  # a small batch per call: one thread is fastest
            while running.any():
                interrupts.check()
                action, state = policy.predict(observation, state=state, episode_start=episode_start,
                                               deterministic=deterministic)
                action = np.asarray(action, dtype=float).reshape(n, 4)
                episode_start = np.zeros(n, dtype=bool)
                observation, _, terminated, truncated, info = envs.step(action)
                for key in ("time", "p_world", "p_ref", "wall_clearance"):
                    rows[key].append(np.array(info[key], dtype=float))
                rows["collision"].append(np.array(info["collision"], dtype=bool))
                rows["action"].append(np.clip(action, -1.0, 1.0))
                steps += running
                terminated_early |= running & terminated
                running &= ~(terminated | truncated)
    finally:
        envs.close()
    stacked = {key: np.stack(value, axis=1) for key, value in rows.items()}  # (n, steps, ...)
    episodes = []
    for k, seed in enumerate(seeds):
        length = int(steps[k])
        p_ref = stacked["p_ref"][k, :length]
        action = stacked["action"][k, :length]
        episodes.append(EpisodeRecord(
            seed=seed, time=stacked["time"][k, :length], p_world=stacked["p_world"][k, :length], p_ref=p_ref,
            wall_normal=_wall_normals(scenes[k], p_ref), collision=stacked["collision"][k, :length],
            wall_clearance=stacked["wall_clearance"][k, :length], action=action, command=mapping.to_physical(action),
            hover_thrust=float(base.vehicle.mass * GRAVITY), terminated=bool(terminated_early[k])))
    return EvaluationResult(_policy_name(policy), env_id, dict(env_kwargs or {}), seeds, episodes)


def _fly(policy, env, seed, deterministic, reset_options, mapping, hover_thrust) -> EpisodeRecord:
    observation, _ = env.reset(seed=seed, options=reset_options)
    scene = env.unwrapped.scene  # after reset: a randomised stand-off may have moved things
    solve_log = getattr(policy, "solve_times", None)
    solve_start = len(solve_log) if isinstance(solve_log, list) else 0
    rows: dict[str, list] = {k: [] for k in ("time", "p_world", "p_ref", "collision", "wall_clearance", "action")}
    state, episode_start = None, True
    terminated = truncated = False
    while not (terminated or truncated):
        interrupts.check()
        action, state = policy.predict(observation, state=state, episode_start=np.array([episode_start]),
                                       deterministic=deterministic)
        action = np.asarray(action, dtype=float).reshape(4)
        episode_start = False
        observation, _, terminated, truncated, info = env.step(action)
        rows["time"].append(info["time"])
        rows["p_world"].append(info["p_world"])
        rows["p_ref"].append(info["p_ref"])
        rows["collision"].append(bool(info["collision"]))
        rows["wall_clearance"].append(info["wall_clearance"])
        rows["action"].append(np.clip(action, -1.0, 1.0))
    p_ref = np.asarray(rows["p_ref"])
    action = np.asarray(rows["action"])
    solve_times = list(solve_log[solve_start:]) if isinstance(solve_log, list) else []
    return EpisodeRecord(
        seed=seed,
        time=np.asarray(rows["time"]),
        p_world=np.asarray(rows["p_world"]),
        p_ref=p_ref,
        wall_normal=_wall_normals(scene, p_ref),
        collision=np.asarray(rows["collision"]),
        wall_clearance=np.asarray(rows["wall_clearance"]),
        action=action,
        command=mapping.to_physical(action),
        hover_thrust=hover_thrust,
        terminated=bool(terminated),
        solve_times=solve_times,
    )
