"""Strikes on a wall or the ceiling: a rotor's guard (or the frame) touches it, and it pushes the vehicle.

Near a wall the rotors' airflow pulls the vehicle *toward* it, and under a ceiling *up* to it;
no aerodynamic effect there pushes it away harder than the thrust and gravity do (drag at the
slow approach speeds near a surface is small). A surface that stops the vehicle does: a guard
gives a few millimetres and stops it within a few tens of milliseconds, while the vehicle's
own loop brakes over hundreds (it must first tilt or cut the thrust). So a strike shows as a
short acceleration away from the surface well beyond the thrust's and gravity's, at the
vehicle's closest approach; and a vehicle that struck a surface several times was stopped
each time at about the same distance: the guard's reach.

In contact (the impact, then pinned against or sliding along the surface) the surface carries
part of the force, and on a wall friction may hold the vehicle up. In the force residual a
pinned vehicle looks like a pull too weak (it does not accelerate, however hard suction or the
ceiling effect pulls), so a fit that keeps these samples finds a wrong k_s or ceiling radius,
or nothing and an unexplained force. :func:`surface_strikes` finds the strikes and the samples
at or nearer than the distance they happened at; the workflow leaves those out with the reason
"wall contact" or "ceiling contact". On the ground a touchdown is a strike by design, and
:mod:`discovery.coverage` leaves the ground's rests and touchdowns out; :func:`ground_strikes` finds
the strikes on it that the vehicle flew on from (bounces), left out as "ground strike".

A surface the scene does not have (a wall missing from the sidecar, a net, an obstacle) is found by
:func:`undeclared_strikes`: the same strikes against a plane where the rotor centres went farthest,
for a ring of horizontal normals and one facing down; the normal nearest the strikes' own push is
the surface's, turned to the plane through the points where the strikes stopped the rotor centres
when they span it. Nothing near it is fitted, so its contact is taken generously: from where each
strike's push began.

Without an accelerometer column the jolt is read from the logged velocity; a velocity estimate
smoothed over more than the jolt's window (a filtered motion-capture derivative, say 50 ms) spreads
a strike too thin to find, and the contact is then fitted as a pull too weak. Log the
acceleration (``ax, ay, az``) when the vehicle may touch a surface.

A vehicle that comes at a wall slowly enough strikes it too softly to find, and the wall's suction may then hold
it against the wall as it flies on along it. What gives it away is friction: the guards sliding along the surface
hold the vehicle back against its sliding, and only at its closest approach. :func:`slid_along` measures the
acceleration along the surface's plane beyond the thrust's and gravity's, less a per-axis fit of it on the in-plane
velocity (constant, linear and quadratic: a steady wind and drag) over the samples away from the closest approach,
and takes the component against the sliding. Half a second or more of sliding within :data:`SAME_DISTANCE` of the
closest approach, held back by at least :data:`RUB_MIN` and :data:`RUB_Z` times that component's own scatter away
from it, marks the surface as touched; flown past at a few centimetres without touching, the same component is zero
within its scatter (no aerodynamic effect near a wall or a ceiling acts along it only at the closest approach).
The hold-back is measured from its level just outside the contact (out to :data:`RUB_BAND`): friction begins at
the touch, while a drag that grows toward the surface over a rotor's scale holds the vehicle back there nearly as
much (one growing by e every 5 cm is told apart; every 3 cm or less, it is not).

A vehicle whose loop drives it on into a surface it cannot pass (a ceiling above its reference,
the integrator winding the thrust up to twice the weight) may strike it once and then stay
pressed there. :func:`pressed_against` finds that the way a rest on the ground is found: over
half a second the vehicle is pushed away from the surface by more than g/4 beyond what the
thrust and gravity do, near it (within :data:`discovery.coverage.NEAR_SURFACE`); half a
second of that, in all, marks the surface as touched.

The jolt is measured as a jump (:func:`jolt_jump`): from its level over the window just before.
Along the approach the surface's own pull keeps it well below zero (suction -1.5 m/s^2 at
2.5 cm), and a strike measured from zero was lost in the scatter that pull adds.

The strike test is one-sided and needs repetition, so that steady flight close to a surface (a hold
at a few centimetres, a survey that turns back at the same distance each pass) is not taken
for contact: at least :data:`MIN_STRIKES` separate jolts away from the surface of
:data:`STRIKE_Z` robust standard deviations of the log's own scatter, each within
:data:`SAME_DISTANCE` of the closest approach, and each after the vehicle came at the surface
with at least :data:`APPROACH_SHARE` of the speed the jolt took away (a glitch in the velocity
estimate during a hold jolts a vehicle that was not moving). One strike suffices when the
vehicle then stays within the contact distance for :data:`PINNED_S`: the surface's pull holds
it there after the first strike (a 2.5 cm guard on a light vehicle), so it never strikes again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from discovery.coverage import NEAR_SURFACE, pushed_beyond_free
from discovery.differentiation import moving_average
from discovery.flight_log import FlightLog
from discovery.regressors import rotor_centres_world, surface_clearances

__all__ = ["Strikes", "surface_strikes", "ground_strikes", "undeclared_strikes", "declared_surface", "outward_jolt",
           "jolt_jump", "pressed_against", "slid_along", "normal_text", "STRIKE_WINDOW_S", "STRIKE_Z", "MIN_STRIKES",
           "SAME_DISTANCE", "CONTACT_MARGIN", "UNDECLARED_CONTACT", "UNDECLARED_DIRECTIONS", "RUB_MIN", "RUB_Z"]

STRIKE_WINDOW_S = 0.03  # s: a guard stops the vehicle in about this long; the loop's braking takes hundreds of ms
STRIKE_Z = 4.0  # robust standard deviations of the log's jumps (jolt_jump) a strike's jump exceeds
SAME_DISTANCE = 0.005  # m: strikes within this of the closest approach to a surface are stopped at one distance
MIN_STRIKES = 2  # separate strikes (at least STRIKE_SEPARATION_S apart) before a surface is taken to be struck
STRIKE_SEPARATION_S = 0.2  # s
CONTACT_MARGIN = 0.002  # m past the farthest strike's distance that still counts as touching (the guard's give)
APPROACH_SHARE = 0.5  # of the speed a jolt takes away, the least the vehicle came at the surface with before it
PINNED_S = 1.0  # s: one strike suffices when the vehicle then stays this long within the contact distance
PINNED_SHARE = 0.9  # of the samples over PINNED_S
PRESSED_S = 0.5  # s of being pressed against a surface, in all, before it is taken to be touched
RUB_WINDOW_S = 0.25  # s: the in-plane acceleration and velocity friction is read from are averaged over this long
SLIDE_SPEED = 0.05  # m/s: the least speed along the surface's plane that counts as sliding along it
#: m/s^2: the least hold-back against the sliding (beyond thrust, gravity and drag) taken for friction. In 475 logs
#: of the second simulator, 30 surfaces came within 2 mm of the guards' reach with half a second or more of sliding
#: at the closest approach: 27 held the vehicle back by 0.37-5.0 m/s^2 (of the rest, one stopped short of touching,
#: one was found by its strikes and one slid 0.5 s held back by 0.15). Flown within 30 cm without touching: at most
#: 0.064 (56 surfaces)
RUB_MIN = 0.2
#: robust standard deviations of the hold-back away from the closest approach: touching gave 8-131 (those 27), not
#: touching at most 0.9
RUB_Z = 6.0
RUB_BAND = 0.02  # m past the closest approach: the hold-back just outside the contact is measured out to here
SCATTER_FLOOR = 0.05  # m/s^2: the least scatter a jolt is measured against (a noise-free simulated log has none)
ONSET_Z = 2.0  # robust standard deviations: a strike's push began where its jump last rose above this
UNDECLARED_CONTACT = "contact with a surface not in the scene"  # the reason its samples are left out
UNDECLARED_DIRECTIONS = 36  # horizontal normals tried for a surface the scene does not have (10 degrees apart)
UNDECLARED_APART_DEG = 45.0  # degrees: normals nearer than this to one taken are the same undeclared surface
#: m: an undeclared surface whose strikes stopped the rotor centres at points this far apart along it is turned to
#: the vertical plane through those points (the ring's normals are 10 degrees apart; 5 degrees off, the plane through
#: one end of a 4 m survey lies 35 cm from its other end, where the strikes then go unseen)
TURN_TO_POINTS_SPAN = 0.3
#: degrees: the plane through the points is taken only this near the ring's normal (the normal nearest the strikes'
#: push may be 13 degrees off when the guards slide along the wall as they strike it)
TURN_TO_POINTS_MAX_DEG = 30.0
TURN_TO_POINTS_WITHIN = 0.03  # m: and only when every point lies this near it (a corner's two walls do not)


@dataclass(frozen=True)
class Strikes:
    """The strikes on one surface of a log's scene (or one it does not have) and the samples in contact with it."""

    surface: str  # "wall 0", "wall 1", ..., "ceiling" or "ground"; or "a surface not in the scene, facing ..."
    effect: str | None  # the effect whose pull acts there: "wall_suction" or "ceiling_effect"; None if undeclared
    normal: np.ndarray  # (3,) the surface's unit normal into free space
    times: np.ndarray  # (strikes,) s: the strongest jump of each strike (empty when only pressed against it)
    pressed_s: float  # s the vehicle was pressed against the surface (pressed_against), within NEAR_SURFACE
    closest: float  # m: the nearest rotor centre's closest approach to the surface's plane
    touch_distance: float  # m: the farthest strike's (or its push's onset's) distance plus CONTACT_MARGIN; nearer
    # than this is contact
    in_contact: np.ndarray  # (n,) bool: nearer the surface than touch_distance, or within STRIKE_WINDOW_S of it
    stopped_at: float | None = None  # m along the normal (world) where the rotor centres went farthest against it:
    # where the strikes stopped them; given for a surface not in the scene, whose place they are all we know of
    give: float = SAME_DISTANCE  # m: how far short of the closest approach a strike may stop (the guard gives more
    # the faster it strikes): SAME_DISTANCE and half the fastest strike's speed times STRIKE_WINDOW_S
    slid_s: float = 0.0  # s the vehicle slid along the surface at its closest approach, held back by friction
    # (slid_along); 0 when it was found by its strikes or by being pressed against it
    held_back: float = 0.0  # m/s^2: the median hold-back against the sliding there (slid_along)


