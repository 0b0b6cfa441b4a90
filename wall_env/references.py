"""Reference trajectories of the tasks: position, velocity and acceleration against time.

Every reference is a frozen dataclass (picklable, so controllers in other processes
can hold a copy) with ``position(t)``, ``velocity(t)`` and ``acceleration(t)`` for an
array of times (s) returning ``(n, 3)`` arrays in the world frame (m, m/s, m/s^2), a
constant heading ``yaw`` (rad, of body x about world z) and a ``duration`` (s).
:meth:`Reference.shifted` translates it, which is how a randomised stand-off moves it.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

__all__ = ["Reference", "HoverReference", "CircleReference", "SweepReference", "CorridorReference",
           "WaypointReference"]


def _vec(values) -> np.ndarray:
    return np.asarray(values, dtype=float)


@dataclass(frozen=True)
class Reference(ABC):
    origin: tuple[float, float, float]
    duration: float
    yaw: float

    @abstractmethod
    def _local(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Offsets from ``origin``, velocity and acceleration, each ``(n, 3)``."""

    def sample(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at times ``t`` (clamped to [0, duration])."""
        times = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        p, v, a = self._local(times)
        return p + _vec(self.origin), v, a

    def position(self, t) -> np.ndarray:
        return self.sample(t)[0]

    def velocity(self, t) -> np.ndarray:
        return self.sample(t)[1]

    def acceleration(self, t) -> np.ndarray:
        return self.sample(t)[2]

    def shifted(self, offset_world) -> Reference:
        """The same reference translated by ``offset_world`` (m)."""
        return dataclasses.replace(self, origin=tuple(_vec(self.origin) + _vec(offset_world)))


def _ramp(t: np.ndarray, ramp_time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Progress s(t) with s' rising linearly from 0 to 1 over ``ramp_time``: (s, s', s'')."""
    if ramp_time <= 0:
        return t, np.ones_like(t), np.zeros_like(t)
    inside = t < ramp_time
    s = np.where(inside, t**2 / (2 * ramp_time), t - ramp_time / 2)
    ds = np.where(inside, t / ramp_time, 1.0)
    dds = np.where(inside, 1.0 / ramp_time, 0.0)
    return s, ds, dds


@dataclass(frozen=True)
class HoverReference(Reference):
    """Hold ``origin``."""

    def _local(self, t):
        zeros = np.zeros((t.size, 3))
        return zeros, zeros.copy(), zeros.copy()


@dataclass(frozen=True)
class CircleReference(Reference):
    """Circle about ``origin`` in the plane spanned by unit vectors ``axis_u`` and ``axis_w``.

    Starts at the lowest point (``origin - radius * axis_w``) at rest; the angular speed
    rises linearly to ``2 pi / period`` over ``ramp_time``, then stays constant.
    """

    radius: float = 0.3
    period: float = 6.0
    axis_u: tuple[float, float, float] = (0.0, 1.0, 0.0)
    axis_w: tuple[float, float, float] = (0.0, 0.0, 1.0)
    ramp_time: float = 1.0

    def _local(self, t):
        u, w = _vec(self.axis_u), _vec(self.axis_w)
        rate = 2 * math.pi / self.period
        s, ds, dds = _ramp(t, self.ramp_time)
        phi = -math.pi / 2 + rate * s
        dphi, ddphi = rate * ds, rate * dds
        radial = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w
        tangent = -np.sin(phi)[:, None] * u + np.cos(phi)[:, None] * w
        p = self.radius * radial
        v = self.radius * dphi[:, None] * tangent
        a = self.radius * (ddphi[:, None] * tangent - (dphi**2)[:, None] * radial)
        return p, v, a


@dataclass(frozen=True)
class SweepReference(Reference):
    """The paper's wall flight (Fig. 10): vertical zig-zag along the wall while approaching it.

    After ``settle`` seconds of hover at ``origin``, the vertical speed is
    ``leg_speeds[i]`` (m/s) during leg i of ``leg_duration`` s, while the position along
    ``wall_normal`` moves ``approach`` metres toward the wall and back as
    ``-approach * (1 - cos(2 pi tau / T)) / 2`` over the whole sweep of duration T.
    """

    wall_normal: tuple[float, float, float] = (1.0, 0.0, 0.0)
    approach: float = 0.1
    leg_speeds: tuple[float, ...] = (0.25, -0.5, 0.5, -0.25)
    leg_duration: float = 4.0
    settle: float = 1.0

    def _local(self, t):
        n = _vec(self.wall_normal)
        sweep = self.leg_duration * len(self.leg_speeds)
        tau = np.clip(t - self.settle, 0.0, sweep)
        active = (t > self.settle) & (t < self.settle + sweep)
        leg = np.minimum((tau // self.leg_duration).astype(int), len(self.leg_speeds) - 1)
        speeds = np.asarray(self.leg_speeds)
        starts = np.concatenate([[0.0], np.cumsum(speeds * self.leg_duration)])
        z = starts[leg] + speeds[leg] * (tau - leg * self.leg_duration)
        vz = np.where(active, speeds[leg], 0.0)
        omega = 2 * math.pi / sweep
        s = -self.approach * (1 - np.cos(omega * tau)) / 2
        ds = np.where(active, -self.approach * omega * np.sin(omega * tau) / 2, 0.0)
        dds = np.where(active, -self.approach * omega**2 * np.cos(omega * tau) / 2, 0.0)
        e3 = np.array([0.0, 0.0, 1.0])
        p = s[:, None] * n + z[:, None] * e3
        v = ds[:, None] * n + vz[:, None] * e3
        a = dds[:, None] * n
        return p, v, a


@dataclass(frozen=True)
class CorridorReference(Reference):
    """Fly along ``direction`` at ``speed`` (ramped up over ``ramp_time``) while weaving
    ``weave_amplitude`` metres along ``lateral`` with period ``weave_period``, so the vehicle
    comes alternately nearer to each wall."""

    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    lateral: tuple[float, float, float] = (0.0, 1.0, 0.0)
    speed: float = 0.5
    weave_amplitude: float = 0.05
    weave_period: float = 4.0
    ramp_time: float = 1.0

    def _local(self, t):
        d, lat = _vec(self.direction), _vec(self.lateral)
        s, ds, dds = _ramp(t, self.ramp_time)
        w = 2 * math.pi / self.weave_period
        # the weave's amplitude ramps with the forward speed so the start is at rest
        y = self.weave_amplitude * np.sin(w * s)
        dy = self.weave_amplitude * w * np.cos(w * s) * ds
        ddy = self.weave_amplitude * (-(w**2) * np.sin(w * s) * ds**2 + w * np.cos(w * s) * dds)
        p = (self.speed * s)[:, None] * d + y[:, None] * lat
        v = (self.speed * ds)[:, None] * d + dy[:, None] * lat
        a = (self.speed * dds)[:, None] * d + ddy[:, None] * lat
        return p, v, a


@dataclass(frozen=True)
class WaypointReference(Reference):
    """Straight legs from waypoint to waypoint (offsets from ``origin``), each flown rest to rest with the
    minimum-jerk profile ``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5`` over ``leg_times[k]`` seconds, after
    ``settle`` seconds at the first waypoint; the last waypoint is held to the end. A leg never leaves the
    segment between its waypoints (no overshoot toward a wall), and its peak speed is 1.875 times its mean."""

    waypoints: tuple[tuple[float, float, float], ...] = ((0.0, 0.0, 0.0),)
    leg_times: tuple[float, ...] = ()
    settle: float = 1.0

    def __post_init__(self) -> None:
        if len(self.leg_times) != len(self.waypoints) - 1 or any(t <= 0 for t in self.leg_times):
            raise ValueError(f"WaypointReference needs one positive leg time per pair of waypoints, got "
                             f"{len(self.waypoints)} waypoints and leg times {self.leg_times}")

    def _local(self, t):
        points = np.asarray(self.waypoints, dtype=float)
        times = np.asarray(self.leg_times, dtype=float)
        starts = self.settle + np.concatenate([[0.0], np.cumsum(times)])
        p = np.repeat(points[:1], t.size, axis=0)
        v = np.zeros((t.size, 3))
        a = np.zeros((t.size, 3))
        for k, duration in enumerate(times):
            tau = np.clip((t - starts[k]) / duration, 0.0, 1.0)
            reached = t >= starts[k]
            step = points[k + 1] - points[k]
            s = tau**3 * (10 - 15 * tau + 6 * tau**2)
            ds = 30 * tau**2 * (1 - tau) ** 2 / duration
            dds = 60 * tau * (1 - tau) * (1 - 2 * tau) / duration**2
            p = np.where(reached[:, None], points[k] + s[:, None] * step, p)
            inside = reached & (t < starts[k + 1])
            v = np.where(inside[:, None], ds[:, None] * step, v)
            a = np.where(inside[:, None], dds[:, None] * step, a)
        return p, v, a
