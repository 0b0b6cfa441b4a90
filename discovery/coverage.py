"""What a flight can and cannot tell: ground contact to leave out, and effects the flight never excited.

Two checks that make a report say *why* it could or could not say more:

- :func:`resting_on_ground`: samples where the thrust carries less than half the
  weight and yet the vehicle falls slower than that thrust lets it: its vertical
  acceleration is more than g/4 above the thrust's (both smoothed alike), while a free
  vehicle would fall at more than g/2. Something else holds it up (the ground, a hand,
  a stand); that force is not aerodynamic, so these samples are left out of the fits
  and the report says how long they lasted. A vehicle that drops the thrust to start a
  quick descent is not held: it falls as fast as its thrust says.
- :func:`ground_contact`: the rotors spinning up on the ground before a take-off and
  the touchdown before they stop, next to a rest: near the height the vehicle rested
  at, with the thrust below the weight. The ground still carries part of the weight
  (the thrust ramps from half the weight to all of it), so these are left out too.
- :func:`at_ceiling`: where a rest is at the ceiling rather than on the ground. A
  vehicle can be held *up* there too: drawn to the ceiling by its rotors' own ceiling
  effect, with the thrust cut below half the weight, it stays. That is contact with the
  ceiling or a gain nearer the ceiling than any image-rotor form is trusted
  (:mod:`discovery.form_range`), so it is left out as well, under its own name.
- :func:`scene_problems`: a rotor behind a wall, below the ground or above the
  ceiling means the scene (sidecar or scene file) is wrong, not the physics: the
  note says which surface and the fix (flip a wall normal, move a point, lower
  ``ground_z``).
- :func:`flight_limits`: for each kind of effect, whether the flight went where the
  effect acts (near a wall, the ground, the ceiling; fast along a body axis; with a
  varying thrust). Where it did not, the effect cannot be found or told apart, and
  the note names the manoeuvre that would determine it. A ground or ceiling effect
  whose surface the flight never came near (:func:`far_surfaces`) is not fitted.
"""

from __future__ import annotations

import numpy as np

from discovery.differentiation import moving_average
from discovery.flight_log import FlightLog
from discovery.regressors import rotor_centres_world, surface_clearances

__all__ = ["REST_THRUST_SHARE", "CONTACT_HEIGHT", "HELD_WINDOW_S", "pushed_beyond_free", "resting_on_ground",
           "ground_contact", "at_ceiling", "rotor_clearances", "flight_limits", "far_surfaces", "nearest_wall",
           "thrust_variation", "scene_problems"]

REST_THRUST_SHARE = 0.5  # of the weight
NOT_FALLING = 0.25  # of g: falling this much slower than the thrust lets it, with thrust below half the weight, is held
HELD_WINDOW_S = 0.5  # s: the acceleration beyond the thrust's that holds a vehicle is averaged over this long
NEAR_SURFACE = 0.3  # m: wall suction, ground and ceiling effects act within about this distance
SPEED_FOR_DRAG = 0.5  # m/s rms along a body axis to determine drag along it
THRUST_VARIATION = 0.1  # relative standard deviation of the thrust that separates a thrust scale from a steady force


def pushed_beyond_free(log: FlightLog, direction: np.ndarray, *, accelerometer: bool) -> np.ndarray:
    """Samples at which the vehicle accelerates along ``direction`` by more than :data:`NOT_FALLING` g beyond what
    the thrust and gravity give it, both averaged over :data:`HELD_WINDOW_S`: something else pushes it that way
    (the ground holds it up, a ceiling pushes it down). The thrust's own acceleration is smoothed like the measured
    one, so that a short, deliberate drop of the thrust in the air (a quick descent) does not look held under the
    smoothing. With ``accelerometer`` the measured acceleration is the log's ``a_world`` where it has one;
    otherwise, and without it, the derivative of the averaged velocity."""
    window = max(1, int(round(HELD_WINDOW_S / float(np.median(np.diff(log.t))))))
    measured = (moving_average(log.a_world @ direction, window) if accelerometer and log.a_world is not None
                else np.gradient(moving_average(log.v_world @ direction, window), log.t))
    return measured > moving_average(log.free_acceleration(direction), window) + NOT_FALLING * log.gravity