def outward_jolt(log: FlightLog, normal: np.ndarray) -> np.ndarray:
    """The acceleration along ``normal`` beyond the thrust's and gravity's (m/s^2), each over about
    :data:`STRIKE_WINDOW_S`: the logged acceleration averaged over the window where the log has one (an accelerometer
    sees an impact whatever filter the velocity estimate went through), else the change of the logged velocity over
    it; less the thrust's and gravity's acceleration averaged over the window. NaN where the window does not fit
    (the log's ends)."""
    n = log.n_samples
    half = _half_window(log)
    jolt = np.full(n, np.nan)
    if n <= 2 * half:
        return jolt
    free_n = log.free_acceleration(normal)
    inner = slice(half, n - half)
    if log.a_world is not None:
        measured = moving_average(log.a_world @ normal, 2 * half + 1)[inner]
    else:
        v_n = log.v_world @ normal
        measured = (v_n[2 * half:] - v_n[:n - 2 * half]) / (log.t[2 * half:] - log.t[:n - 2 * half])
    jolt[inner] = measured - moving_average(free_n, 2 * half + 1)[inner]
    return jolt


def pressed_against(log: FlightLog, normal: np.ndarray) -> np.ndarray:
    """Samples at which the vehicle is pushed away from the surface whose normal is ``normal`` by more than
    :data:`discovery.coverage.NOT_FALLING` g beyond what the thrust and gravity do, both averaged over
    :data:`discovery.coverage.HELD_WINDOW_S` (:func:`discovery.coverage.pushed_beyond_free`, from the accelerometer
    when the log has one): a vehicle whose loop drives it on into a ceiling with twice its weight in thrust, and
    that does not rise. No aerodynamic effect near a wall or a ceiling pushes that way (they pull toward it)."""
    return pushed_beyond_free(log, normal, accelerometer=True)


