"""Step 2 of discovery: leave out what is not aerodynamic, with the reason.

Every sample at which something other than the thrust, gravity and the air holds or pushes the vehicle is left out
of the fit, and the report says how long and why:

- **held up**: resting on the ground (or held by a hand), the thrust carrying less than half the weight
  (:func:`discovery.coverage.ground_contact`);
- **ground contact**: the rotors spinning up or down on the ground next to a rest;
- **held at the ceiling**: drawn up onto the ceiling by its own ceiling effect (:func:`discovery.coverage.at_ceiling`);
- **wall contact**, **ceiling contact**, **ground strike**: struck, pressed against or slid along a surface of the
  scene (:mod:`discovery.surface_contact`), with a limit on the effect whose pull acts there;
- **contact with a surface not in the scene**: struck a surface the scene does not have, with where it is.

:func:`leave_out_contact` returns each log's remaining parts with these records, the notes and the limits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from discovery.coverage import (
    CONTACT_HEIGHT,
    HELD_WINDOW_S,
    NOT_FALLING,
    REST_THRUST_SHARE,
    at_ceiling,
    ground_contact,
    rotor_clearances,
)
from discovery.flight_log import FlightLog
from discovery.surface_contact import (
    CONTACT_MARGIN,
    STRIKE_WINDOW_S,
    STRIKE_Z,
    UNDECLARED_CONTACT,
    Strikes,
    declared_surface,
    ground_strikes,
    normal_text,
    surface_strikes,
    undeclared_strikes,
)

__all__ = ["LeftOut", "leave_out_contact", "MAX_TIMES_LISTED"]

MAX_TIMES_LISTED = 5  # strike times a note lists before it says how many more


@dataclass
class LeftOut:
    """What :func:`leave_out_contact` kept and left out of a set of logs."""

    logs: list[FlightLog]  # each log's samples that were kept, as a log (the parts long enough to fit)
    records: list[dict]  # per log and reason: {"log", "reason", "seconds", "time_intervals"} (the report's left_out)
    notes: list[str]  # one per log and reason, for the report
    limits: list[dict]  # the effects not measured where the vehicle touched a surface: {"effects", "reason",
    # "manoeuvre"}


def leave_out_contact(logs: list[FlightLog], shortest: float) -> LeftOut:
    """Each log of ``logs`` without the samples something other than the thrust held up or pushed (see the module
    text), with a note for each; the parts shorter than ``shortest`` (s) are dropped."""
    found = LeftOut([], [], [], [])
    airborne, records, notes = found.logs, found.records, found.notes
    for log in logs:
        resting, contact = ground_contact(log)
        dt = float(np.median(np.diff(log.t)))
        touching = _surface_contact(log, resting | contact, dt, notes, found.limits)
        on_surface = np.logical_or.reduce([np.zeros(log.n_samples, dtype=bool), *touching.values()])
        resting, contact = resting & ~on_surface, contact & ~on_surface
        ceiling = at_ceiling(log)
        hung, near_ceiling = resting & ceiling, contact & ceiling
        resting_low, contact_low = resting & ~hung, contact & ~near_ceiling
        if resting_low.any():
            notes.append(
                f"{log.source}: {resting_low.sum() * dt:.1f} s of {log.duration:.1f} s held up by something "
                f"else: the thrust carries less than {100 * REST_THRUST_SHARE:.0f} % of the weight and the vehicle "
                "does not fall (on the ground or held): "
                "left out, that force is not aerodynamic")
        if contact_low.any():
            notes.append(
                f"{log.source}: {contact_low.sum() * dt:.1f} s of rotors spinning up or down on the ground (next "
                f"to a rest, no more than {100 * CONTACT_HEIGHT:.0f} cm above the ground the vehicle rested on or "
                "took off from, the thrust below the weight): left out, the ground still carries part of the weight")
        if hung.any():
            notes.append(_held_at_ceiling(log, hung | near_ceiling, hung.sum() * dt, near_ceiling.sum() * dt))
        held = {"held up": resting_low, "ground contact": contact_low, "held at the ceiling": hung | near_ceiling}
        for why, mask in [*((why, mask) for why, mask in held.items() if mask.any()), *touching.items()]:
            records.append({"log": log.source, "reason": why, "seconds": round(float(mask.sum() * dt), 3),
                            "time_intervals": _intervals(log.t, mask)})
        left_out = resting | contact | on_surface
        if (~left_out).sum() >= 2 and not left_out.all():
            kept = log.select(~left_out)
            if kept.duration >= shortest:
                airborne.append(kept)
    return found


def _surface_contact(log: FlightLog, held: np.ndarray, dt: float, notes: list[str], limits: list[dict]
                     ) -> dict[str, np.ndarray]:
    """The samples ``log`` spent in contact with a wall or the ceiling it struck
    (:func:`discovery.surface_contact.surface_strikes`), by left-out reason ("wall contact", "ceiling contact"),
    with a note and a limit per surface; then with a surface the scene does not have
    (:func:`discovery.surface_contact.undeclared_strikes`), with a note. A stretch ``held`` up (a rest, or the
    moments next to it) that reaches into the contact is the surface holding the vehicle (friction on a wall),
    and counts as its contact too."""
    by_reason: dict[str, np.ndarray] = {}
    edges = np.flatnonzero(np.diff(np.concatenate([[0], held.astype(int), [0]])))  # the held stretches' ends

    def with_held(in_contact: np.ndarray) -> np.ndarray:
        out = in_contact.copy()
        for a, b in zip(edges[::2], edges[1::2]):
            if out[a:b].any():
                out[a:b] = True
        return out

    def declared_contact(struck: Strikes, in_contact: np.ndarray, pushed: str) -> None:
        """Leave ``in_contact`` out as contact with the scene's surface ``struck``, with a note and the limit on
        its pull; ``pushed`` says how its strikes pushed the vehicle."""
        kind = struck.surface.split(" ")[0]  # "wall", "ceiling" or "ground"
        pull = {"wall": "suction", "ceiling": "the ceiling effect", "ground": "the ground effect"}[kind]
        name = struck.surface if kind == "wall" else f"the {struck.surface}"
        reason = "ground strike" if kind == "ground" else f"{kind} contact"  # apart from a touchdown's
        reach_of = ("the landing gear's reach below the rotor centres, as struck" if kind == "ground" else
                    "a guard's reach, if the vehicle has guards,")
        by_reason[reason] = by_reason.get(reason, np.zeros(log.n_samples, dtype=bool)) | in_contact
        evidence = []
        if len(struck.times):
            evidence.append(
                f"struck {name} {_listed_times(struck.times)}: each time pushed {pushed} more than "
                f"{STRIKE_Z:g} times the log's own scatter beyond what the thrust and gravity do, within "
                f"{1e3 * STRIKE_WINDOW_S:g} ms, and within {1e3 * struck.give:.3g} mm of its closest approach")
        if struck.pressed_s > 0:
            evidence.append(
                f"was pressed against {name} for {struck.pressed_s:.1f} s: pushed away from it more than "
                f"{NOT_FALLING:g} g beyond what the thrust and gravity do (over {HELD_WINDOW_S:g} s), as no "
                "aerodynamic effect there pushes")
        if struck.slid_s > 0:
            evidence.append(
                f"slid along {name} for {struck.slid_s:.1f} s at its closest approach, held back against its "
                f"sliding by {struck.held_back:.2f} m/s^2 more than just outside it (beyond what the thrust, "
                "gravity and the drag seen away from it do): friction, as no aerodynamic effect acts along it only "
                "there")
        notes.append(
            f"{log.source}: the vehicle {'; and it '.join(evidence)} (the nearest rotor centre came within "
            f"{1e3 * struck.closest:.1f} mm of the plane). {in_contact.sum() * dt:.1f} s with a rotor centre "
            f"nearer than {1e3 * struck.touch_distance:.1f} mm (or held there) are left out as {reason}: the "
            f"{kind} pushes the vehicle there, a force that is not aerodynamic; {pull} nearer than that is not "
            f"determined by this flight ({reach_of} is about {1e3 * (struck.touch_distance - CONTACT_MARGIN):.0f} "
            "mm)")
        limits.append({
            "effects": [struck.effect],
            "reason": f"{log.source} touched {name}; the samples nearer it than "
                      f"{1e3 * struck.touch_distance:.0f} mm (rotor centre) are {reason}, left out, so {pull} "
                      "there is not measured",
            "manoeuvre": f"approach the {kind} slowly and turn back short of touching it, at several distances"})

    for struck in surface_strikes(log):
        declared_contact(struck, with_held(struck.in_contact), "away from it")
    bounces = ground_strikes(log, held)
    if bounces is not None:
        declared_contact(bounces, bounces.in_contact & ~held, "up, away from it, and flew on,")
    declared = np.logical_or.reduce([np.zeros(log.n_samples, dtype=bool), *by_reason.values()])
    excluded = held | declared
    for struck in undeclared_strikes(log, excluded):
        scene_surface = declared_surface(log, struck)
        if scene_surface is not None:  # strikes the test on the scene's plane missed: the scene has it
            off = float(np.degrees(np.arccos(np.clip(struck.normal @ scene_surface.normal, -1.0, 1.0))))
            declared_contact(scene_surface, with_held(scene_surface.in_contact & ~declared),
                             f"along {normal_text(struck.normal)} (world), {off:.0f} degrees off its normal (a "
                             "guard sliding along it pushes along it too),")
            continue
        in_contact = with_held(struck.in_contact & ~declared)
        reason = UNDECLARED_CONTACT
        by_reason[reason] = by_reason.get(reason, np.zeros(log.n_samples, dtype=bool)) | in_contact
        normal = normal_text(struck.normal)
        reach = struck.stopped_at
        place = (f"with the normal {normal}: the rotor centres stopped {reach:.3f} m along it, so the plane lies "
                 "there less the reach of the vehicle's guards")
        notes.append(
            f"{log.source}: the vehicle struck a surface the scene does not have {_listed_times(struck.times)}: "
            f"each time pushed along {normal} (world) more than {STRIKE_Z:g} times the log's own "
            f"scatter beyond what the thrust and gravity do, within {1e3 * STRIKE_WINDOW_S:g} ms, where its rotor "
            f"centres went farthest against that direction (within {1e3 * struck.give:.3g} mm of {reach:.3f} m "
            f"along it). {in_contact.sum() * dt:.1f} s there (or held there) are left out as {reason}, a force "
            f"that is not aerodynamic. If it is a wall or a ceiling, add it to the scene (sidecar or --scene) "
            f"{place}; its suction or ceiling effect can then be fitted too")
        facing_down = float(struck.normal[2]) < -0.5
        limits.append({
            "effects": ["ceiling_effect" if facing_down else "wall_suction"],
            "reason": f"{log.source} struck a surface the scene does not have, facing {normal}: its "
                      f"{'ceiling effect' if facing_down else 'suction'} is not fitted",
            "manoeuvre": f"add the surface to the scene (sidecar or --scene) {place}"})
    return by_reason


def _held_at_ceiling(log: FlightLog, samples: np.ndarray, hung_s: float, next_to_s: float) -> str:
    """The note for the samples ``log`` spent held at the ceiling (:func:`discovery.coverage.at_ceiling`)."""
    closest = float(rotor_clearances(log)[0][samples].min())
    where = (f"a rotor reached {1e3 * -closest:.3g} mm past the ceiling plane (scene.ceiling_z may be that much "
             "low, or the height estimate off)" if closest < 0 else
             f"the rotors came within {1e3 * closest:.3g} mm of the ceiling")
    beside = (f", with the {next_to_s:.1f} s next to it (the thrust below the weight, no more than "
              f"{100 * CONTACT_HEIGHT:.0f} cm below where it hung)" if next_to_s > 0 else "")
    return (f"{log.source}: {hung_s:.1f} s of {log.duration:.1f} s held at the ceiling: the thrust carries less "
            f"than {100 * REST_THRUST_SHARE:.0f} % of the weight and the vehicle does not fall; {where}. Drawn up "
            "by its own ceiling effect, it is in contact with the ceiling or nearer it than any image-rotor form "
            f"is trusted: left out{beside}")


def _listed_times(times: np.ndarray) -> str:
    """``"3 times (t = 1.00, 2.00, 3.00 s)"``, the first :data:`MAX_TIMES_LISTED` times and how many more."""
    at = ", ".join(f"{t:.2f}" for t in times[:MAX_TIMES_LISTED])
    more = f" and {len(times) - MAX_TIMES_LISTED} more" if len(times) > MAX_TIMES_LISTED else ""
    return f"{len(times)} times (t = {at}{more} s)"


def _intervals(t: np.ndarray, mask: np.ndarray) -> list[list[float]]:
    """The stretches of ``t`` where ``mask`` holds, as ``[from_s, to_s]``."""
    out: list[list[float]] = []
    changes = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    for a, b in zip(changes[::2], changes[1::2]):
        out.append([round(float(t[a]), 3), round(float(t[b - 1]), 3)])
    return out
