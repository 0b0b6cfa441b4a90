"""What a flight can and cannot tell: ground contact to leave out, and effects the flight never excited.

Two checks that make a report say *why* it could or could not say more:

- :func:`resting_on_ground`: samples where the thrust carries less than half the
  weight and yet the vehicle does not fall (vertical acceleration above -g/4, while
  a free vehicle would fall at more than g/2). Something else holds it up (the
  ground, a hand, a stand); that force is not aerodynamic, so these samples are left
  out of the fits and the report says how long they lasted.
- :func:`scene_problems`: a rotor behind a wall, below the ground or above the
  ceiling means the scene (sidecar or scene file) is wrong, not the physics: the
  note says which surface and the fix (flip a wall normal, move a point, lower
  ``ground_z``).
- :func:`flight_limits`: for each kind of effect, whether the flight went where the
  effect acts (near a wall, the ground, the ceiling; fast along a body axis; with a
  varying thrust). Where it did not, the effect cannot be found or told apart, and
  the note names the manoeuvre that would determine it.
"""

from __future__ import annotations

import numpy as np

from discovery.differentiation import moving_average
from discovery.flight_log import FlightLog

__all__ = ["REST_THRUST_SHARE", "resting_on_ground", "flight_limits", "scene_problems"]

REST_THRUST_SHARE = 0.5  # of the weight
NOT_FALLING = 0.25  # of g: a vertical acceleration above -NOT_FALLING g with thrust below half the weight is held
NEAR_SURFACE = 0.3  # m: wall suction, ground and ceiling effects act within about this distance
SPEED_FOR_DRAG = 0.5  # m/s rms along a body axis to determine drag along it
THRUST_VARIATION = 0.1  # relative standard deviation of the thrust that separates a thrust scale from a steady force


def resting_on_ground(log: FlightLog) -> np.ndarray:
    """Samples where something other than the thrust holds the vehicle up (see the module text)."""
    thrust = log.rotor_thrusts.sum(axis=1) if log.rotor_thrusts is not None else log.thrust_cmd
    vertical = thrust * log.R_body_to_world[:, 2, 2]
    weight = log.vehicle.mass * log.gravity
    dt = float(np.median(np.diff(log.t)))
    v_smooth = moving_average(log.v_world[:, 2], max(1, int(round(0.5 / dt))))
    a_z = np.gradient(v_smooth, log.t)
    # with the thrust carrying a share s < 1/2 of the weight a free vehicle falls at (1 - s) g > g / 2
    not_falling = a_z > -NOT_FALLING * log.gravity
    return (vertical < REST_THRUST_SHARE * weight) & not_falling


def flight_limits(regressors: list, thrust: np.ndarray) -> list[dict]:
    """Effects this flight cannot determine, each ``{"effects", "reason", "manoeuvre"}``."""
    values = {r.name: r.values for r in regressors}
    out = []

    def closest(name: str) -> float | None:
        v = values.get(name)
        return None if v is None or not np.isfinite(v).any() else float(np.nanmin(v))

    walls = sorted(n for n in values if n.startswith("nearest rotor distance to wall")
                   or n == "nearest rotor distance to the structure")
    if not walls:
        out.append({"effects": ["wall_suction"], "reason": "the scene has no wall",
                    "manoeuvre": "add the wall to the scene (sidecar or --scene) and fly within "
                                 f"{NEAR_SURFACE:g} m of it"})
    else:
        distances = [d for d in (closest(n) for n in walls) if d is not None]
        nearest = min(distances) if distances else float("inf")
        if nearest > NEAR_SURFACE:
            out.append({"effects": ["wall_suction"],
                        "reason": f"the rotors never came closer than {nearest:.2f} m to a wall",
                        "manoeuvre": f"fly with the rotors within {NEAR_SURFACE:g} m of the wall, at several distances"})
    for name, effect, surface in (("height above ground", "ground_effect", "ground"),
                                  ("distance to ceiling", "ceiling_effect", "ceiling")):
        low = closest(name)
        if low is None:
            out.append({"effects": [effect], "reason": f"the scene has no {surface}",
                        "manoeuvre": f"give {surface}_z in the scene and fly within {NEAR_SURFACE:g} m of it"})
        elif low > NEAR_SURFACE:
            out.append({"effects": [effect],
                        "reason": f"the rotors never came closer than {low:.2f} m to the {surface}",
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
        variation = float(np.std(thrust) / max(np.mean(thrust), 1e-9))
        if variation < THRUST_VARIATION:
            out.append({"effects": ["thrust_scale", "constant_force"],
                        "reason": f"the thrust varies by only {100 * variation:.0f} % (std/mean): a thrust scale "
                                  "and a vertical steady force look alike",
                        "manoeuvre": "climb and descend briskly (thrust varying by 20 % or more) to tell them apart"})
    return out


PENETRATION = 0.02  # m beyond a surface before a sample counts as through it


def scene_problems(regressors: list, times: np.ndarray) -> list[str]:
    """Likely sidecar errors: rotors through a wall, the ground or the ceiling, with the fix to make."""
    out = []
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
            out.append(f"likely sidecar error: the rotors are behind wall {k} (down to {deepest:.2f} m) for "
                       f"{seconds:.1f} s, which a vehicle cannot be; {fix}")
        elif reg.name == "height above ground":
            out.append(f"likely sidecar error: the rotors are below the ground (down to {deepest:.2f} m under "
                       f"ground_z) for {seconds:.1f} s; lower scene.ground_z by at least {-deepest:.2f} m, or the "
                       "position estimate drifted (check the log's altitude source)")
        elif reg.name == "distance to ceiling":
            out.append(f"likely sidecar error: the rotors are above the ceiling (by up to {-deepest:.2f} m) for "
                       f"{seconds:.1f} s; raise scene.ceiling_z by at least {-deepest:.2f} m")
    return out