def _plane_axes(normal: np.ndarray) -> np.ndarray:
    """``(3, 2)`` two orthonormal directions (world) in the plane whose unit normal is ``normal``."""
    other = np.eye(3)[int(np.argmin(np.abs(normal)))]
    first = np.cross(normal, other)
    first /= np.linalg.norm(first)
    return np.stack([first, np.cross(normal, first)], axis=1)


def slid_along(log: FlightLog, normal: np.ndarray, distance: np.ndarray, closest: float) -> tuple[float, float, float]:
    """How the vehicle slid along the surface whose unit ``normal`` (into free space) it came within ``closest`` of
    (the nearest rotor centre ``distance`` from its plane at every sample): ``(seconds, hold_back, z)``, the time it
    slid (:data:`SLIDE_SPEED`) within :data:`SAME_DISTANCE` of the closest approach, the median acceleration against
    its sliding there beyond thrust, gravity and the drag and wind seen away from it, less the same just outside the
    contact (out to :data:`RUB_BAND` past the closest approach; m/s^2; see the module text), and that in robust
    standard deviations of the hold-back away from it. ``(0, 0, 0)`` when either has too few samples."""
    dt = float(np.median(np.diff(log.t)))
    window = max(1, int(round(RUB_WINDOW_S / dt)))
    axes = _plane_axes(normal)
    v_plane = moving_average(log.v_world @ axes, window)
    if log.a_world is not None:
        a_plane = moving_average(log.a_world @ axes, window)
    else:
        a_plane = np.gradient(v_plane, log.t, axis=0)
    free = np.stack([moving_average(log.free_acceleration(axis), window) for axis in axes.T], axis=1)
    push = a_plane - free
    at_closest = distance < closest + SAME_DISTANCE
    away = ~_widened(at_closest, window)
    speed = np.linalg.norm(v_plane, axis=1)
    sliding = speed > SLIDE_SPEED
    if away.sum() < 10 or (away & sliding).sum() < 10:
        return 0.0, 0.0, 0.0
    rest = np.empty_like(push)
    for k in range(2):  # a steady wind and drag, fitted where the surface cannot touch the vehicle
        basis = np.stack([np.ones(log.n_samples), v_plane[:, k], v_plane[:, k] * np.abs(v_plane[:, k])], axis=1)
        coefficients = np.linalg.lstsq(basis[away], push[away, k], rcond=None)[0]
        rest[:, k] = push[:, k] - basis @ coefficients
    hold_back = -np.sum(rest * v_plane, axis=1) / np.maximum(speed, 1e-9)
    # only at speeds the fit away from the surface saw: drag extrapolated beyond them is no baseline
    tested = at_closest & sliding & (speed <= np.percentile(speed[away], 99))
    if not tested.any():
        return 0.0, 0.0, 0.0
    baseline = hold_back[away & sliding]
    centre = float(np.median(baseline))
    scatter = max(1e-6, 1.4826 * float(np.median(np.abs(baseline - centre))))
    # measured from just outside the contact (the next RUB_BAND), where the vehicle slid too: friction begins at the
    # touch, while a drag that grows toward the surface (not in the library) is there as well
    band = sliding & (distance >= closest + SAME_DISTANCE + CONTACT_MARGIN) & (distance < closest + RUB_BAND)
    outside = float(np.median(hold_back[band])) if band.sum() >= 10 else centre
    held = float(np.median(hold_back[tested])) - outside
    return float(tested.sum() * dt), held, held / scatter


