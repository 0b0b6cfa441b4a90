"""Strikes on a wall: a rotor's guard (or the frame) touches a wall, and the wall pushes the vehicle.

Near a wall the rotors' airflow pulls the vehicle *toward* it; no aerodynamic effect near a
wall pushes it away harder than the thrust does (drag on the slow approach speeds near a
wall is small). A wall that stops the vehicle does: a guard gives a few millimetres and stops
it within a few tens of milliseconds, while the vehicle's own loop brakes over hundreds (it
must first tilt the thrust away). So a strike shows as a short outward acceleration well
beyond the thrust's, at the vehicle's closest approach to that wall; and a vehicle that
struck a wall several times was stopped each time at about the same distance: the guard's
reach.

In contact (the impact, then pinned against or sliding along the wall) the wall carries
part of the force, and friction may hold the vehicle up. In the force residual a pinned
vehicle looks like a suction too weak (it does not accelerate, however hard suction pulls),
so a fit that keeps these samples finds a wrong k_s and an unexplained force "against
thrust". :func:`wall_strikes` finds the strikes and the samples at or nearer than the
distance they happened at; the workflow leaves those out with the reason "wall contact".

Without an accelerometer column the jolt is read from the logged velocity; a velocity estimate
smoothed over more than the jolt's window (a filtered motion-capture derivative, say 50 ms) spreads
a strike too thin to find, and the contact is then fitted as a suction too weak. Log the
acceleration (``ax, ay, az``) when the vehicle may touch a wall.

The test is one-sided and needs repetition, so that steady flight close to a wall (a hold at
a few centimetres, a survey that turns back at the same distance each pass) is not taken for
contact: at least :data:`MIN_STRIKES` separate outward jolts of :data:`STRIKE_Z` robust
standard deviations of the log's own scatter, each within :data:`SAME_DISTANCE` of the
closest approach, and each after the vehicle came at the wall with at least
:data:`APPROACH_SHARE` of the speed the jolt took away (a glitch in the velocity estimate
during a hold jolts a vehicle that was not moving).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from discovery.coverage import NEAR_SURFACE
from discovery.differentiation import moving_average
from discovery.flight_log import FlightLog

__all__ = ["WallStrikes", "wall_strikes", "outward_jolt", "STRIKE_WINDOW_S", "STRIKE_Z", "MIN_STRIKES",
           "SAME_DISTANCE", "CONTACT_MARGIN"]

STRIKE_WINDOW_S = 0.03  # s: a guard stops the vehicle in about this long; the loop's braking takes hundreds of ms
STRIKE_Z = 4.0  # robust standard deviations of the outward acceleration beyond the thrust's
SAME_DISTANCE = 0.005  # m: strikes within this of the closest approach to a wall are stopped at one distance
MIN_STRIKES = 2  # separate strikes (at least STRIKE_SEPARATION_S apart) before a wall is taken to be struck
STRIKE_SEPARATION_S = 0.2  # s
CONTACT_MARGIN = 0.002  # m past the farthest strike's distance that still counts as touching (the guard's give)
APPROACH_SHARE = 0.5  # of the speed a jolt takes away, the least the vehicle came at the wall with before it
SCATTER_FLOOR = 0.05  # m/s^2: the least scatter a jolt is measured against (a noise-free simulated log has none)


@dataclass(frozen=True)
class WallStrikes:
    """The strikes on wall ``wall`` of a log's scene and the samples in contact with it."""

    wall: int
    times: np.ndarray  # (strikes,) s: the strongest jolt of each strike
    closest: float  # m: the nearest rotor centre's closest approach to the wall plane
    touch_distance: float  # m: the farthest strike's distance plus CONTACT_MARGIN; nearer than this is contact
    in_contact: np.ndarray  # (n,) bool: nearer the wall than touch_distance, or within STRIKE_WINDOW_S of it