def resting_on_ground(log: FlightLog) -> np.ndarray:
    """Samples where something other than the thrust holds the vehicle up (see the module text): the thrust carries
    less than half the weight, so a free vehicle would fall at more than g / 2, and it falls :data:`NOT_FALLING` g
    slower than that (:func:`pushed_beyond_free`, from the velocity)."""
    vertical = log.total_thrust * log.R_body_to_world[:, 2, 2]
    weight = log.vehicle.mass * log.gravity
    return (vertical < REST_THRUST_SHARE * weight) & pushed_beyond_free(log, np.array([0.0, 0.0, 1.0]),
                                                                        accelerometer=False)


CONTACT_HEIGHT = 0.03  # m: within this of the height the vehicle rested at, it is still on the ground
CONTACT_CENTRE_S = 0.5  # s of a rest stretch next to its end whose median height is the ground's


def ground_contact(log: FlightLog) -> tuple[np.ndarray, np.ndarray]:
    """Samples on the ground with the rotors turning: spin-up before a take-off and touchdown before the rotors stop.

    They extend each stretch the vehicle rested (:func:`resting_on_ground`) for as long as the vertical thrust
    stays below the weight and the height no more than :data:`CONTACT_HEIGHT` above the ground: the height it
    rested at (the median over the :data:`CONTACT_CENTRE_S` next to the stretch's end), or before a touchdown the
    higher of that and the heights it took off from. The ground still carries part of the weight there, a force
    that is not aerodynamic. The velocity is not asked: a state estimate drifts on touchdown (a PX4 SITL log
    reads 0.46 m/s down, and heights down to 0.45 m below the take-off's, while on the ground). A stretch held
    at the ceiling (:func:`at_ceiling`) is extended the other way: while the vehicle stays no more than
    :data:`CONTACT_HEIGHT` below the height it was held at. Returns ``(resting, contact)``: the held-up samples
    and the samples next to them that the surface still carries."""
    resting = resting_on_ground(log)
    contact = np.zeros_like(resting)
    if not resting.any() or resting.all():
        return resting, contact
    vertical = log.total_thrust * log.R_body_to_world[:, 2, 2]
    weight = log.vehicle.mass * log.gravity
    height = log.p_world[:, 2]
    ceiling = at_ceiling(log)
    dt = float(np.median(np.diff(log.t)))
    centre = max(1, int(round(CONTACT_CENTRE_S / dt)))
    edges = np.flatnonzero(np.diff(resting.astype(int)))  # index before each change
    take_off: list[float] = []  # heights the vehicle rested at on the ground before each take-off
    for edge in edges:
        rest = edge if resting[edge] else edge + 1
        if resting[edge]:  # a rest stretch ends at edge: spin-up (or leaving the ceiling) after it
            held = float(np.median(height[max(0, edge - centre + 1):edge + 1]))
            if not ceiling[rest]:
                take_off.append(held)
            step, i = 1, edge + 1
        else:  # a rest stretch starts at edge + 1: touchdown before it; the estimate may have drifted below
            # the height the vehicle took off from (a PX4 SITL log reads 0.45 m below it), and the vehicle is down
            # once it is back at that height
            held = float(np.median(height[edge + 1:edge + 1 + centre]))
            if not ceiling[rest]:
                held = max([held] + take_off)
            step, i = -1, edge
        # on the ground the vehicle is carried while no higher than it rested; at the ceiling, no lower than it hung
        sign = -1.0 if ceiling[rest] else 1.0
        while 0 <= i < len(height) and not resting[i] and vertical[i] < weight \
                and sign * (height[i] - held) <= CONTACT_HEIGHT:
            contact[i] = True
            i += step
    return resting, contact