def jolt_jump(jolt: np.ndarray, half: int) -> np.ndarray:
    """``jolt`` less its mean over the ``2 half + 1`` samples that end where its own window (``half`` samples each
    side) begins: how suddenly the push away from the surface changed. Near a wall, suction's pull keeps the jolt
    well below zero all along the approach (-1.5 m/s^2 at 2.5 cm), and a strike is the jump from there; measured from
    zero it was lost in the scatter that suction's own structure adds. NaN where either window has no value."""
    n = len(jolt)
    width = 2 * half + 1
    jump = np.full(n, np.nan)
    start = 2 * width - 1  # the first sample whose earlier window fits: it ends at i - half - 1
    if n <= start:
        return jump
    sums = np.concatenate([[0.0], np.cumsum(np.nan_to_num(jolt))])
    counts = np.concatenate([[0], np.cumsum(np.isfinite(jolt))])
    i = np.arange(start, n)
    end = i - half  # exclusive end of the earlier window
    mean = (sums[end] - sums[end - width]) / width
    full = (counts[end] - counts[end - width]) == width
    jump[i] = np.where(full, jolt[i] - mean, np.nan)
    return jump


def _half_window(log: FlightLog) -> int:
    """Samples on each side of a jolt's centre: half of :data:`STRIKE_WINDOW_S` at the log's median rate, at least 1."""
    return max(1, int(round(STRIKE_WINDOW_S / float(np.median(np.diff(log.t))) / 2)))


def _approach_speed(log: FlightLog, normal: np.ndarray, i: int, half: int) -> float:
    """The mean speed (m/s) toward the surface over the window before the jolt's own at sample ``i`` (negative:
    away from it). A strike follows an approach of at least :data:`APPROACH_SHARE` of the speed its jolt took away;
    a glitch in the velocity estimate, or a hold's noise, jolts a vehicle that was not moving."""
    before = log.v_world[max(0, i - 3 * half):max(1, i - half), :] @ normal
    return float(-before.mean())


def _stays_pinned(t: np.ndarray, distance: np.ndarray, i: int, touch: float) -> bool:
    """Whether, for :data:`PINNED_S` after sample ``i``, nearly all samples (:data:`PINNED_SHARE`) stay nearer the
    surface than ``touch``: a strike the surface's pull then holds the vehicle against."""
    after = (t > t[i]) & (t <= t[i] + PINNED_S)
    return bool(t[-1] - t[i] >= PINNED_S and np.mean(distance[after] < touch) >= PINNED_SHARE)


