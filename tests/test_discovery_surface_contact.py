"""Strikes on a wall or the ceiling (:mod:`discovery.surface_contact`): told apart from a survey that turns back at
one distance."""

from __future__ import annotations

import numpy as np
import pytest

from discovery.flight_log import FlightLog, NominalVehicle
from discovery.regressors import rotor_centres_world
from discovery.surface_contact import (
    CONTACT_MARGIN,
    RUB_MIN,
    RUB_Z,
    SAME_DISTANCE,
    STRIKE_WINDOW_S,
    declared_surface,
    jolt_jump,
    normal_text,
    outward_jolt,
    pressed_against,
    slid_along,
    surface_strikes,
    undeclared_strikes,
)
from wall_env.scene import Scene, Wall
from wall_env.vehicle import VehicleParams

RATE_HZ = 100.0
MASS = 1.3
G = 9.81
PERIOD_S = 4.0  # the survey's period toward and away from the wall
AMPLITUDE = 0.1  # m
STOP = 0.047  # m: the nearest rotor centre's distance from the wall plane where the wall stops the vehicle
VELOCITY_NOISE = 0.003  # m/s
CEILING_Z = 2.0  # m


def _survey(depth: float | np.ndarray, seed: int = 0, *, velocity_lag_s: float = 0.0,
            velocity_noise: float = VELOCITY_NOISE, accelerometer: bool = False, ceiling: bool = False,
            along_wall: float = 0.0, amplitude: float = AMPLITUDE, give_s: float = 0.0) -> tuple[FlightLog, np.ndarray]:
    """A vehicle flying toward and away from a wall at x = 0 (normal +x): its loop (a PD on position, the thrust
    tilted to give the acceleration it asks) steers a sinusoid whose turning point lies ``depth`` past where the
    wall stops it (negative: short of it). Where the vehicle would pass the stop, the wall stops it dead and holds
    it while the loop pushes on toward the wall; it leaves once the loop pulls it away. The logged velocity is the
    true one filtered over ``velocity_lag_s`` (first order), with noise; with ``accelerometer`` the log has the
    acceleration too (0.1 m/s^2 noise). With ``ceiling`` the same up and down under a ceiling at z = CEILING_Z
    (normal -z), level, the thrust carrying the weight and the loop's acceleration. ``along_wall`` (m): the vehicle also
    swings along the wall (y) by this much either side, at half the survey's frequency, so that the strikes fall at
    one end and the other in turn (rolled to give that acceleration too). ``depth`` may change over the flight (one
    value per sample of the 20 s), and ``amplitude`` (m) is the sinusoid's. With ``give_s`` (s) the guard gives:
    struck at speed v, it stops the vehicle ``give_s v`` past the stop. Returns the log and the samples the surface
    held."""
    vehicle = NominalVehicle.from_vehicle_params(VehicleParams(mass=MASS))
    # x: the distance coordinate (the wall's x; under the ceiling, the rotors' depth below it)
    rotor_x = vehicle.rotor_positions_array[:, 0] if not ceiling else np.zeros(4)  # tilted, a rotor sits at x cos
    x_stop = STOP - float(rotor_x.min())  # where the vehicle stops when level
    t = np.arange(int(20.0 * RATE_HZ)) / RATE_HZ
    omega, dt = 2 * np.pi / PERIOD_S, 1.0 / RATE_HZ
    x_ref = x_stop - depth + amplitude * (1 + np.cos(omega * t))  # from the far end, turning at 2, 6, ... s
    v_ref = -amplitude * omega * np.sin(omega * t)
    a_ref = -amplitude * omega ** 2 * np.cos(omega * t)
    swing = omega / 2 * (t - PERIOD_S / 2)  # at the ends of the wall at every turning point: 2, 6, ... s
    y, v_y, a_y = (along_wall * f for f in (np.cos(swing), -omega / 2 * np.sin(swing), -(omega / 2) ** 2 * np.cos(swing)))
    x, v, a = np.zeros(len(t)), np.zeros(len(t)), np.zeros(len(t))
    held = np.zeros(len(t), dtype=bool)
    x[0], v[0] = x_ref[0], v_ref[0]
    give = 0.0
    for k in range(len(t)):
        a[k] = a_ref[k] + 4.0 * (x_ref[k] - x[k]) + 4.0 * (v_ref[k] - v[k])
        if k + 1 < len(t):
            v[k + 1], x[k + 1] = v[k] + a[k] * dt, x[k] + (v[k] + 0.5 * a[k] * dt) * dt
            stop = STOP - float(_rotor_x(vehicle.rotor_positions_array, a[k], a_y[k]).min()) if not ceiling else STOP
            if not held[k]:
                give = give_s * max(0.0, -v[k])  # what the guard gives, struck at this speed
            if x[k + 1] < stop - give:  # the wall: stopped (a strike), held while the loop pushes toward it
                x[k + 1], v[k + 1], held[k + 1] = stop - give, 0.0, True
    rng = np.random.default_rng(seed)
    v_estimate = v.copy()
    for k in range(1, len(t)):
        v_estimate[k] = v_estimate[k - 1] + dt / (velocity_lag_s + dt) * (v[k] - v_estimate[k - 1])
    v_measured = v_estimate + rng.normal(0.0, velocity_noise, len(t))
    a_measured = np.gradient(v, t) + rng.normal(0.0, 0.1, len(t))
    n = len(t)
    if ceiling:
        q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        thrust = MASS * (G - a)  # a is along -z
        p_world = np.column_stack([np.zeros(n), np.zeros(n), CEILING_Z - x])
        along = np.array([0.0, 0.0, -1.0])
        scene = Scene((), 0.0, CEILING_Z)
    else:
        # tilted so the thrust's horizontal share gives (a, a_y) and its vertical share the weight
        angle, axis = _tilt(a, a_y)
        q = np.column_stack([np.cos(angle / 2), *(np.sin(angle / 2) * axis.T)])
        thrust = MASS * np.sqrt(a**2 + a_y**2 + G**2)
        p_world = np.column_stack([x, y, np.full(n, 1.0)])
        along = np.array([1.0, 0.0, 0.0])
        scene = Scene((Wall((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),), 0.0, None)
    swinging = np.column_stack([np.zeros(n), np.zeros(n) if ceiling else v_y, np.zeros(n)])
    log = FlightLog(t=t, p_world=p_world, v_world=v_measured[:, None] * along + swinging, q_body_to_world=q,
                    omega_body=np.zeros((n, 3)), thrust_cmd=thrust, omega_cmd_body=np.zeros((n, 3)), vehicle=vehicle,
                    scene=scene, gravity=G, a_world=a_measured[:, None] * along if accelerometer else None)
    return log, held


def _tilt(a_x, a_y) -> tuple[np.ndarray, np.ndarray]:
    """The angle (rad) and unit axis (horizontal, (n, 3)) that turn the body's z axis to the thrust giving horizontal
    acceleration (a_x, a_y) and carrying the weight."""
    a_x, a_y = np.atleast_1d(a_x), np.atleast_1d(a_y)
    angle = np.arctan2(np.hypot(a_x, a_y), G)
    norm = np.maximum(np.hypot(a_x, a_y), 1e-300)
    return angle, np.column_stack([-a_y / norm, a_x / norm, np.zeros_like(a_x)])


def _rotor_x(rotors_body: np.ndarray, a_x: float, a_y: float) -> np.ndarray:
    """Each rotor centre's world x offset from the centre of mass, tilted by :func:`_tilt` (Rodrigues' formula)."""
    angle, axis = _tilt(a_x, a_y)
    (c,), (kx, ky, _) = np.cos(angle), axis[0]
    return (c + (1 - c) * kx**2) * rotors_body[:, 0] + (1 - c) * kx * ky * rotors_body[:, 1]


def test_the_outward_jolt_is_the_velocitys_change_beyond_the_thrusts():
    """Free flight: the thrust explains every change of velocity and the jolt is noise. At a strike the velocity
    goes from its approach speed to zero in one sample, which the jolt gives as that speed over its window."""
    log, held = _survey(depth=0.005)
    jolt = outward_jolt(log, np.array([1.0, 0.0, 0.0]))
    free = np.isfinite(jolt)
    free[np.flatnonzero(np.diff(held.astype(int))) + np.arange(-3, 4)[:, None]] = False  # away from every edge
    window_s = 2 * round(STRIKE_WINDOW_S * RATE_HZ / 2) / RATE_HZ
    noise = np.sqrt(2) * VELOCITY_NOISE / window_s  # two noisy velocities over the window
    assert np.std(jolt[free]) < 1.2 * noise  # 1.8 times it with the thrust's acceleration left in
    entry = np.flatnonzero(np.diff(held.astype(int)) == 1)[0] + 1  # the first sample the wall holds
    speed = -(log.v_world[entry - 2, 0])  # about the approach speed just before
    assert jolt[entry] == pytest.approx(speed / window_s, rel=0.25)


def test_a_vehicle_the_wall_stops_again_and_again_is_in_contact_and_one_that_turns_back_short_of_it_is_not():
    """Five strikes at 47 mm are found, one per pass, and every sample the wall held is in contact. A survey that
    turns back just short of the wall every pass comes as near and stops at one distance too, but nothing pushes it
    away harder than its thrust does: it is not taken for contact."""
    log, held = _survey(depth=0.005)
    (struck,) = surface_strikes(log)
    assert (struck.surface, struck.effect) == ("wall 0", "wall_suction")
    entries = log.t[np.flatnonzero(np.diff(held.astype(int)) == 1) + 1]
    assert len(entries) == 5 and len(struck.times) == 5  # one per period of 4 s in 20 s
    assert np.allclose(struck.times, entries, atol=2 * STRIKE_WINDOW_S)
    assert struck.closest == pytest.approx(STOP, abs=1e-4)
    assert STOP < struck.touch_distance <= STOP + SAME_DISTANCE + CONTACT_MARGIN
    assert struck.in_contact[held].all()
    survey, held = _survey(depth=-0.001)
    assert not held.any()
    rotors = survey.p_world[:, None, :] + np.einsum("nij,rj->nri", survey.R_body_to_world,
                                                    survey.vehicle.rotor_positions_array)
    assert survey.scene.walls[0].distance(rotors).min() < STOP + 0.002  # as near as the struck vehicle, within 2 mm
    assert surface_strikes(survey) == []


def test_with_an_accelerometer_strikes_are_found_behind_a_velocity_estimate_that_smooths_them_away():
    """A velocity estimate filtered over 60 ms (a motion-capture derivative, say) with 1 cm/s of noise spreads each
    strike thinner than the log's scatter: none is found from it. The logged acceleration still shows each one."""
    smoothed = {"depth": 0.005, "velocity_lag_s": 0.06, "velocity_noise": 0.01}
    log, held = _survey(**smoothed)
    assert held.sum() >= 5 and surface_strikes(log) == []
    log, held = _survey(**smoothed, accelerometer=True)
    (struck,) = surface_strikes(log)
    assert len(struck.times) == 5
    assert struck.in_contact[held].all()


def test_glitches_in_the_velocity_estimate_during_a_hold_by_the_wall_are_not_strikes():
    """A hold 47 mm from the wall stays within 5 mm of its closest approach throughout; two glitches of 5 cm/s in the
    velocity estimate jolt it outward by 12 times its scatter. Taken for strikes, they put the whole hold down as
    contact. The vehicle was not coming at the wall before either, so neither is a strike."""
    log, _ = _survey(depth=-0.001)
    n = log.n_samples
    log.p_world[:, 0] = log.p_world[:, 0].min()
    log.q_body_to_world[:] = [1.0, 0.0, 0.0, 0.0]
    log.thrust_cmd[:] = MASS * G
    log.v_world[:, 0] = np.random.default_rng(5).normal(0.0, VELOCITY_NOISE, n)
    glitches = [500, 1200]
    log.v_world[glitches, 0] += 0.05
    jolt = outward_jolt(log, np.array([1.0, 0.0, 0.0]))
    window_s = 2 * round(STRIKE_WINDOW_S * RATE_HZ / 2) / RATE_HZ
    assert np.nanmax(jolt) > 10 * np.sqrt(2) * VELOCITY_NOISE / window_s  # as far above the scatter as a strike
    assert surface_strikes(log) == []


def test_strikes_on_the_ceiling_are_found_against_gravity_and_the_thrust():
    """The same survey flown up and down under a ceiling: the thrust carries the weight as well, and the jolt away
    from the ceiling is what is left beyond both."""
    log, held = _survey(depth=0.005, ceiling=True)
    (struck,) = surface_strikes(log)
    assert (struck.surface, struck.effect) == ("ceiling", "ceiling_effect")
    assert len(struck.times) == 5 and struck.pressed_s == 0.0
    assert struck.closest == pytest.approx(STOP, abs=1e-4)
    assert struck.in_contact[held].all()
    survey, held = _survey(depth=-0.001, ceiling=True)
    assert not held.any() and surface_strikes(survey) == []


def test_a_vehicle_driven_into_the_ceiling_is_pressed_against_it_and_one_hovering_under_it_is_not():
    """3 cm under the ceiling and still, the thrust at the weight for 2 s, then at 1.5 times it for 2 s (the loop
    winding up against a ceiling it cannot pass), then at the weight again. Only the middle 2 s is the vehicle pushed
    down harder than gravity less the thrust, which only the ceiling does (less the half-second average's edges)."""
    t = np.arange(int(6.0 * RATE_HZ)) / RATE_HZ
    n = len(t)
    thrust = np.where((t >= 2.0) & (t < 4.0), 1.5, 1.0) * MASS * G
    vehicle = NominalVehicle.from_vehicle_params(VehicleParams(mass=MASS))
    rng = np.random.default_rng(3)
    log = FlightLog(t=t, p_world=np.column_stack([np.zeros(n), np.zeros(n), np.full(n, CEILING_Z - 0.03)]),
                    v_world=rng.normal(0.0, VELOCITY_NOISE, (n, 3)), q_body_to_world=np.tile([1.0, 0, 0, 0], (n, 1)),
                    omega_body=np.zeros((n, 3)), thrust_cmd=thrust, omega_cmd_body=np.zeros((n, 3)), vehicle=vehicle,
                    scene=Scene((), 0.0, CEILING_Z), gravity=G)
    pressed = pressed_against(log, np.array([0.0, 0.0, -1.0]))
    # the 0.5 s average of a 0.5 g step crosses 0.25 g half way in: from 2.0 s to 4.0 s, within a sample or two
    assert 1.95 <= t[pressed].min() <= 2.05 and 3.93 <= t[pressed].max() <= 4.02
    assert pressed.sum() / RATE_HZ == pytest.approx(2.0, abs=0.08)
    (touched,) = surface_strikes(log)
    assert touched.surface == "ceiling" and len(touched.times) == 0
    assert touched.pressed_s == pytest.approx(2.0, abs=0.08)
    assert touched.touch_distance == pytest.approx(0.03 + CONTACT_MARGIN, abs=1e-6)
    hover = FlightLog(**{**log.__dict__, "thrust_cmd": np.full(n, MASS * G)})
    assert not pressed_against(hover, np.array([0.0, 0.0, -1.0])).any() and surface_strikes(hover) == []


def test_the_jump_measures_a_strike_from_the_pull_the_vehicle_was_under_just_before():
    """Near the wall suction keeps the jolt at -1.5 m/s^2 along the approach; a strike lifts it to +2.2 m/s^2 for a
    window. Measured from zero that is 2.2; measured from where it was just before, the 3.7 the wall gave. Before
    the earlier window fits (the log's start) there is no jump."""
    half = 2
    t = np.arange(200) / RATE_HZ
    jolt = -1.5 + 0.2 * np.sin(2 * np.pi * 0.5 * t)  # suction's pull, changing slowly along the approach
    strike = 120
    jolt[strike - half:strike + half + 1] = 2.2
    jump = jolt_jump(jolt, half)
    width = 2 * half + 1
    assert np.isnan(jump[:2 * width - 1]).all() and np.isfinite(jump[2 * width - 1:]).all()
    before = jolt[strike - half - width:strike - half].mean()
    assert jump[strike] == pytest.approx(2.2 - before, abs=1e-12)
    assert 3.6 < jump[strike] < 3.8
    quiet = np.isfinite(jump) & (np.abs(np.arange(200) - strike) > 3 * width)
    assert np.abs(jump[quiet]).max() < 0.04  # the pull changes by at most 0.63 m/s^3 x 50 ms = 0.03 m/s^2


def _turned(log: FlightLog, yaw: float, scene: Scene) -> FlightLog:
    """``log`` turned by ``yaw`` (rad) about the world's z axis, in ``scene``."""
    c, s = np.cos(yaw), np.sin(yaw)
    R_turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    q_turn = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    w, x, y, z = log.q_body_to_world.T  # q_turn * q, q_turn about z only
    q = np.column_stack([q_turn[0] * w - q_turn[3] * z, q_turn[0] * x - q_turn[3] * y, q_turn[0] * y + q_turn[3] * x,
                         q_turn[0] * z + q_turn[3] * w])
    return FlightLog(**{**log.__dict__, "p_world": log.p_world @ R_turn.T, "v_world": log.v_world @ R_turn.T,
                        "q_body_to_world": q, "scene": scene,
                        "a_world": None if log.a_world is None else log.a_world @ R_turn.T})


def test_strikes_on_a_wall_the_scene_does_not_have_name_its_normal_and_where_the_vehicle_stopped():
    """The same five strikes with the wall missing from the scene, and the world turned 35.4 degrees about z: the
    wall's normal is (cos 35.4, sin 35.4, 0). No declared surface is struck. The five strikes fall at one place on
    the wall, so the undeclared wall is found along the tried normal nearest it (10 degrees apart), where the rotor
    centres stopped, and every sample the wall held is in contact. A survey that turns back short of the wall
    strikes nothing."""
    yaw = np.radians(35.4)
    log, held = _survey(depth=0.005)
    turned = _turned(log, yaw, Scene((), 0.0, None))
    assert surface_strikes(turned) == []
    (struck,) = undeclared_strikes(turned, np.zeros(turned.n_samples, dtype=bool))
    assert struck.effect is None and len(struck.times) == 5
    assert np.degrees(np.arccos(struck.normal @ [np.cos(yaw), np.sin(yaw), 0.0])) <= 5.0 + 1e-9
    assert min(abs(np.degrees(np.arctan2(struck.normal[1], struck.normal[0])) - a) for a in (30.0, 40.0)) < 1e-9
    rotors = turned.p_world[:, None, :] + np.einsum("nij,rj->nri", turned.R_body_to_world,
                                                    turned.vehicle.rotor_positions_array)
    assert struck.stopped_at == pytest.approx((rotors @ struck.normal).min(), abs=1e-12)
    assert struck.in_contact[held].all()
    # samples already left out (a rest, say) neither strike nor place the plane: without the strikes, nothing
    assert undeclared_strikes(turned, struck.in_contact) == []
    short, held = _survey(depth=-0.001)
    assert not held.any() and undeclared_strikes(_turned(short, yaw, Scene((), 0.0, None)),
                                                 np.zeros(short.n_samples, dtype=bool)) == []


def test_strikes_found_as_undeclared_that_fall_on_a_wall_of_the_scene_are_that_walls():
    """The five strikes found without the wall in the scene (5 degrees off its normal, as a guard sliding along it
    pushes) are, in the scene that has the wall, that wall's: its name, effect and normal, the rotor centres'
    closest approach to its plane, and, as on the scene's plane, every sample nearer it than where the strikes
    stopped them is contact. The same wall 1 m
    farther out, 0.1 m nearer (the rotors went behind it) or turned 90 degrees (0.2 m to the side, within reach of
    the flight) is not where the strikes were."""
    yaw = np.radians(35.4)
    log, held = _survey(depth=0.005)
    (struck,) = undeclared_strikes(_turned(log, yaw, Scene((), 0.0, None)), np.zeros(log.n_samples, dtype=bool))
    normal = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    with_wall = _turned(log, yaw, Scene((Wall((0.0, 0.0, 0.0), tuple(normal)),), 0.0, None))
    wall = declared_surface(with_wall, struck)
    assert wall is not None and (wall.surface, wall.effect, wall.stopped_at) == ("wall 0", "wall_suction", None)
    assert np.allclose(wall.normal, normal) and np.array_equal(wall.times, struck.times)
    rotors = with_wall.p_world[:, None, :] + np.einsum("nij,rj->nri", with_wall.R_body_to_world,
                                                       with_wall.vehicle.rotor_positions_array)
    distance = (rotors @ normal).min(axis=1)
    assert wall.closest == pytest.approx(distance.min(), abs=1e-12) and wall.closest == pytest.approx(STOP, abs=2e-3)
    # the guards touch the wall where the strikes stopped the rotor centres: every sample nearer is contact too
    assert wall.touch_distance == pytest.approx(STOP + CONTACT_MARGIN, abs=1e-3)
    assert wall.in_contact[struck.in_contact].all() and wall.in_contact[distance < wall.touch_distance].all()
    assert wall.in_contact[held].all() and wall.in_contact.mean() < 0.2
    side = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    for point, facing in ((-1.0 * normal, normal), (0.1 * normal, normal), (-0.2 * side, side)):
        elsewhere = _turned(log, yaw, Scene((Wall(tuple(point), tuple(facing)),), 0.0, None))
        assert declared_surface(elsewhere, struck) is None


def test_an_undeclared_wall_struck_along_its_length_is_turned_to_the_plane_through_the_strikes():
    """The same survey drifting 2 m along the wall, turned 35.4 degrees: each tried normal's plane (10 degrees apart)
    meets the flight at one end, where it strikes only some of the five times. The points where the strikes
    stopped the rotor centres span the wall, and the plane through them is the wall's: its normal within 0.2
    degrees, and all five strikes on it."""
    yaw = np.radians(35.4)
    log, held = _survey(depth=0.005, along_wall=1.0)
    turned = _turned(log, yaw, Scene((), 0.0, None))
    (struck,) = undeclared_strikes(turned, np.zeros(turned.n_samples, dtype=bool))
    assert np.degrees(np.arccos(min(1.0, struck.normal @ [np.cos(yaw), np.sin(yaw), 0.0]))) < 0.2
    assert len(struck.times) == 5 and struck.in_contact[held].all()
    assert normal_text(struck.normal) == "(+0.815, +0.579, +0.000)"


def test_strikes_at_several_speeds_on_a_guard_that_gives_are_all_strikes_on_one_wall():
    """Struck ever faster (0.5 to 1.3 m/s) into a guard that gives 15 ms times the speed it is struck at, the fastest
    strike goes farthest and the others stop short of it by up to 12 mm. Each of the five is a strike, on the
    declared wall and on the same wall missing from the scene, and every sample the wall held is in contact.
    Counting only strikes within SAME_DISTANCE of the farthest found four."""
    n = int(20.0 * RATE_HZ)
    log, held = _survey(depth=np.linspace(0.01, 0.5, n), amplitude=1.0, give_s=0.015)
    (wall,) = surface_strikes(log)
    assert len(wall.times) == 5 and wall.in_contact[held].all()
    speeds = [-float(log.v_world[max(0, i - 5):i - 1, 0].mean()) for i in np.searchsorted(log.t, wall.times)]
    assert min(speeds) > 0.4 and max(speeds) > 1.2
    farthest = [float(log.p_world[max(0, i - 3):i + 4, 0].min()) for i in np.searchsorted(log.t, wall.times)]
    assert np.ptp(farthest) > 2 * SAME_DISTANCE
    assert wall.give == pytest.approx(SAME_DISTANCE + 0.5 * STRIKE_WINDOW_S * max(speeds), rel=0.1)
    hidden = FlightLog(**{**log.__dict__, "scene": Scene((), 0.0, None)})
    (struck,) = undeclared_strikes(hidden, np.zeros(hidden.n_samples, dtype=bool))
    assert np.allclose(struck.normal, [1.0, 0.0, 0.0]) and len(struck.times) == 5 and struck.in_contact[held].all()


def test_strikes_on_a_ceiling_the_scene_does_not_have_face_down():
    """The survey up and down under a ceiling missing from the scene: the strikes are found facing down, and the
    rotors stopped at the ceiling's height less the stop."""
    log, held = _survey(depth=0.005, ceiling=True)
    log = FlightLog(**{**log.__dict__, "scene": Scene((), 0.0, None)})
    assert surface_strikes(log) == []
    (struck,) = undeclared_strikes(log, np.zeros(log.n_samples, dtype=bool))
    assert np.allclose(struck.normal, [0.0, 0.0, -1.0]) and len(struck.times) == 5
    assert struck.stopped_at == pytest.approx(-(CEILING_Z - STOP), abs=1e-4)  # along -z: minus the height
    assert struck.in_contact[held].all()


def _slide_along_wall(held_back: float, seed: int = 5, growing_over: float | None = None
                      ) -> tuple[FlightLog, np.ndarray]:
    """30 s swinging along a wall at x = 0 (y, 0.8 m either side, period 6 s) while the distance goes out and in
    slowly: three times the vehicle eases in over 2 s to where the nearest rotor centre is STOP from the plane, stays
    there for 4 s and eases out to 15 cm further. Linear drag (0.3 1/s) acts all along, and the thrust makes up for
    it. At the wall the thrust also makes up for ``held_back`` (m/s^2) against the sliding: what friction takes when
    the guards touch; with 0 the vehicle holds itself at that distance without touching (a survey at a constant
    standoff). With ``growing_over`` (m) the hold-back is not friction but a drag that grows toward the wall, by e
    every ``growing_over`` nearer, to ``held_back`` at the wall. The position, velocity and attitude are the same
    in every case. Returns the log and the samples at the wall."""
    vehicle = NominalVehicle.from_vehicle_params(VehicleParams(mass=MASS))
    t = np.arange(int(30.0 * RATE_HZ)) / RATE_HZ
    n = len(t)
    phase = np.mod(t, 10.0)  # out 0-2 s, easing in 2-4 s, at the wall 4-8 s, easing out 8-10 s
    ease = np.clip(np.where(phase < 6.0, (phase - 2.0) / 2.0, (10.0 - phase) / 2.0), 0.0, 1.0)
    ease = 0.5 * (1 - np.cos(np.pi * ease))  # 0 far out, 1 at the wall, with no speed at either end
    x = STOP - float(vehicle.rotor_positions_array[:, 0].min()) + 0.15 * (1.0 - ease)
    y = 0.8 * np.sin(2 * np.pi * t / 6.0)
    v = np.column_stack([np.gradient(x, t), np.gradient(y, t), np.zeros(n)])
    a = np.column_stack([np.gradient(v[:, 0], t), np.gradient(v[:, 1], t), np.zeros(n)])
    at_wall = ease >= 1.0
    speed = np.maximum(np.linalg.norm(v, axis=1), 1e-9)
    x_wall = STOP - float(vehicle.rotor_positions_array[:, 0].min())
    share = at_wall if growing_over is None else np.exp(-(x - x_wall) / growing_over)
    a_thrust = a + 0.3 * v + held_back * share[:, None] * v / speed[:, None]
    angle, axis = _tilt(a_thrust[:, 0], a_thrust[:, 1])
    q = np.column_stack([np.cos(angle / 2), *(np.sin(angle / 2) * axis.T)])
    rng = np.random.default_rng(seed)
    log = FlightLog(t=t, p_world=np.column_stack([x, y, np.full(n, 1.0)]),
                    v_world=v + rng.normal(0.0, VELOCITY_NOISE, (n, 3)), q_body_to_world=q,
                    omega_body=np.zeros((n, 3)), thrust_cmd=MASS * np.sqrt(np.sum(a_thrust[:, :2] ** 2, axis=1) + G**2),
                    omega_cmd_body=np.zeros((n, 3)), vehicle=vehicle,
                    scene=Scene((Wall((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),), 0.0, None), gravity=G)
    return log, at_wall


def test_a_vehicle_held_back_as_it_slides_along_the_wall_touches_it_and_one_at_the_same_standoff_does_not():
    """Eased in too slowly to strike, the vehicle slides along the wall for 12 s held back by friction (0.6 m/s^2
    against its sliding, beyond the drag it has everywhere): the wall is touched, the hold-back is measured within
    10 %, and the samples at the wall are in contact while those 15 cm out are not. The same flight holding itself
    at the same distance (no friction) is not taken for contact: the drag fitted away from the wall explains it. Nor
    is a drag that grows toward the wall, by e every 5 cm nearer (the scale of a rotor), to the same 0.6 m/s^2 at
    it: it holds the vehicle back just outside the contact nearly as much (over 3 cm or less it would be taken for
    friction)."""
    log, at_wall = _slide_along_wall(held_back=0.6)
    normal = np.array([1.0, 0.0, 0.0])
    rotors = rotor_centres_world(log.p_world, log.R_body_to_world, log.vehicle.rotor_positions_array)
    distance = log.scene.walls[0].distance(rotors).min(axis=1)
    assert distance.min() == pytest.approx(STOP, abs=1e-3)
    (touched,) = surface_strikes(log)
    assert touched.surface == "wall 0" and len(touched.times) == 0 and touched.pressed_s == 0.0
    near = (distance < distance.min() + SAME_DISTANCE).sum() / RATE_HZ  # 12 s at the wall and the easing's ends
    assert 6.0 < touched.slid_s <= near  # the time there sliding faster than SLIDE_SPEED
    assert touched.held_back == pytest.approx(0.6, rel=0.1)
    assert touched.in_contact[at_wall].all() and not touched.in_contact[distance > STOP + 0.05].any()
    standoff, _ = _slide_along_wall(held_back=0.0)
    seconds, held_back, z = slid_along(standoff, normal, distance, float(distance.min()))
    assert seconds > 6.0 and abs(held_back) < RUB_MIN / 4 and abs(z) < RUB_Z / 2
    assert surface_strikes(standoff) == []
    growing, _ = _slide_along_wall(held_back=0.6, growing_over=0.05)
    seconds, held_back, z = slid_along(growing, normal, distance, float(distance.min()))
    assert held_back < RUB_MIN and z < RUB_Z
    assert surface_strikes(growing) == []