def at_ceiling(log: FlightLog) -> np.ndarray:
    """The samples at which the vehicle is at the ceiling rather than on the ground: the scene has a ceiling, the
    highest rotor is within :data:`NEAR_SURFACE` of it and nearer it than the lowest rotor is to the ground (when the
    scene has one). A rest (:func:`ground_contact`) at such samples is held at the ceiling."""
    below_ceiling, above_ground = rotor_clearances(log)
    return (below_ceiling < NEAR_SURFACE) & (below_ceiling < above_ground)


def rotor_clearances(log: FlightLog) -> tuple[np.ndarray, np.ndarray]:
    """``(below_ceiling, above_ground)`` (m) at every sample (:func:`discovery.regressors.surface_clearances`), inf
    where the scene has no such surface."""
    rotor_z = rotor_centres_world(log.p_world, log.R_body_to_world, log.vehicle.rotor_positions_array)[:, :, 2]
    above_ground, below_ceiling = surface_clearances(rotor_z, log.scene)
    never = np.full(log.n_samples, np.inf)
    return (never if below_ceiling is None else below_ceiling), (never if above_ground is None else above_ground)


def nearest_wall(regressors: list) -> float | None:
    """The rotors' closest approach to a wall (m) over the flight, inf when never finite; None when the scene has no
    wall."""
    walls = [r for r in regressors if r.name.startswith("nearest rotor distance to wall")
             or r.name == "nearest rotor distance to the structure"]
    if not walls:
        return None
    distances = [float(np.nanmin(r.values)) for r in walls if np.isfinite(r.values).any()]
    return min(distances) if distances else float("inf")


def thrust_variation(thrust: np.ndarray) -> float:
    """How much the thrust varied over the flight: its standard deviation over its mean. Below
    :data:`THRUST_VARIATION` a thrust scale and a vertical steady force look alike."""
    return float(np.std(thrust) / max(np.mean(thrust), 1e-9))


#: the regressor of each surface whose image-rotor effect is a candidate only where the flight came near it
SURFACE_EFFECTS = (("height above ground", "ground_effect", "ground"), ("distance to ceiling", "ceiling_effect", "ceiling"))


def _closest(regressors: list, name: str) -> float | None:
    """The least value of regressor ``name`` (m), None when the flight has none."""
    v = next((r.values for r in regressors if r.name == name), None)
    return None if v is None or not np.isfinite(v).any() else float(np.nanmin(v))


def far_surfaces(regressors: list) -> dict[str, float]:
    """The ground and ceiling effects whose surface the rotors never came within :data:`NEAR_SURFACE` of, with the
    closest approach (m): such a flight cannot determine them, so they are not candidates.

    A 2 kg vehicle flown up and down between 0.7 m and 1.7 m against a force growing with height was given a ground
    effect of radius 0.42 m (2.4 % of the thrust at 0.7 m): its gain, a function of the height, bent an affine thrust
    map to the force, and with the ground effect written the height was the model's own quantity, so the map was never
    asked whether it stood in for a force of the height."""
    out = {}
    for name, effect, _ in SURFACE_EFFECTS:
        low = _closest(regressors, name)
        if low is not None and low > NEAR_SURFACE:
            out[effect] = low
    return out