def _planes(log: FlightLog, rotors_world: np.ndarray) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """``(surface, effect, normal, distance)`` for each wall and the ceiling: the unit normal into free space and
    the nearest rotor centre's distance from the plane at every sample. A wall whose normal points into it (most of
    the flight behind it) is turned round, as the scene check turns it."""
    planes = []
    for k, wall in enumerate(log.scene.walls):
        normal, distance = np.asarray(wall.normal), wall.distance(rotors_world).min(axis=1)
        if np.mean(distance < 0) > 0.5:
            normal, distance = -normal, -wall.distance(rotors_world).max(axis=1)
        planes.append((f"wall {k}", "wall_suction", normal, distance))
    below_ceiling = surface_clearances(rotors_world[:, :, 2], log.scene)[1]
    if below_ceiling is not None:
        planes.append(("ceiling", "ceiling_effect", np.array([0.0, 0.0, -1.0]), below_ceiling))
    return planes


def surface_strikes(log: FlightLog) -> list[Strikes]:
    """The walls and the ceiling of ``log.scene`` the vehicle struck (see the module text), each with its contact
    samples."""
    if log.n_samples < 3:
        return []
    rotors_world = rotor_centres_world(log.p_world, log.R_body_to_world, log.vehicle.rotor_positions_array)
    out = []
    for surface, effect, normal, distance in _planes(log, rotors_world):
        closest = float(distance.min())
        if closest >= NEAR_SURFACE:
            continue
        # a rotor centre past the plane is a scene error (reported as such), not a guard touching the surface
        jump = jolt_jump(outward_jolt(log, normal), _half_window(log))
        struck = _strikes_on(log, surface, effect, normal, distance, closest, jump, candidates=distance > 0,
                             pressed=True)
        if struck is None and closest > 0:
            struck = _slid_against(log, surface, effect, normal, distance, closest)
        if struck is not None:
            out.append(struck)
    return out


def _slid_against(log: FlightLog, surface: str, effect: str, normal: np.ndarray, distance: np.ndarray,
                  closest: float) -> Strikes | None:
    """The surface as touched when friction held the vehicle back as it slid along it at its closest approach
    (:func:`slid_along`), with every sample within :data:`SAME_DISTANCE` and :data:`CONTACT_MARGIN` of the closest
    approach in contact; None otherwise."""
    seconds, held_back, z = slid_along(log, normal, distance, closest)
    if seconds < PRESSED_S or held_back < RUB_MIN or z < RUB_Z:
        return None
    touch = closest + SAME_DISTANCE + CONTACT_MARGIN
    pad = _strike_pad(float(np.median(np.diff(log.t))))
    in_contact = _widened(distance < touch, pad)
    return Strikes(surface=surface, effect=effect, normal=normal, times=np.zeros(0), pressed_s=0.0, closest=closest,
                   touch_distance=touch, in_contact=in_contact, slid_s=seconds, held_back=held_back)


def ground_strikes(log: FlightLog, excluded: np.ndarray) -> Strikes | None:
    """The ground struck in flight: bounces off it that the vehicle flew on from (a survey that dips onto the
    ground, a hard landing it takes off again from), found as strikes on a wall are, the distance being the lowest
    rotor centre's height above ``scene.ground_z``; None when there are fewer than :data:`MIN_STRIKES`. A touchdown
    the vehicle then rests after is not one (:mod:`discovery.coverage` leaves rests and touchdowns out), nor are the
    samples ``excluded`` (those rests). Without this, a survey striking the ground at 3.5 m/s every 15 s left 1 N
    of its impacts to be fitted, as a ground effect 4 times too wide and a drag it did not have."""
    if log.n_samples < 3 or excluded.all() or log.scene.ground_z is None:
        return None
    rotors_world = rotor_centres_world(log.p_world, log.R_body_to_world, log.vehicle.rotor_positions_array)
    height = rotors_world[:, :, 2].min(axis=1) - log.scene.ground_z
    closest = float(height[~excluded].min())
    if closest >= NEAR_SURFACE:
        return None
    up = np.array([0.0, 0.0, 1.0])
    jump = jolt_jump(outward_jolt(log, up), _half_window(log))
    return _strikes_on(log, "ground", "ground_effect", up, height, closest, jump,
                       candidates=(height > 0) & ~excluded, pressed=False, from_onset=True, bounces_only=True)