def outward_jolt(log: FlightLog, normal: np.ndarray) -> np.ndarray:
    """The acceleration along ``normal`` beyond the thrust's (m/s^2), each over about :data:`STRIKE_WINDOW_S`: the
    logged acceleration averaged over the window where the log has one (an accelerometer sees an impact whatever
    filter the velocity estimate went through), else the change of the logged velocity over it; less the thrust's
    acceleration averaged over the window. NaN where the window does not fit (the log's ends)."""
    n = log.n_samples
    dt = float(np.median(np.diff(log.t)))
    half = max(1, int(round(STRIKE_WINDOW_S / dt / 2)))
    jolt = np.full(n, np.nan)
    if n <= 2 * half:
        return jolt
    thrust_n = log.total_thrust * (log.R_body_to_world[:, :, 2] @ normal) / log.vehicle.mass
    inner = slice(half, n - half)
    if log.a_world is not None:
        measured = moving_average(log.a_world @ normal, 2 * half + 1)[inner]
    else:
        v_n = log.v_world @ normal
        measured = (v_n[2 * half:] - v_n[:n - 2 * half]) / (log.t[2 * half:] - log.t[:n - 2 * half])
    jolt[inner] = measured - moving_average(thrust_n, 2 * half + 1)[inner]
    return jolt


def _was_approaching(log: FlightLog, normal: np.ndarray, i: int, jolt: float) -> bool:
    """Whether the vehicle came at the wall before the jolt at sample ``i``: over the window before the jolt's own,
    its mean speed toward the wall is at least half the speed the jolt took away (``jolt`` times its window). A
    glitch in the velocity estimate, or a hold's noise, jolts a vehicle that was not moving."""
    dt = float(np.median(np.diff(log.t)))
    half = max(1, int(round(STRIKE_WINDOW_S / dt / 2)))
    before = log.v_world[max(0, i - 3 * half):max(1, i - half), :] @ normal
    return bool(-before.mean() >= APPROACH_SHARE * jolt * 2 * half * dt)


def wall_strikes(log: FlightLog) -> list[WallStrikes]:
    """The walls of ``log.scene`` the vehicle struck (see the module text), each with its contact samples."""
    if log.n_samples < 3 or not log.scene.walls:
        return []
    rotors_world = log.p_world[:, None, :] + np.einsum("nij,rj->nri", log.R_body_to_world,
                                                       log.vehicle.rotor_positions_array)
    dt = float(np.median(np.diff(log.t)))
    out = []
    for k, wall in enumerate(log.scene.walls):
        normal = np.asarray(wall.normal)
        distance = wall.distance(rotors_world).min(axis=1)
        if np.mean(distance < 0) > 0.5:  # the normal points into the wall (the scene check flips it too)
            normal, distance = -normal, -wall.distance(rotors_world).max(axis=1)
        closest = float(distance.min())
        if closest >= NEAR_SURFACE:
            continue
        jolt = outward_jolt(log, normal)
        finite = np.isfinite(jolt)
        if finite.sum() < 3:
            continue
        centre = float(np.median(jolt[finite]))
        scatter = max(SCATTER_FLOOR, 1.4826 * float(np.median(np.abs(jolt[finite] - centre))))
        hits = np.flatnonzero(finite & (np.where(finite, jolt, 0.0) > centre + STRIKE_Z * scatter)
                              & (distance < closest + SAME_DISTANCE))
        hits = hits[[_was_approaching(log, normal, int(i), float(jolt[i])) for i in hits]]
        strikes: list[list[int]] = []
        for i in hits:
            if strikes and log.t[i] - log.t[strikes[-1][-1]] <= STRIKE_SEPARATION_S:
                strikes[-1].append(int(i))
            else:
                strikes.append([int(i)])
        if len(strikes) < MIN_STRIKES:
            continue
        touch = float(distance[hits].max()) + CONTACT_MARGIN
        peaks = np.array([log.t[max(s, key=lambda i: jolt[i])] for s in strikes])
        # widened by the jolt's window on each side: a stiff guard bounces the vehicle off in a sample or two, too
        # short a gap to cut the log there, and the residual's smoothing would carry the impulse into the samples
        # kept on either side
        pad = max(1, int(round(STRIKE_WINDOW_S / dt)))
        in_contact = np.convolve((distance < touch).astype(float), np.ones(2 * pad + 1), mode="same") > 0
        out.append(WallStrikes(wall=k, times=peaks, closest=closest, touch_distance=touch, in_contact=in_contact))
    return out