def flight_limits(regressors: list, thrust: np.ndarray, asked: str | None = None) -> list[dict]:
    """Effects this flight cannot determine, each ``{"effects", "reason", "manoeuvre"}``; ``asked``: the one effect
    the user asked to fit, which is fitted even on a surface the flight never came near."""
    values = {r.name: r.values for r in regressors}
    out = []

    nearest = nearest_wall(regressors)
    if nearest is None:
        out.append({"effects": ["wall_suction"], "reason": "the scene has no wall",
                    "manoeuvre": "add the wall to the scene (sidecar or --scene) and fly within "
                                 f"{NEAR_SURFACE:g} m of it"})
    else:
        if nearest > NEAR_SURFACE:
            out.append({"effects": ["wall_suction"],
                        "reason": f"the rotors never came closer than {nearest:.2f} m to a wall",
                        "manoeuvre": f"fly with the rotors within {NEAR_SURFACE:g} m of the wall, at several distances"})
    far = far_surfaces(regressors)
    for name, effect, surface in SURFACE_EFFECTS:
        if _closest(regressors, name) is None:
            out.append({"effects": [effect], "reason": f"the scene has no {surface}",
                        "manoeuvre": f"give {surface}_z in the scene and fly within {NEAR_SURFACE:g} m of it"})
        elif effect in far:
            out.append({"effects": [effect],
                        "reason": f"the rotors never came closer than {far[effect]:.2f} m to the {surface}"
                                  + ("" if effect == asked else ": not fitted"),
                        "manoeuvre": f"hover at several heights within {NEAR_SURFACE:g} m of the {surface}"})
    for axis in "xyz":
        v = values.get(f"velocity along body {axis}")
        if v is None:
            continue
        rms = float(np.sqrt(np.nanmean(v**2)))
        if rms < SPEED_FOR_DRAG:
            out.append({"effects": ["linear_drag", "quadratic_drag"],
                        "reason": f"speed along body {axis} is {rms:.2f} m/s rms: too slow to determine drag "
                                  f"along body {axis}",
                        "manoeuvre": f"fly back and forth along body {axis} at 1 m/s or more"})
    if len(thrust):
        variation = thrust_variation(thrust)
        if variation < THRUST_VARIATION:
            out.append({"effects": ["thrust_scale", "constant_force"],
                        "reason": f"the thrust varies by only {100 * variation:.0f} % (std/mean): a thrust scale "
                                  "and a vertical steady force look alike",
                        "manoeuvre": "climb and descend briskly (thrust varying by 20 % or more) to tell them apart"})
    return out


PENETRATION = 0.02  # m beyond a surface before a sample counts as through it


def scene_problems(regressors: list, times: np.ndarray) -> list[dict]:
    """Likely sidecar errors: rotors through a wall, the ground or the ceiling, with the fix to make.

    Each is ``{"message", "surface", "effects", "wall", "reversed"}``: the warning, the surface (``wall``,
    ``ground``, ``ceiling``), the effects that act against it, the wall's index (walls only) and whether
    the flight is behind the wall most of the time (its normal points into the wall: the fix is certain).
    """
    out: list[dict] = []
    dt = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    for reg in regressors:
        v = reg.values
        if not np.isfinite(v).any():
            continue
        through = v < -PENETRATION
        if not through.any():
            continue
        seconds, deepest = through.sum() * dt, float(np.nanmin(v))
        if reg.name.startswith("nearest rotor distance to wall"):
            k = reg.name.rsplit(" ", 1)[-1]
            most = float(np.mean(v[np.isfinite(v)] < 0))
            fix = (f"its normal points into the wall: flip the sign of scene.walls[{k}].normal (normals point away "
                   "from the wall, into free space)" if most > 0.5 else
                   f"move scene.walls[{k}].point at least {-deepest:.2f} m back along the normal, or check the "
                   "log's frame")
            out.append({"message": f"likely sidecar error: the rotors are behind wall {k} (down to {deepest:.2f} m) "
                                   f"for {seconds:.1f} s, which a vehicle cannot be; {fix}",
                        "surface": "wall", "wall": int(k), "reversed": most > 0.5, "effects": ["wall_suction"]})
        elif reg.name == "height above ground":
            out.append({"message": f"likely sidecar error: the rotors are below the ground (down to {deepest:.2f} m "
                                   f"under ground_z) for {seconds:.1f} s; lower scene.ground_z by at least "
                                   f"{-deepest:.2f} m, or the position estimate drifted (check the log's altitude "
                                   "source)", "surface": "ground", "reversed": False, "effects": ["ground_effect"]})
        elif reg.name == "distance to ceiling":
            out.append({"message": f"likely sidecar error: the rotors are above the ceiling (by up to {-deepest:.2f} m)"
                                   f" for {seconds:.1f} s; raise scene.ceiling_z by at least {-deepest:.2f} m",
                        "surface": "ceiling", "reversed": False, "effects": ["ceiling_effect"]})
    return out