def undeclared_strikes(log: FlightLog, excluded: np.ndarray) -> list[Strikes]:
    """Surfaces the scene does not have that the vehicle struck: a wall, a net or an obstacle missing from the
    sidecar. The same strikes as on a declared surface (:func:`surface_strikes`, without the press) against a plane
    where the rotor centres went farthest, tried for :data:`UNDECLARED_DIRECTIONS` horizontal normals and one facing
    down (a ceiling); the samples ``excluded`` (already left out: rests, contact with declared surfaces) neither strike
    nor place the plane. A strike pushes the vehicle along the surface's normal, so of the normals whose planes were
    struck the one nearest the strikes' mean push is taken (a flight to and fro along one line strikes the plane
    of every normal within 90 degrees of the true one at the same moments). A normal within
    :data:`UNDECLARED_APART_DEG` of one taken, with strikes at other moments, is the same surface met where its
    tilted plane touches the flight: its strikes and contact join that one's. Farther off, a normal with
    :data:`MIN_STRIKES` strikes of its own is another surface (a corner). The push is not asked to lie along the
    normal: friction on a guard that slides along the surface may push harder. ``effect`` is None."""
    if log.n_samples < 3 or excluded.all():
        return []
    rotors_world = rotor_centres_world(log.p_world, log.R_body_to_world, log.vehicle.rotor_positions_array)
    # the jump along a normal is the jumps along the world axes projected on it (the jolt is linear in the normal)
    half = _half_window(log)
    pushes = np.column_stack([jolt_jump(outward_jolt(log, axis), half) for axis in np.eye(3)])
    angles = 2.0 * np.pi * np.arange(UNDECLARED_DIRECTIONS) / UNDECLARED_DIRECTIONS
    normals = [np.array([np.cos(a), np.sin(a), 0.0]) for a in angles] + [np.array([0.0, 0.0, -1.0])]

    def facing(normal: np.ndarray) -> Strikes | None:
        along = (rotors_world @ normal).min(axis=1)
        stopped_at = float(along[~excluded].min())
        name = "a surface not in the scene, facing " + normal_text(normal)
        struck = _strikes_on(log, name, None, normal, along - stopped_at, 0.0, pushes @ normal, candidates=~excluded,
                             pressed=False, from_onset=True)
        return None if struck is None else replace(struck, stopped_at=stopped_at)

    found = []
    for normal in normals:
        struck = facing(normal)
        if struck is None:
            continue
        push = np.nanmean(pushes[np.searchsorted(log.t, struck.times)], axis=0)
        found.append((float(normal @ push) / max(float(np.linalg.norm(push)), 1e-12), struck))
    out: list[Strikes] = []
    for _, struck in sorted(found, key=lambda f: -f[0]):
        taken = np.concatenate([np.zeros(0), *(other.times for other in out)])
        own = np.array([t for t in struck.times if not np.any(np.abs(taken - t) <= STRIKE_SEPARATION_S)])
        same = [k for k, other in enumerate(out)
                if float(struck.normal @ other.normal) >= np.cos(np.radians(UNDECLARED_APART_DEG))]
        if same and own.size:  # the same surface, struck where its plane at this tilt meets the flight
            other = out[same[0]]
            out[same[0]] = replace(other, times=np.sort(np.concatenate([other.times, own])),
                                   in_contact=other.in_contact | struck.in_contact)
        elif not same and (not out or own.size >= MIN_STRIKES):
            near = [other.times for _, other in found
                    if float(struck.normal @ other.normal) >= np.cos(np.radians(UNDECLARED_APART_DEG))]
            out.append(_turned_to_points(log, rotors_world, struck, _separate(np.concatenate(near)), facing))
    return out


def declared_surface(log: FlightLog, struck: Strikes) -> Strikes | None:
    """``struck``, a surface :func:`undeclared_strikes` found, as the wall or ceiling of ``log.scene`` it is; None
    when it is none of them. It is a declared plane when its normal lies within :data:`TURN_TO_POINTS_MAX_DEG` of the
    plane's (guards sliding along a wall push along it too) and every sample in contact has its nearest rotor centre
    on the plane's free side and within :data:`discovery.coverage.NEAR_SURFACE` of it. :func:`surface_strikes` may miss
    such strikes: a slow graze on each pass jolts the vehicle too little, and a bounce that stops a few millimetres
    short of the closest approach is not counted with it. The plane's ``surface``, ``effect``, ``normal`` and
    ``closest`` replace the undeclared ones, and ``stopped_at`` is None (the scene gives the plane's place). As on a
    plane of the scene, the guards touch it as far out as the strikes stopped the rotor centres: nearer than that
    (``touch_distance``, with :data:`CONTACT_MARGIN`) is contact too, the grazes on other passes included."""
    rotors_world = rotor_centres_world(log.p_world, log.R_body_to_world, log.vehicle.rotor_positions_array)
    pad = _strike_pad(float(np.median(np.diff(log.t))))
    for surface, effect, normal, distance in _planes(log, rotors_world):
        near = distance[struck.in_contact]
        if (float(normal @ struck.normal) >= np.cos(np.radians(TURN_TO_POINTS_MAX_DEG)) and near.size
                and float(near.min()) >= 0.0 and float(near.max()) < NEAR_SURFACE):
            stops = [float(distance[max(0, i - pad):i + pad + 1].min()) for i in np.searchsorted(log.t, struck.times)]
            touch = max(stops, default=float(distance.min())) + CONTACT_MARGIN
            nearer = _widened(distance < touch, pad)
            return replace(struck, surface=surface, effect=effect, normal=normal, closest=float(distance.min()),
                           touch_distance=touch, in_contact=struck.in_contact | nearer, stopped_at=None)
    return None


