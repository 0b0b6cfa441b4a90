"""Flights that excite an effect: a varied-speed survey reference and ready-made scenarios.

An effect can only be found where the flight shows it. The four wall tasks excite
wall suction (the sweep approaches the wall), ground and ceiling effects (the sweep
spans 2 m of height, so with the right altitude and ceiling it passes close to
both), thrust errors and steady forces; but none flies fast or in every direction,
and drag only shows with speed along each body axis. :class:`SurveyReference` is a
Lissajous figure whose speed along every world axis sweeps from zero to a few m/s,
or, small and slow, keeps the vehicle close to the ground, a ceiling or the wall for
the whole flight (a localised effect then dominates the log instead of hiding in
noise for most of it). Its sinusoids have no velocity steps: the sweep's steps make
the PID saturate rotors for an instant, which no aerodynamic effect describes.

Flying inside the suction zone (or under a ceiling) needs a controller stiffer than
the pull's negative stiffness: two rotors give ``2 k_s`` N/m, above the default PID's
``m Kp = 8`` N/m already at the paper's ``k_s = 4.1`` N/m, so the default PID drifts
into the wall. The wall and ceiling scenarios therefore fly the PID with larger gains.
Near a ground or a ceiling the PID also has integral action: without it, a thrust 14 %
short of the weight kept a ceiling survey 12 cm from the ceiling instead of 5 cm, and the
ground's push kept a ground survey 2 to 3 cm higher than planned, where the distance
offset of either effect no longer shows.

:class:`Retarget` flies any reference in an existing environment without changing
the environment: it rewrites the observation's reference fields (``p_error``,
``v_error``, ``reference_preview``) and exposes the new ``reference`` as the
attribute controllers read (:mod:`controllers.env_description`). The env's own
reference is then ignored, so the scenario raises ``max_tracking_error`` to keep the
env from ending the episode for straying from it.

:data:`SCENARIOS` holds named flights, each an env id, env keyword arguments and an
optional survey; ``wall-inspector fly --scenario NAME`` uses them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from wall_env.observation import OBSERVATION_FIELDS, PREVIEW_DT, PREVIEW_STEPS
from wall_env.references import Reference

__all__ = ["SurveyReference", "Retarget", "Scenario", "SCENARIOS", "survey_for"]


@dataclass(frozen=True)
class SurveyReference(Reference):
    """Lissajous survey about ``origin``: ``amplitude[i] * sin(2 pi s / period[i])`` per world axis.

    The progress ``s(t)`` ramps its rate from 0 to 1 over ``ramp_time`` so the flight
    starts at rest. Peak speed per axis is ``2 pi amplitude / period`` and peak
    acceleration ``(2 pi / period)^2 amplitude``; different periods make the speed
    along each axis visit every value in between, in every combination.

    ``start``: where the vehicle is at ``t = 0`` (the env's own start); the reference
    glides from there onto the figure over ``lead_in`` seconds with a quintic blend
    (continuous to the acceleration), so the flight has no jump at its start.
    """

    amplitude: tuple[float, float, float] = (1.5, 1.5, 0.5)  # m
    period: tuple[float, float, float] = (5.0, 6.5, 4.0)  # s
    ramp_time: float = 2.0  # s
    start: tuple[float, float, float] | None = None  # m, world
    lead_in: float = 3.0  # s

    def _local(self, t):
        amp = np.asarray(self.amplitude, dtype=float)
        w = 2 * math.pi / np.asarray(self.period, dtype=float)
        if self.ramp_time > 0:
            inside = t < self.ramp_time
            s = np.where(inside, t**2 / (2 * self.ramp_time), t - self.ramp_time / 2)
            ds = np.where(inside, t / self.ramp_time, 1.0)
            dds = np.where(inside, 1.0 / self.ramp_time, 0.0)
        else:
            s, ds, dds = t, np.ones_like(t), np.zeros_like(t)
        phase = s[:, None] * w
        p = amp * np.sin(phase)
        v = amp * w * np.cos(phase) * ds[:, None]
        a = amp * (-(w**2) * np.sin(phase) * ds[:, None] ** 2 + w * np.cos(phase) * dds[:, None])
        if self.start is not None and self.lead_in > 0:
            offset = np.asarray(self.start, dtype=float) - np.asarray(self.origin, dtype=float)
            tau = np.clip(t / self.lead_in, 0.0, 1.0)[:, None]
            blend = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
            d_blend = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / self.lead_in
            dd_blend = (60 * tau - 180 * tau**2 + 120 * tau**3) / self.lead_in**2
            p = p + (1 - blend) * offset
            v = v - d_blend * offset
            a = a - dd_blend * offset
        return p, v, a

    @property
    def peak_speed(self) -> np.ndarray:
        """Peak speed per world axis (m/s)."""
        return 2 * math.pi * np.asarray(self.amplitude) / np.asarray(self.period)


def _xyz(values: Any) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in values)
    return x, y, z


def survey_for(env: gym.Env, amplitude=(1.6, 2.1, 0.5), period=(5.0, 6.5, 4.0), centre=None,
               duration: float | None = None, lead_in: float = 3.0) -> SurveyReference:
    """A survey for ``env`` about ``centre`` (world, m; default the env reference's start), over its duration,
    gliding in from the env's start point."""
    unwrapped: Any = env.unwrapped
    base = unwrapped.reference
    start = base.position(0.0)[0]
    origin = start if centre is None else np.asarray(centre, dtype=float)
    return SurveyReference(_xyz(origin), float(duration if duration is not None else base.duration),
                           base.yaw, amplitude=_xyz(amplitude), period=_xyz(period), start=_xyz(start),
                           lead_in=lead_in)


class Retarget(gym.ObservationWrapper):
    """Fly ``reference`` instead of the env's own: observation reference fields, ``reference`` and the
    info's ``p_ref`` and ``v_ref`` follow it (so :func:`controllers.evaluation.evaluate` scores against it)."""

    def __init__(self, env: gym.Env, reference: Reference):
        super().__init__(env)
        self.reference = reference

    def _info(self, info: dict) -> dict:
        if "time" in info:
            p_ref, v_ref, _ = self.reference.sample(float(info["time"]))
            info = dict(info)
            info["p_ref"], info["v_ref"] = p_ref[0], v_ref[0]
        return info

    def reset(self, **kwargs):
        observation, info = super().reset(**kwargs)
        return observation, self._info(info)

    def step(self, action):
        observation, reward, terminated, truncated, info = super().step(action)
        return observation, reward, terminated, truncated, self._info(info)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        obs = np.array(observation, dtype=np.float64)
        f = OBSERVATION_FIELDS
        t = float(obs[f["time"]][0])
        times = t + PREVIEW_DT * np.arange(PREVIEW_STEPS + 1)
        p_ref, v_ref, _ = self.reference.sample(times)
        obs[f["p_error"]] = obs[f["p_world"]] - p_ref[0]
        obs[f["v_error"]] = obs[f["v_world"]] - v_ref[0]
        obs[f["reference_preview"]] = (p_ref[1:] - p_ref[0]).ravel()
        return obs.astype(np.float32)


@dataclass(frozen=True)
class Scenario:
    """A named flight: env id and keyword arguments, an optional survey and controller keywords.

    ``survey`` holds :func:`survey_for`'s ``amplitude``, ``period`` and ``centre`` (any
    may be omitted); ``policy_kwargs`` go to the controller (e.g. stiffer PID gains).
    """

    name: str
    description: str
    env_id: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    survey: dict[str, Any] | None = None
    policy_kwargs: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "env_id": self.env_id, "env_kwargs": dict(self.env_kwargs),
                "survey": None if self.survey is None else dict(self.survey), "policy_kwargs": dict(self.policy_kwargs)}


_NEAR = {"amplitude": (0.6, 0.6, 0.06), "period": (7.0, 9.0, 3.5)}  # slow, +-0.06 m in height
#: near a ground or a ceiling: stiff vertically, with integral action, so the survey flies the planned distances
_NEAR_GAINS = {"kp": [8.0, 8.0, 30.0], "kv": [4.0, 4.0, 11.0], "ki": [0.0, 0.0, 30.0]}
_ARM = 0.1 / math.sqrt(2.0)  # the default vehicle's rotor offset along body x (m)
FINITE_WALL_TOP = 1.2  # m, where the finite wall of ``finite-wall-survey`` ends

SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("wall-sweep", "the paper's sweep along the wall (approaching 0.1 m and back) with a PID stiff "
                 "enough (Kp 30 1/s^2 toward the wall) to fly inside the suction zone",
                 "WallInspector/WallSweep-v0", {"standoff": 0.26},
                 policy_kwargs={"kp": [30.0, 30.0, 10.0], "kv": [11.0, 11.0, 6.0]}),
        Scenario("wall-survey", "a slow 30 s survey facing the wall, the near rotors 0.08 to 0.18 m from it, "
                 "with a PID stiff enough (Kp 30 1/s^2) to fly inside the suction zone", "WallInspector/WallHover-v0",
                 {"standoff": 0.25, "altitude": 1.0, "max_tracking_error": 100.0, "duration": 30.0},
                 survey={"amplitude": (0.05, 0.6, 0.3), "period": (6.0, 9.0, 5.0), "centre": (0.13 + _ARM, 0.0, 1.0)},
                 policy_kwargs={"kp": [30.0, 30.0, 10.0], "kv": [11.0, 11.0, 6.0]}),
        Scenario("finite-wall-survey", "the wall survey along a wall that ends 1.2 m up (a box: the scene says "
                 "so), the survey crossing its top edge: the near rotors 0.08 to 0.18 m from its face, the vehicle "
                 "0.85 to 1.55 m high", "WallInspector/WallHover-v0",
                 {"standoff": 0.25, "altitude": 1.2, "max_tracking_error": 100.0, "duration": 30.0,
                  "scene": {"bodies": [{"type": "box", "size": [0.2, 6.0, FINITE_WALL_TOP],
                                        "position": [-0.1, 0.0, FINITE_WALL_TOP / 2]}]}},
                 survey={"amplitude": (0.05, 0.6, 0.35), "period": (6.0, 9.0, 5.0),
                         "centre": (0.13 + _ARM, 0.0, FINITE_WALL_TOP)},
                 policy_kwargs={"kp": [30.0, 30.0, 10.0], "kv": [11.0, 11.0, 6.0]}),
        Scenario("floor-to-ceiling", "the sweep from 0.15 m above the ground to 0.17 m under a ceiling, "
                 "0.5 m from the wall", "WallInspector/WallSweep-v0",
                 {"standoff": 0.5, "altitude": 1.15, "ceiling_z": 2.32}),
        Scenario("survey", "a Lissajous survey 3 m from the wall, up to 3 m/s horizontally and 1.5 m/s vertically",
                 "WallInspector/WallHover-v0", {"standoff": 3.0, "altitude": 2.0, "max_tracking_error": 100.0},
                 survey={"amplitude": (2.4, 3.1, 0.95), "period": (5.0, 6.5, 4.0)}),
        Scenario("ground-survey", "a slow survey 0.07 to 0.19 m above the ground, with a PID stiff vertically "
                 "(Kp 30 1/s^2) and with integral action, to hold the distances against the ground's push",
                 "WallInspector/WallHover-v0",
                 {"standoff": 1.5, "altitude": 0.5, "max_tracking_error": 100.0},
                 survey={**_NEAR, "centre": (1.5, 0.0, 0.13)}, policy_kwargs=_NEAR_GAINS),
        Scenario("ceiling-survey", "a slow survey 0.08 to 0.20 m under a ceiling at 2 m, with a PID stiff "
                 "vertically (Kp 30 1/s^2) and with integral action, against the ceiling's pull",
                 "WallInspector/WallHover-v0",
                 {"standoff": 1.5, "altitude": 1.5, "ceiling_z": 2.0, "max_tracking_error": 100.0},
                 survey={**_NEAR, "centre": (1.5, 0.0, 1.86)}, policy_kwargs=_NEAR_GAINS),
    )
}