def _turned_to_points(log: FlightLog, rotors_world: np.ndarray, struck: Strikes, times: np.ndarray,
                      facing: Callable[[np.ndarray], Strikes | None]) -> Strikes:
    """``struck`` (an undeclared wall, its normal one of the ring's) turned to the vertical plane through the points
    where strikes stopped the rotor centres, and struck again (``facing``: the strikes for a normal). The strikes at
    ``times`` are those of every ring normal near this one: each ring plane meets the flight somewhere else along
    the wall, so together they span it. Each strike's point is its nearest rotor centre at its farthest against the
    normal, within the strike's window; the plane through the points (least squares across it) gives a normal, the
    points are taken again against that, until it turns by less than 0.1 degrees. Kept as it is when the points
    span less than :data:`TURN_TO_POINTS_SPAN` along it, when the plane through them is more than
    :data:`TURN_TO_POINTS_MAX_DEG` off or any point lies farther than :data:`TURN_TO_POINTS_WITHIN` from it (more
    what the guards gave beyond :data:`SAME_DISTANCE`, :attr:`Strikes.give`: slower strikes stop short), when
    the turned plane is struck fewer times, or when it faces down (a ceiling)."""
    if abs(struck.normal[2]) > 1e-9 or times.size < 2:
        return struck
    pad = _strike_pad(float(np.median(np.diff(log.t))))
    windows = [rotors_world[max(0, i - pad):i + pad + 1] for i in np.searchsorted(log.t, times)]
    ring = normal = struck.normal
    for _ in range(10):
        points = np.array([window[np.unravel_index(np.argmin(window @ normal), window.shape[:2])][:2]
                           for window in windows])
        xy = points - points.mean(axis=0)
        along_wall = np.linalg.svd(xy, full_matrices=False)[2][0]
        if np.ptp(xy @ along_wall) < TURN_TO_POINTS_SPAN:
            return struck
        turned = np.array([-along_wall[1], along_wall[0], 0.0])
        turned *= np.sign(turned @ ring)
        if turned @ ring < np.cos(np.radians(TURN_TO_POINTS_MAX_DEG)) or \
                np.abs(xy @ turned[:2]).max() > TURN_TO_POINTS_WITHIN + struck.give - SAME_DISTANCE:
            return struck
        settled = turned @ normal > np.cos(np.radians(0.1))
        normal = turned
        if settled:
            break
    again = facing(normal)
    return again if again is not None and again.times.size >= struck.times.size else struck


def normal_text(normal: np.ndarray) -> str:
    """A unit normal as the notes give it: ``(+0.819, +0.574, +0.000)``."""
    return "(" + ", ".join(f"{round(float(c), 3) + 0.0:+.3f}" for c in normal) + ")"


def _separate(times: np.ndarray) -> np.ndarray:
    """``times`` sorted, each within :data:`STRIKE_SEPARATION_S` of the one kept before it dropped (one strike found
    on several planes)."""
    kept: list[float] = []
    for time in np.sort(times):
        if not kept or time - kept[-1] > STRIKE_SEPARATION_S:
            kept.append(float(time))
    return np.array(kept)


def _onset(jump: np.ndarray, level: float, first: int, half: int) -> np.ndarray:
    """The samples where the push of the strike whose first hit is ``first`` began: back from it while the ``jump``
    stays above ``level``, and the jolt's window before that."""
    start = first
    while start > 0 and np.isfinite(jump[start - 1]) and jump[start - 1] > level:
        start -= 1
    return np.arange(max(0, start - half), start + 1)


def _widened(mask: np.ndarray, samples: int) -> np.ndarray:
    """``mask`` with every sample within ``samples`` of one it holds set too."""
    return np.convolve(mask.astype(float), np.ones(2 * samples + 1), mode="same") > 0


def _strike_pad(dt: float) -> int:
    """Samples of period ``dt`` (s) in a strike's window, :data:`STRIKE_WINDOW_S`, on each side of it (at least one)."""
    return max(1, int(round(STRIKE_WINDOW_S / dt)))


def _strikes_on(log: FlightLog, surface: str, effect: str | None, normal: np.ndarray, distance: np.ndarray,
                closest: float, jolt: np.ndarray, *, candidates: np.ndarray, pressed: bool,
                from_onset: bool = False, bounces_only: bool = False) -> Strikes | None:
    """The strikes on one plane (unit ``normal`` into free space, the nearest rotor centre ``distance`` from it at
    every sample, ``closest`` at the nearest; ``jolt`` the :func:`jolt_jump` along the normal) at the samples
    ``candidates``, and the samples in contact; None when it was not touched. With ``pressed``, a vehicle pressed
    against it (:func:`pressed_against`) has touched it too. With ``from_onset`` the contact reaches as far as any
    strike's push began (:data:`ONSET_Z`), not only as far as its strongest samples: generous for a fast strike,
    whose 30 ms window spans centimetres of travel. With ``bounces_only`` only strikes the vehicle flew on from
    count (:data:`MIN_STRIKES` of them), and the contact reaches as far as they stopped it."""
    dt = float(np.median(np.diff(log.t)))
    half = _half_window(log)
    finite = np.isfinite(jolt)
    if finite.sum() < 3:
        return None
    centre = float(np.median(jolt[finite]))
    scatter = max(SCATTER_FLOOR, 1.4826 * float(np.median(np.abs(jolt[finite] - centre))))
    jolted = np.flatnonzero(finite & (np.where(finite, jolt, 0.0) > centre + STRIKE_Z * scatter) & candidates)
    speeds = np.array([_approach_speed(log, normal, int(i), half) for i in jolted])
    came_at_it = speeds >= APPROACH_SHARE * jolt[jolted] * 2 * half * dt  # the jump's speed: jolt times its window
    jolted, speeds = jolted[came_at_it], speeds[came_at_it]
    # a guard gives more the faster it strikes: the strikes at the closest approach are the fastest, and a slower
    # one stopped short of them by up to what they gave (stopped within STRIKE_WINDOW_S, at most half their speed
    # times that: 4 cm between strikes at 5 and 0.3 m/s on a 3000 N/m guard)
    at_closest = distance[jolted] < closest + SAME_DISTANCE
    near = jolted[at_closest]
    give = SAME_DISTANCE + 0.5 * STRIKE_WINDOW_S * max(speeds[at_closest], default=0.0)
    hits = jolted[distance[jolted] < closest + give]
    strikes: list[list[int]] = []
    for i in hits:
        if strikes and log.t[i] - log.t[strikes[-1][-1]] <= STRIKE_SEPARATION_S:
            strikes[-1].append(int(i))
        else:
            strikes.append([int(i)])
    against = (pressed_against(log, normal) & (distance < NEAR_SURFACE) & candidates if pressed
               else np.zeros(log.n_samples, dtype=bool))
    # the guards touch the surface at least as far out as the strikes near the closest approach reached, and as
    # where each strike stopped the rotor centres (a slower one, giving less, stops short of the closest); not as
    # far as every sample of a slower strike's jolt, whose centred window begins before the guard touches
    pad = _strike_pad(dt)
    stops = [float(distance[max(0, s[0] - pad):s[-1] + pad + 1].min()) for s in strikes]
    if bounces_only:  # a strike the vehicle then rests after (within what it gave) is a touchdown, not a bounce
        kept = [k for k, s in enumerate(strikes) if not _stays_pinned(log.t, distance, s[-1], stops[k] + give)]
        strikes, stops = [strikes[k] for k in kept], [stops[k] for k in kept]
        reach = max(stops, default=-np.inf) + CONTACT_MARGIN
        struck = len(strikes) >= MIN_STRIKES
    else:
        reach = max([float(distance[near].max()) if near.size else -np.inf, *stops]) + CONTACT_MARGIN
        struck = len(strikes) >= MIN_STRIKES or any(_stays_pinned(log.t, distance, s[-1], reach) for s in strikes)
    if not struck and against.sum() * dt < PRESSED_S:
        return None
    touching = np.flatnonzero(against)
    if from_onset and struck:
        touching = np.concatenate([touching, *(_onset(jolt, centre + ONSET_Z * scatter, s[0], half) for s in strikes)])
    touch = max(reach if struck else -np.inf, float(distance[touching].max()) + CONTACT_MARGIN if touching.size
                else -np.inf)
    peaks = np.array([log.t[max(s, key=lambda i: jolt[i])] for s in strikes]) if struck else np.zeros(0)
    # widened by the jolt's window on each side: a stiff guard bounces the vehicle off in a sample or two, too
    # short a gap to cut the log there, and the residual's smoothing would carry the impulse into the samples
    # kept on either side
    in_contact = _widened(distance < touch, pad)
    return Strikes(surface=surface, effect=effect, normal=normal, times=peaks, pressed_s=float(against.sum() * dt),
                   closest=closest, touch_distance=touch, in_contact=in_contact, give=give)
