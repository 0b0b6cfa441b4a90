"""The discovery workflow as one estimator: ``Discovery().fit(logs)``, then inspect, ``predict`` and ``score``.

::

    from discovery import Discovery, read_log

    found = Discovery().fit([read_log("flight.csv")])
    found.effects_            # named effects with fitted parameters
    found.gap_before_, found.gap_after_
    found.model_.save("model.json")   # loads in the env (model=...) and in SC-MPC
    found.report()            # the JSON report as a dict
    found.predict(read_log("other.csv"))   # the model's aerodynamic force on another flight
    found.score(read_log("other.csv"))     # the share of the nominal model's force gap it explains there

One straight pipeline, each step in its own module:

1. **load** the logs (:mod:`discovery.flight_log`);
2. **segments**: leave out what is not aerodynamic, with the reason (:mod:`discovery.left_out`:
   held up by the ground or a hand, and the rotors spinning up or down on the ground,
   :mod:`discovery.coverage`; in contact with a wall or the ceiling the vehicle struck, pressed or
   slid along, :mod:`discovery.surface_contact`) and cut the logs into gap-free segments with their
   cross-validation folds (:mod:`discovery.residuals`);
3. **residuals**: the force residual of paper Eq. 28 at every sample against the nominal
   model (:mod:`discovery.residuals`), and a scene that cannot be right (a rotor behind a
   wall) corrected (a reversed wall normal) or kept away from the effects that depend on it;
4. **localise**: which candidate regressor the residual depends on, where it is large
   and in which direction (:mod:`discovery.regressors`);
5. **candidates**: the effects of the library (objects; their fuller forms, an affine thrust
   map, :mod:`discovery.thrust_map`, and a motor lag, :mod:`discovery.motor_lag`, beside them);
6. **fit** and 7. **select**: every candidate set fitted by least squares and ranked on
   held-out data, added greedily while it pays for itself (:mod:`discovery.selection`,
   :mod:`discovery.fitting`, one :class:`~discovery.layout.ParameterLayout` per set, each flight
   with its own wind); what the flight did not determine is nulled or left out and the rest
   **fitted again** (:mod:`discovery.determination`); effects that cancel each other are
   look-alikes and the simplest account is kept (:mod:`discovery.cancelling`); a wall that ends
   gets its suction fitted on its side of the edge (:mod:`discovery.wall_extent`); a ground or ceiling
   effect is fitted again without the samples nearer its surface than its form is trusted, and the set
   asked again there (:mod:`discovery.form_range`); a model whose held-out gap is not smaller than the
   nominal model's is never written;
8. **report**: the log's noise floor (:mod:`discovery.noise`) and what is left beyond it, with
   where it lives (:mod:`discovery.unexplained`), kept effects that only stood in for it dropped
   (:mod:`discovery.standins`), the model file (:class:`wall_env.model_file.FlightModel`), the
   held-out gaps before and after (``force_rms_N``, ``prediction_rms_m``), each flight held out
   in turn when several were fitted, plots (:mod:`discovery.plots`) and the JSON report
   (:mod:`discovery.report`).

All held-out figures use the same cross-validation folds: each time block is predicted
by parameters fitted without it. The model written is the model scored.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from discovery.cancelling import cancelling_sets, simpler
from discovery.cancelling import manoeuvre as cancel_manoeuvre
from discovery.coverage import (
    NEAR_SURFACE,
    far_surfaces,
    flight_limits,
    ground_contact,
    nearest_wall,
    scene_problems,
)
from discovery.determination import determining_manoeuvre, refit_determined
from discovery.fitting import Candidate, EffectFit
from discovery.flight_log import FlightLog
from discovery.flights import conditions, model_on, still_air
from discovery.form_range import fit_within_form
from discovery.left_out import leave_out_contact
from discovery.motor_lag import LAG_KEY, UNDETERMINED_LAG
from discovery.noise import BAND_HZ, TRANSIENT_RATIO
from discovery.prediction import DEFAULT_HORIZON_S, DEFAULT_STRIDE_S, prediction_pairs
from discovery.regressors import describe_force, localise_residual, piecewise_linear, regressors
from discovery.residuals import DEFAULT_BLOCK_S, DEFAULT_WINDOW_S, FlightData, prepare
from discovery.selection import (
    MIN_SHARE,
    MIN_WEIGHT_SHARE,
    Selection,
    effect_name,
    fit_only,
    floor_left_by,
    forward_selection,
    parameter_price,
    sequential_explained,
)
from discovery.standins import OWN_QUANTITIES, depends_on, own_quantity, structures_for, test_effect
from discovery.suction_bound import suction_bound
from discovery.thrust_map import ThrustMap, written_effects
from discovery.unexplained import is_unexplained, where_it_lives
from discovery.wall_extent import BoundedWall, find_edge, plain_wall, side_gains
from wall_env.effects import EFFECTS, Effect, make_effect
from wall_env.effects.constant_force import ConstantForce
from wall_env.effects.ground import FORM_TRUSTED_FROM_RADII
from wall_env.model_file import FlightModel

__all__ = ["Discovery", "DEFAULT_WINDOW_S", "DEFAULT_BLOCK_S"]

EDGE_STEPS_M = (0.04, 0.02, 0.01, 0.005)  # m, the steps of the search that places a wall's edge on held-out data
EDGE_MOVES = 3  # moves at each step at most


def _rms(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return float("nan")
    return float(np.sqrt(np.mean(np.sum(x.reshape(len(x), -1) ** 2, axis=1))))


def check_positive(name: str, value: float, unit: str, *, low: float, high: float) -> float:
    """``value`` as a float in ``[low, high]``, or a ValueError naming the parameter and the range."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number of {unit} in [{low:g}, {high:g}], got {value!r}") from None
    if not (math.isfinite(number) and low <= number <= high):
        raise ValueError(f"{name} must be in [{low:g}, {high:g}] {unit}, got {value!r}")
    return number


def minimum_duration(window_s: float, horizon_s: float) -> float:
    """Shortest log (s) discovery can work with: four smoothing windows, and two prediction horizons."""
    return max(4.0 * window_s, 2.0 * horizon_s)


def _candidate_templates(candidates: list | None, options: dict[str, dict[str, Any]]) -> list[Effect]:
    """The candidate effects as objects: names (with ``options``) or :class:`~wall_env.effects.Effect` instances."""
    items = list(EFFECTS) if candidates is None else list(candidates)
    out: list[Effect] = []
    for item in items:
        if isinstance(item, Effect):
            if item.name not in EFFECTS:
                raise ValueError(f"candidate {item!r} is not an effect of the library {sorted(EFFECTS)}")
            out.append(item)
        elif isinstance(item, str):
            if item not in EFFECTS:
                raise ValueError(f"unknown effect(s) {[item]}; the library has {sorted(EFFECTS)}")
            out.append(make_effect(item, **options.get(item, {})))
        else:
            raise ValueError(f"a candidate is an effect name or an Effect instance, got {item!r}")
    names = [e.name for e in out]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"each effect may be a candidate once; repeated: {repeated}")
    return out


class Discovery:
    """Find what the nominal model misses in flight logs, name it from the effects library and fit it.

    Parameters
    ----------
    candidates: the effects to consider, as names or :class:`~wall_env.effects.Effect` objects (whose
        options give the form tried first; default: the whole library).
    effect: fit only this effect, without selection (the paper's identification, Sec. 3.4).
    window_s: smoothing window of the differentiator and of the matched force kernel (s).
    block_s, n_folds: cross-validation time blocks (s) and folds.
    horizon_s, stride_s: open-loop prediction horizon and spacing of its start points (s).
    max_effects: at most this many effects are added.
    unexplained_threshold: share of the final held-out residual that regressor bin means
        must predict for it to be reported as ``unexplained``.
    options: effect options for candidates given by name, e.g. ``{"wall_suction": {"thrust_scaling": True}}``.
    motor_lag: look for a motor lag next to the chosen effects when the vehicle block gives no
        ``motor_time_constant`` (:mod:`discovery.motor_lag`); one found becomes the model's
        vehicle ``motor_time_constant`` and the effects are chosen again with it.
    progress: a callable receiving short status strings (e.g. ``print``), or None.
    """

    residual_before_: np.ndarray  # (n, 3) N, the nominal model's held-out force residual
    where_before_: dict  # where that residual is (discovery.regressors.localise_residual)
    _hold: dict[str, dict[int, float]]  # entries held at their null value, by candidate key
    limits_: list[dict]  # what the flight could not determine, each {"effects", "reason", "manoeuvre"}

    def __init__(self, candidates: list[str | Effect] | None = None, effect: str | None = None, *,
                 window_s: float = DEFAULT_WINDOW_S, block_s: float = DEFAULT_BLOCK_S, n_folds: int = 5,
                 horizon_s: float = DEFAULT_HORIZON_S, stride_s: float = DEFAULT_STRIDE_S, max_effects: int = 3,
                 unexplained_threshold: float = 0.15, options: dict[str, dict[str, Any]] | None = None,
                 motor_lag: bool = True, progress=None):
        check_positive("window_s", window_s, "s", low=0.02, high=10.0)
        check_positive("horizon_s", horizon_s, "s", low=0.02, high=10.0)
        check_positive("block_s", block_s, "s", low=0.1, high=1e4)
        check_positive("stride_s", stride_s, "s", low=0.001, high=10.0)
        if isinstance(n_folds, bool) or not isinstance(n_folds, (int, np.integer)) or not 2 <= n_folds <= 20:
            raise ValueError(f"n_folds must be an integer in [2, 20], got {n_folds!r}")
        if isinstance(max_effects, bool) or not isinstance(max_effects, (int, np.integer)) or max_effects < 0:
            raise ValueError(f"max_effects must be a non-negative integer, got {max_effects!r}")
        if effect is not None and effect not in EFFECTS:
            raise ValueError(f"unknown effect(s) {[effect]}; the library has {sorted(EFFECTS)}")
        self.options = dict(options or {})
        self._templates = _candidate_templates(candidates, self.options)
        self.candidates = [e.name for e in self._templates]
        self.effect = effect
        self.window_s = float(window_s)
        self.block_s = float(block_s)
        self.n_folds = int(n_folds)
        self.horizon_s = float(horizon_s)
        self.stride_s = float(stride_s)
        self.max_effects = int(max_effects)
        self.unexplained_threshold = float(unexplained_threshold)
        if not isinstance(motor_lag, bool):
            raise ValueError(f"motor_lag must be True or False, got {motor_lag!r}")
        self.motor_lag = motor_lag
        self.progress = progress

    # ------------------------------------------------------------------ fitting
    def _say(self, text: str) -> None:
        if self.progress is not None:
            self.progress(text)

    def _template(self, name: str) -> Effect:
        return next((e for e in self._templates if e.name == name), None) or make_effect(name, **self.options.get(name, {}))

    def fit(self, logs: list[FlightLog] | FlightLog) -> Discovery:
        """Run the pipeline on ``logs``; results land in the attributes ending in ``_``.

        BLAS runs on one thread meanwhile: the least-squares matrices have a few thousand rows
        and at most a dozen columns, so threads gain nothing, and on a busy machine their
        waiting made each small SVD 70 times slower (fitting a one-minute log took 6 s
        instead of 2 s at load 3 on two cores).
        """
        with threadpool_limits(limits=1, user_api="blas"):
            return self._fit(logs)

    def _fit(self, logs: list[FlightLog] | FlightLog) -> Discovery:
        started = time.perf_counter()
        # 1: load
        logs = self._checked(logs)
        self.logs_ = logs
        self.notes_: list[str] = []
        # 2: segments
        airborne = self._airborne(logs)
        self._say("preparing residuals")
        try:
            data = prepare(airborne, window_s=self.window_s, block_s=self.block_s, n_folds=self.n_folds)
        except ValueError:
            if airborne:
                raise
            shortest = minimum_duration(self.window_s, self.horizon_s)
            return self._nothing_to_fit(f"no airborne stretch of at least {shortest:.3g} s: nothing to fit", started)
        self.usable_ = True
        # 3: a scene that cannot be right
        data, airborne, excluded = self._checked_scene(data, airborne)
        # 4-7: localise, candidates, fit, select
        look_for_lag = self.motor_lag and self.effect is None and data.vehicle.motor_time_constant == 0
        r_nom, selection = self._choose(data, look_for_lag, excluded)
        # the user's nominal model, against which every "before" figure is given
        data_before, nominal_before = data, FlightModel(data.vehicle.to_vehicle_params(), [])
        residual_before, where_before = self.residual_before_, self.where_before_
        lag = selection.motor_lag
        if lag is not None and lag["kept"]:
            # not aerodynamic: the vehicle's own motor time constant; the effects are chosen again on the thrust
            # the lagging rotors produced
            tau = lag["time_constant_s"]
            self._say(f"the thrust lags the log by {1e3 * tau:.3g} ms: choosing the effects again with that lag")
            airborne = [replace(log, vehicle=replace(log.vehicle, motor_time_constant=tau)) for log in airborne]
            data = prepare(airborne, window_s=self.window_s, block_s=self.block_s, n_folds=self.n_folds)
            r_nom, selection = self._choose(data, False, excluded)
            selection.motor_lag = lag
            self.residual_before_, self.where_before_ = residual_before, where_before
        self.data_ = data
        self.notes_ += [p["message"] for p in self.scene_problems_ if not p.get("corrected")]
        self.selection_: Selection | None = selection
        self.limits_ += selection.form_limits
        self._lag_limits(lag)
        # what the flight determined, fitted again without the rest; never worse than the nominal model
        # measured on what the chosen effects leave: a brisk flight's forces reach into the noise's band
        self.noise_ = floor_left_by(data, selection.chosen)
        if self.noise_["filtered"]:
            self.notes_.append(
                f"the residual's noise falls with frequency: at the top of the band above {BAND_HZ:g} Hz it has "
                f"{100 * self.noise_['band_top_share']:.0f} % of the power that white and differenced-white noise "
                "fitted there predict; the log's states look filtered (an estimator's output), whose own errors below "
                f"{BAND_HZ:g} Hz the noise floor cannot see: the floor ({self.noise_['floor_N']:.4f} N) is a lower bound, "
                "and 'times the noise floor' may overstate what is left")
        if self.noise_.get("transient_share", 0.0) > 0:
            self.notes_.append(
                f"{100 * self.noise_['transient_share']:.0f} % of the log's spectrum segments held a transient "
                f"the model does not describe (more than {TRANSIENT_RATIO:g} times the typical segment's power above "
                f"{BAND_HZ:g} Hz: a strike, a guard grazing a surface) and were left out of the noise floor")
        self.stand_ins_: list[dict] = []
        self.withheld_: dict[str, Any] | None = None
        self.form_range_: dict[str, Any] | None = None
        final, self._hold, self.undetermined_ = refit_determined(selection.fitter, selection.chosen, self._say)
        final, selection = self._chosen_without_bounded(data, r_nom, excluded, final, selection)
        self.selection_ = selection
        final = self._cancelling(data, final, selection)
        final = self._never_worse(data, r_nom, self._wall_edge(data, r_nom, final, selection, excluded), selection)
        self._finish(data, r_nom, final, selection)
        # a kept effect that only stands in for a structure the library cannot describe is not written as physics;
        # asked when something is left, or when a quantity no kept effect depends on describes the nominal gap as
        # well as they do: otherwise an effect that leaves nothing but noise is the simpler account of its residual
        # than any shape-free description (on a sinusoidal flight a thrust scale's force is also a function of the
        # position)
        if final.names and (self.unexplained_ is not None or self._rival_quantity() is not None):
            kept = self._without_stand_ins(data, r_nom, final, selection)
            final = self._never_worse(data, r_nom, kept, selection)
            if final is not kept:
                self._finish(data, r_nom, final, selection)
        final = self._within_form(data, r_nom, final, selection)
        # a parameter nulled in the model file is said of the effects written; what was left out is said of any
        written = {e.name for e in final.fit.effects}
        self.undetermined_ = [c for c in self.undetermined_
                              if c["effect"] in written or c["action"].startswith("effect left out")]
        self.notes_ += self.written_notes_
        self._wind_limit(data, final)
        self._suction_bound(selection, excluded)
        # the proof against the user's nominal model
        self._say("open-loop predictions")
        vehicle = data.vehicle.to_vehicle_params()
        self.prediction_before_ = prediction_pairs(data_before, nominal_before.aero_model(), None, self.horizon_s,
                                                   self.stride_s)
        self.prediction_after_ = self._predictions(data, final, vehicle)
        self.prediction_errors_before_ = np.linalg.norm(self.prediction_before_[1] - self.prediction_before_[2], axis=1)
        self.prediction_errors_after_ = np.linalg.norm(self.prediction_after_[1] - self.prediction_after_[2], axis=1)
        self.gap_before_ = {"force_rms_N": _rms(self.residual_before_),
                            "prediction_rms_m": _rms(self.prediction_errors_before_)}
        self.gap_after_ = {"force_rms_N": _rms(self.residual_after_),
                           "prediction_rms_m": _rms(self.prediction_errors_after_)}
        self.runtime_s_ = time.perf_counter() - started
        return self

    def _chosen_without_bounded(self, data: FlightData, r_nom: list[np.ndarray], excluded: set[str],
                                final: Candidate, selection: Selection) -> tuple[Candidate, Selection]:
        """The effects chosen again without those left out because a parameter ran to a bound of its range.

        Such an effect did something no value of it inside its range does, and it took the place of what the
        selection would otherwise have chosen: hovering slowly under a ceiling, the thrust is nearly a function of
        the distance to it, and an affine thrust map of scale 0.30 (its bound) scored like the ceiling effect; left
        out, it left nothing, and the ceiling effect alone explained 94 % of the held-out gap. The second choice is
        kept when its held-out score is better than that of what the first left, and it leaves only noise.
        """
        bounded = sorted({c["effect"] for c in self.undetermined_
                          if c["action"].startswith("effect left out") and "reaches a bound" in c["reason"]})
        if not bounded or self.effect is not None or selection.fitter is None:
            return final, selection
        self._say(f"choosing the effects again without {', '.join(bounded)}, left out at a bound of its range")
        templates = [t for t in self._candidates(excluded) if t.name not in bounded]
        again = forward_selection(data, r_nom, templates, self.max_effects, progress=self._say, look_for_lag=False)
        chosen, hold, cases = refit_determined(again.fitter, again.chosen, self._say)
        if not chosen.names or chosen.score >= final.score or chosen.problem is None:
            return final, selection
        # kept only as a whole account (what it leaves is within noise): a second choice that leaves a structure
        # is one more stand-in for it (a quadratic drag in a 6 m/s wind for a force growing with height)
        left = data.concat(chosen.problem.out_of_fold(chosen.fit.fold_theta, r_nom))
        if is_unexplained(_rms(left), self.noise_, data.weight, MIN_WEIGHT_SHARE):
            return final, selection
        again.motor_lag = selection.motor_lag
        self.limits_ += [limit for limit in again.form_limits if limit not in self.limits_]
        self._hold = hold
        self.undetermined_ = [c for c in self.undetermined_ if c["effect"] in bounded] + cases
        self.notes_.append(f"{', '.join(bounded)} ran to a bound of its range and was left out; chosen again "
                           f"without it: {', '.join(e.name for e in chosen.fit.effects)}")
        return chosen, again

    def _never_worse(self, data: FlightData, r_nom: list[np.ndarray], final: Candidate,
                     selection: Selection) -> Candidate:
        """``final``, or the nominal model when ``final``'s held-out force gap is not smaller than the nominal's."""
        residual_after = data.concat(final.problem.out_of_fold(final.fit.fold_theta, r_nom)) if final.problem \
            else data.concat(r_nom)
        if not final.names or _rms(residual_after) < _rms(self.residual_before_) or selection.fitter is None:
            return final
        self.withheld_ = {"effects": [e.name for e in final.fit.effects], "force_rms_N": _rms(residual_after),
                          "nominal_force_rms_N": _rms(self.residual_before_)}
        self.notes_.append(
            f"not written: the model with {', '.join(self.withheld_['effects'])} leaves a held-out force gap of "
            f"{self.withheld_['force_rms_N']:.4g} N, not smaller than the nominal model's "
            f"{self.withheld_['nominal_force_rms_N']:.4g} N; the model file is the nominal model")
        lag = selection.motor_lag
        if lag is not None and lag["kept"]:
            selection.motor_lag = dict(lag, kept=False, reason="the model with it is not better than the nominal model")
        return selection.fitter.candidate([])

    def _cancelling(self, data: FlightData, final: Candidate, selection: Selection) -> Candidate:
        """Kept effects whose forces cancel are look-alikes (:mod:`discovery.cancelling`): reported with the
        manoeuvre that separates them, and the simplest account the held-out score cannot tell from them kept."""
        self.cancelling_: list[dict] = []
        fitter = selection.fitter
        if fitter is None or final.problem is None or len(final.names) < 2:
            return final
        forces = [data.concat(per_segment) for per_segment in final.problem.forces(final.fit.theta)]
        sets = cancelling_sets([e.name for e in final.fit.effects], forces, MIN_WEIGHT_SHARE * data.weight)
        for found in sets[:1]:
            chosen, label = simpler(fitter, final, found, parameter_price(data.effective_samples()), self._hold)
            record = {"effects": found["effects"], "force_rms_N": found["force_rms_N"], "sum_rms_N": found["sum_rms_N"],
                      "kept": label, "manoeuvre": cancel_manoeuvre(found["effects"])}
            self.cancelling_.append(record)
            self.limits_.append({"effects": found["effects"],
                                 "reason": f"{', '.join(found['effects'])} cancel each other in this flight (each "
                                           f"{min(found['force_rms_N']):.3g} N rms or more, together "
                                           f"{found['sum_rms_N']:.3g} N): the flight cannot tell them apart; "
                                           f"kept: {label}, the simplest account within one parameter's price of "
                                           "the best held-out score",
                                 "manoeuvre": record["manoeuvre"]})
            if chosen is not final:
                self._say(f"effects that cancel: kept {label}")
                final = chosen
        return final

    def _wind_limit(self, data: FlightData, final: Candidate) -> None:
        """Drag in a wind from one flight: when the wind is fast against the flight's own speed, the drag is nearly
        ``C w^2 + 2 C w v`` and a coefficient and a wind speed trade off; flights at several winds tell them apart."""
        effect = next((e for e in final.fit.effects if e.name == "quadratic_drag" and "w" in e.values), None)
        if effect is None or data.n_flights > 1:
            return
        wind = float(np.linalg.norm(effect.values["w"]))
        speed = float(np.sqrt(np.mean(np.sum(data.concat([seg.states.v_world for seg in data.segments]) ** 2, axis=1))))
        if wind > 2.0 * speed:
            self.limits_.append({
                "effects": ["quadratic_drag"],
                "reason": f"the wind ({wind:.3g} m/s) is fast against the flight's own speed ({speed:.2g} m/s rms): "
                          "the drag is then nearly C w^2 along the wind, and from one flight a drag coefficient and a "
                          "wind speed trade off (only C w^2 is well determined)",
                "manoeuvre": "fly the same vehicle at several wind speeds (or in still air too) and give all the logs "
                             "to one discover: the drag coefficient is shared, each flight has its own wind"})

    def _wall_edge(self, data: FlightData, r_nom: list[np.ndarray], final: Candidate,
                   selection: Selection, excluded: set[str]) -> Candidate:
        """Wall suction fitted again on the wall's side of an edge, when the data show one and it scores better by
        more than a parameter's price (:mod:`discovery.wall_extent`). The edge is looked for again with the
        suction fitted on its side, until it stays within a centimetre."""
        self.wall_edge_: dict | None = None
        fitter = selection.fitter
        if fitter is None:
            return final
        base, index = final, next((i for i, e in enumerate(final.fit.effects) if e.name == "wall_suction"), None)
        if index is None:
            # a suction the selection left out may have lost only because the plane it acts on is too big: across a
            # wall that ends 1.2 m up, on a flight above the top half the time, the plane's held-out gap was 8 times
            # the nominal model's; fitted on the wall's side of the edge the data show, it took 80 % of the gap
            nearest = nearest_wall(self.regressors_)
            if "wall_suction" not in fitter.templates or "wall_suction" in excluded or nearest is None \
                    or nearest > NEAR_SURFACE:
                return final
            final = fitter.candidate(base.names + ["wall_suction"], previous=base.previous(), hold=self._hold)
            index = len(final.names) - 1
        key = final.names[index]
        options = {k: v for k, v in fitter.templates[key].option_values.items()
                   if k not in ("axis", "side", "edge_m")}
        current, edge = final, None
        for _ in range(3):
            found = find_edge(data, *self._suctions(data, r_nom, fitter, current, index))
            if found is None or (edge is not None and (found["axis"], found["side"]) != (edge["axis"], edge["side"])):
                break
            if edge is not None and abs(found["edge_m"] - edge["edge_m"]) < 0.01:
                break
            edge = found
            current, self._hold = self._bounded_wall(fitter, current, index, options, edge, self._hold)
        if edge is None or current is final:
            return base
        # the edge search compares smoothed forces with a step in height, and on a brisk climb across the edge the
        # smoothing carries suction above it (edges 5-9 cm high on faster flights of the second simulator); the bounded
        # wall's own term smooths its force as the data are, so its held-out score places the edge, searched around
        # the first estimate. The form was chosen on the whole plane, where a thrust-scaled suction can fit the
        # missing wall better (it was chosen on those flights, whose suction does not scale, and k_s came out 11-15 %
        # low): at the placed edge the plain form is scored again, the option priced as a parameter
        current, edge = self._placed_edge(fitter, current, index, options, edge)
        if options.get("thrust_scaling"):
            plain_options = {**options, "thrust_scaling": False}
            plain, plain_hold = self._bounded_wall(fitter, current, index, plain_options, edge, self._hold, say=False)
            if plain.score < current.score:
                current, self._hold, options = plain, plain_hold, plain_options
                current, edge = self._placed_edge(fitter, current, index, options, edge)
        placed = fitter.templates[current.names[index]]
        assert isinstance(placed, BoundedWall)
        self._say(f"wall suction on one side of an edge: {placed.describe()}")
        # the share of the suction the data show on each side, at the edge placed and the parameters fitted there
        edge = {**edge, **side_gains(data, *self._suctions(data, r_nom, fitter, current, index), edge)}
        if current.score >= base.score - parameter_price(data.effective_samples()):
            self._hold = {(key if effect_name(k) == "wall_suction" else k): v for k, v in self._hold.items()}
            return base
        if base is not final:  # the suction the selection left out, now kept: its share of the held-out energy
            nominal = selection.nominal.mse
            selection.explained["wall_suction"] = (base.mse - current.mse) / nominal if nominal > 0 else 0.0
        self.wall_edge_ = {**edge, "description": placed.describe()}
        self.notes_.append(
            f"wall 0 seems to end: where the fitted wall suction acts, the data show {100 * edge['gain_outside']:.0f} % "
            f"of it beyond the edge and {100 * edge['gain_inside']:.0f} % on the wall's side; {placed.describe()}. "
            "Wall suction was fitted on the wall's side only (the held-out score is better by more than a parameter's "
            "price); the model file's wall_suction acts on the whole plane the scene gives: limit the wall in your "
            "simulation to where it is")
        return current

    @staticmethod
    def _suctions(data: FlightData, r_nom: list[np.ndarray], fitter, current: Candidate, index: int
                  ) -> tuple[np.ndarray, np.ndarray]:
        """The suction of the whole plane at ``current``'s parameters of its wall (entry ``index``), and what the data
        show of it (the nominal residual less the other effects' forces), both smoothed, all segments ``(N, 3)``."""
        assert current.problem is not None
        forces = current.problem.forces(current.fit.theta)
        others = sum((data.concat(per_segment) for i, per_segment in enumerate(forces) if i != index),
                     np.zeros((data.n_samples, 3)))
        wall = plain_wall(current.fit.effects[index])
        plane = EffectFit(data, [wall], r_nom, fitter.terms, ["plane"])
        return data.concat(plane.forces(wall.param_vector())[0]), data.concat(r_nom) - others

    def _placed_edge(self, fitter, current: Candidate, index: int, options: dict, edge: dict
                     ) -> tuple[Candidate, dict]:
        """The bounded wall of ``current`` with its edge moved to where the held-out score is best: steps of
        :data:`EDGE_STEPS_M`, at most :data:`EDGE_MOVES` moves each."""
        for step in EDGE_STEPS_M:
            for _ in range(EDGE_MOVES):
                tried = [(current, self._hold, edge)]
                for shift in (-step, step):
                    moved = {**edge, "edge_m": edge["edge_m"] + shift}
                    tried.append((*self._bounded_wall(fitter, current, index, options, moved, self._hold, say=False),
                                  moved))
                best = min(tried, key=lambda t: t[0].mse)
                if best[0] is current:
                    break
                current, self._hold, edge = best
        return current, edge

    def _bounded_wall(self, fitter, current: Candidate, index: int, options: dict, edge: dict,
                      hold: dict[str, dict[int, float]], say: bool = True) -> tuple[Candidate, dict[str, dict[int, float]]]:
        """``current`` with its wall suction (entry ``index``) acting on the wall's side of ``edge`` only, fitted,
        and the entries held, keyed for it."""
        template = BoundedWall(**options, axis=edge["axis"], side=edge["side"], edge_m=float(edge["edge_m"]))
        key = current.names[index]
        form = " thrust_scaling" if options.get("thrust_scaling") else ""
        bounded_key = f"{effect_name(key)}[edge {edge['axis']} {edge['side']} {edge['edge_m']:.4f}{form}]"
        fitter.add(bounded_key, template)
        keys = [bounded_key if k == key else k for k in current.names]
        rename = {key: bounded_key}
        if say:
            self._say(f"wall suction on one side of an edge: {template.describe()}")
        hold = {rename.get(k, k): v for k, v in hold.items()}
        previous = {rename.get(k, k): v for k, v in current.previous().items()}
        return fitter.candidate(keys, previous=previous, hold=hold), hold

    def _finish(self, data: FlightData, r_nom: list[np.ndarray], final: Candidate, selection: Selection) -> None:
        """The final model's held-out residual, model file, each effect's force and where it acts, and what is
        left beyond the noise."""
        self.final_: Candidate | None = final
        self.motor_lag_ = selection.motor_lag
        explained = selection.explained
        if selection.fitter is not None and final.names and list(final.names) != list(selection.chosen.names):
            # the set written is not the one selection chose (refitted without what the flight did not determine,
            # without stand-ins): each share is that of the set written, not of the effects it was chosen beside
            explained = sequential_explained(selection.fitter, final, selection.nominal, self._hold)
        self.explained_fraction_ = {e.name: explained.get(e.name, 0.0) for e in final.fit.effects}
        self.residual_after_ = data.concat(final.problem.out_of_fold(final.fit.fold_theta, r_nom)) \
            if final.problem and final.names else data.concat(r_nom)
        vehicle = data.vehicle.to_vehicle_params()
        fitted = list(final.fit.effects)
        # with several flights, each flight's wind is its own condition (flights_): the effects are for still air
        self.effects_ = still_air(fitted, data.n_flights)
        self.param_std_ = final.fit.std_dicts()
        if data.n_flights > 1:
            self.param_std_ = [{k: ([float("nan")] * len(v) if k == "w" and isinstance(v, list) else v)
                                for k, v in std.items()} for std in self.param_std_]
        lag = selection.motor_lag
        # entries whose standard error is the one fitted beside a found lag: what widens them is the lag
        self.widened_by_lag_: set[tuple[str, str]] = set()
        if lag is not None and lag["kept"]:
            widened = [_with_lag_uncertainty(e, std, lag["effect_std"]) for e, std in zip(fitted, self.param_std_)]
            self.param_std_ = [std for std, _ in widened]
            self.widened_by_lag_ = {(e.name, label) for e, (_, labels) in zip(fitted, widened) for label in labels}
        within = self.form_range_ or {}
        for name, shift in (within.get("leakage_shift") or {}).items():
            # the parameters as fitted within the form (not another set finished after it): their leak counts
            self.param_std_ = [_with_shift(std, shift) if e.name == name and
                               e.params_dict() == within["within_form"].get(name) else std
                               for e, std in zip(fitted, self.param_std_)]
        written, self.written_notes_ = written_effects([plain_wall(e) for e in self.effects_])
        self.model_ = FlightModel(vehicle, written, _written_std(written, fitted, self.param_std_),
                                  data.vehicle.vehicle_fields(motor_lag_found=bool(lag and lag["kept"])))
        self.flights_ = conditions(data, final)
        self.effect_forces_ = {}
        self.where_ = {}
        if final.problem is not None and final.names:
            for effect, per_segment in zip(fitted, final.problem.forces(final.fit.theta)):
                force = data.concat(per_segment)
                self.effect_forces_[effect.name] = force
                self.where_[effect.name] = describe_force(data, force, self.regressors_)
        self.unexplained_ = self._unexplained(data)

    def _without_stand_ins(self, data: FlightData, r_nom: list[np.ndarray], final: Candidate,
                           selection: Selection) -> Candidate:
        """Drop the kept effects that only stand in for a structure the library cannot describe
        (:mod:`discovery.standins`), fit the rest again and finish with them; one that acts partly as a proxy
        becomes a limit.

        Each kept effect is taken out in turn: where the residual then lives (:mod:`discovery.unexplained`) is
        what the effect was explaining. When that is not the effect's own quantity (a thrust scale explaining a
        residual that depends on height), the effect is fitted again next to a shape-free description of it."""
        fitter = selection.fitter
        if fitter is None:
            return final
        changed = False
        for _ in range(3):  # what is left after dropping stand-ins (or an effect they leave undetermined) is asked again
            found: list[dict] = []
            for i, key in enumerate(final.names):
                others = [k for k in final.names if k != key]
                without = fitter.candidate(others, previous=final.previous(),
                                           hold={k: v for k, v in self._hold.items() if k in others})
                residual = data.concat(without.problem.out_of_fold(without.fit.fold_theta, r_nom)) \
                    if without.problem is not None and others else data.concat(r_nom)
                if not is_unexplained(_rms(residual), self.noise_, data.weight, MIN_WEIGHT_SHARE):
                    continue
                where = where_it_lives(data, residual, self.regressors_, self.noise_, self.unexplained_threshold)
                if own_quantity(final.fit.effects[i], where):
                    continue
                steady = any(e.name == ConstantForce.name for j, e in enumerate(final.fit.effects) if j != i)
                structures = structures_for(data, where, self.regressors_, final.fit.effects[i].name, steady,
                                            residual)
                if not structures:
                    continue
                self._say(f"asking whether {key} only stands in for a residual that {where['lives_in']} describes")
                standin, proxies = test_effect(fitter, final, i, structures, where,
                                               parameter_price(data.effective_samples()), self._hold)
                if standin is not None:
                    found.append(standin)
                for proxy in proxies:
                    self.limits_.append({
                        "effects": [proxy["effect"]],
                        "reason": f"{proxy['effect']} {proxy['parameter']} acts partly as a proxy: without it the "
                                  f"residual {proxy['lives_in']}, and with that described apart it would be "
                                  f"{proxy['with']:.4g} instead of {proxy['without']:.4g} (+- {proxy['std']:.2g})",
                        "manoeuvre": "fly where that residual does not, or vary that quantity independently of the "
                                     "others", "proxy": proxy["parameter"]})
            if not found:
                break
            changed = True
            dropped = {s["key"] for s in found}
            keys = [k for k in final.names if k not in dropped]
            # fitted afresh: an entry held only because a stand-in stood beside it is free again
            rest, rest_hold, undetermined = self._refit_kept(fitter, keys, final.previous(), inherited=False)
            left_out = [k for k in keys if k not in rest.names]
            if left_out:
                # the rest fitted without the stand-ins leaves the flight undetermined (a thrust map pinned at its
                # lowest scale once the ceiling effect beside it is gone): the stand-ins were judged against an
                # effect that is not written, so that effect goes and they are judged again without it
                self._say(f"once {', '.join(sorted(dropped))} go, {', '.join(left_out)} is undetermined: left out, "
                          "and the rest asked again")
                self.undetermined_ += [c for c in undetermined if c["action"].startswith("effect left out")]
                self._drop_proxy_limits({fitter.templates[k].name for k in left_out})
                final, self._hold, again = self._refit_kept(fitter, [k for k in final.names if k not in left_out],
                                                            final.previous())
                self.undetermined_ += again
            else:
                self.stand_ins_ += found
                self._say(f"not written as physics (stand-ins): {', '.join(sorted(dropped))}")
                final, self._hold = rest, rest_hold
                kept = {fitter.templates[k].name for k in keys}  # their entries were asked again
                self.undetermined_ = [c for c in self.undetermined_ if c["effect"] not in kept] + undetermined
            if not final.names:
                break
        if changed:
            self._finish(data, r_nom, final, selection)
        return final

    def _within_form(self, data: FlightData, r_nom: list[np.ndarray], final: Candidate,
                     selection: Selection) -> Candidate:
        """``final`` with its ground or ceiling effect fitted where the image-rotor form is trusted
        (:mod:`discovery.form_range`), finished again when that changed it; the report says what was set aside."""
        if selection.fitter is None:
            return final
        within, hold, self.form_range_ = fit_within_form(selection.fitter, final, self._hold, data, self.regressors_,
                                                         selection.n_eff, self._say)
        summary = self.form_range_
        if summary is None:
            return final
        names, surfaces = ", ".join(summary["effects"]), " or ".join(summary["surfaces"])
        closest_m = summary["closest_m"]
        closest = "" if closest_m is None else (f" (the closest {1e3 * closest_m:.3g} mm)" if closest_m >= 0 else
                                                 f" (one reached {-1e3 * closest_m:.3g} mm past its plane)")
        aside = (f"{100 * summary['share_set_aside']:.0f} % of the samples ({summary['seconds_set_aside']:.1f} s) had "
                 f"a rotor within {FORM_TRUSTED_FROM_RADII:g} effective radius of {surfaces}{closest}, where how the "
                 "gain levels off is the form's guess")
        on_all = "; ".join(f"{name} {_params_text(params)}" for name, params in summary["on_all"].items())
        if summary.get("added"):
            # what was said of it when it was left out no longer holds: it is written
            self.undetermined_ = [c for c in self.undetermined_ if c["effect"] != summary["added"]]
            self.notes_.append(f"{summary['added']} added where its form is trusted: fitted there it is determined and "
                               f"scores better than the model without it; on every sample it had been left out")
        if summary["applied"]:
            self.notes_.append(f"{names} fitted without the samples nearer {surfaces} than its form is trusted: "
                               f"{aside}; fitted on them too it would be {on_all}")
            misfit = summary.get("set_aside_misfit") or {}
            if misfit.get("forms_kept"):
                forms = ", ".join(k for k in final.names if effect_name(k) in summary["effects"])
                self.notes_.append(f"fitted on every sample, {forms} predicts the samples set aside about as well as "
                                   f"the rest (their vertical mean square {misfit['ratio']:.2f} times, sampling "
                                   f"allows {misfit['limit']:.2f}): the gain levels off there as the form says, so "
                                   "its form stays as chosen on every sample")
            own = {e.name: std for e, std in zip(within.fit.effects, within.fit.std_dicts())}
            for name, shift in (summary.get("leakage_shift") or {}).items():
                if not any(abs(float(v)) > float(own.get(name, {}).get(k, np.inf)) for k, v in shift.items()):
                    continue  # within the fit's own standard errors: said only where it widens them by sqrt 2
                moved = ", ".join(f"{k} by {float(v):+.2g} m" for k, v in shift.items())
                self.notes_.append(f"{name}'s parameters move ({moved}) when what the form leaves nearer than that "
                                   "is taken out of the rows fitted on, whose force is smoothed over samples that "
                                   "near too; their standard errors count that shift")
        else:
            resting = [f"{name} {key}" for name, params in summary["on_all"].items() for key in params]
            verb = "rests" if len(resting) == 1 else "rest"
            self.limits_.append({"effects": summary["effects"],
                                 "reason": f"{aside}; {summary['reason']}, and {' and '.join(resting)} {verb} on "
                                           "that guess",
                                 "manoeuvre": f"fly at several distances beyond one effective radius of {surfaces} "
                                              "(about 0.1 m to 0.5 m)"})
        for change in summary["changed"]:
            gone = [k for k in change["from"] if k not in change["to"]]
            if not gone:  # an effect only added is said above
                continue
            came = {effect_name(k): k for k in change["to"] if k not in change["from"]}
            said = [f"{k} in the form {came[effect_name(k)]}" if effect_name(k) in came else f"without {k}"
                    for k in gone]
            if change.get("immaterial"):
                self.notes_.append(f"within the range the form is trusted, {', '.join(gone)} explains less than "
                                   f"{100 * MIN_SHARE:g} % of the force gap or {100 * MIN_WEIGHT_SHARE:g} % of the "
                                   "weight: it only paid for itself on the samples set aside, and is left out")
                continue
            self.notes_.append(f"within the range the form is trusted, the model {' and '.join(said)} scores better: "
                               f"{', '.join(gone)} only paid for itself on the samples set aside")
        if within is final:
            return final
        self._hold = hold
        self._drop_proxy_limits({e.name for e in final.fit.effects} - {e.name for e in within.fit.effects})
        final = self._never_worse(data, r_nom, within, selection)
        self._finish(data, r_nom, final, selection)
        return final

    def _drop_proxy_limits(self, gone: set[str]) -> None:
        """What was said of the parameters of effects no longer in the model (``gone``, effect names) as proxies."""
        self.limits_ = [x for x in self.limits_ if not ("proxy" in x and set(x["effects"]) <= gone)]

    def _refit_kept(self, fitter, keys: list[str], previous: dict[str, np.ndarray], inherited: bool = True
                    ) -> tuple[Candidate, dict[str, dict[int, float]], list]:
        """``keys`` fitted again with the entries they had held (none unless ``inherited``), and what the flight does
        not determine among them left out (:func:`~discovery.determination.refit_determined`)."""
        hold = {k: v for k, v in self._hold.items() if k in keys} if inherited else {}
        return refit_determined(fitter, fitter.candidate(keys, previous=previous, hold=hold), self._say, hold)

    def _rival_quantity(self) -> dict | None:
        """The quantity no kept effect's form depends on whose shape-free map explains the nominal held-out gap
        best, when it leaves no more than the kept effects do (``{"regressor", "explained_fraction"}``); None
        otherwise, or when every kept effect is steady (a steady force is a function of any quantity).

        The kept effects may then stand in for a force of that quantity: climbing slowly and evenly, the thrust
        follows the height, and an affine thrust map with a vertical steady force left only noise of a force
        growing with height, which the map of the height explained a little better still."""
        varying = [e.name for e in self.effects_ if e.name in OWN_QUANTITIES]
        if not varying:
            return None
        before, after = _rms(self.residual_before_), _rms(self.residual_after_)
        for entry in self.where_before_.get("all_explained", []):
            name = entry["regressor"] or ""
            if name in ("everywhere", "time") or any(depends_on(e, name) for e in varying):
                continue
            return entry if before * math.sqrt(max(1.0 - entry["explained_fraction"], 0.0)) <= after else None
        return None

    def _unexplained(self, data: FlightData) -> dict | None:
        """What the final model leaves that is more than noise, and where it lives (:mod:`discovery.unexplained`)."""
        left = localise_residual(data, self.residual_after_, self.regressors_)
        self.where_after_ = left
        after = _rms(self.residual_after_)
        localised = left["regressor"] is not None and left["explained_fraction"] >= self.unexplained_threshold \
            and left.get("range") is not None
        above = is_unexplained(after, self.noise_, data.weight, MIN_WEIGHT_SHARE)
        if not (above or localised):
            return None
        where = where_it_lives(data, self.residual_after_, self.regressors_, self.noise_, self.unexplained_threshold)
        self._where_left = where
        floor = self.noise_["floor_N"]
        excess = math.sqrt(max(after**2 - floor**2, 0.0)) if math.isfinite(floor) else after
        states = where["states"] if where["states"].get("regressor") not in (None, "everywhere") else left
        return {"force_rms_N": after, "noise_floor_N": floor,
                "times_noise_floor": after / floor if floor and math.isfinite(floor) else None,
                "excess_rms_N": excess, "share_of_weight": excess / data.weight, "lives_in": where["lives_in"],
                "where": _public_where(states),
                "shape": self._shape(states) if where["lives_in"] == "states" or localised else None,
                "position": {k: v for k, v in where["position"].items() if k != "cells"},
                "position_cells": where["position"]["cells"], "time": where["time"], "level_N": where["level_N"],
                "direction_world": where["direction_world"]}

    # ------------------------------------------------------------------ the steps
    def _checked(self, logs: list[FlightLog] | FlightLog) -> list[FlightLog]:
        """Step 1: the logs as a list, each long enough for the smoothing window and the prediction horizon."""
        logs = [logs] if isinstance(logs, FlightLog) else list(logs)
        if not logs:
            raise ValueError("discovery needs at least one flight log")
        shortest = minimum_duration(self.window_s, self.horizon_s)
        for log in logs:
            if log.duration < shortest:
                raise ValueError(
                    f"{log.source}: the log lasts {log.duration:.3g} s ({log.n_samples} samples); discovery needs "
                    f"at least {shortest:.3g} s (4 smoothing windows of window_s = {self.window_s:g} s and 2 "
                    f"prediction horizons of horizon_s = {self.horizon_s:g} s): record a longer flight or lower "
                    "window_s / horizon_s (--window, --horizon)")
        return logs

    def _airborne(self, logs: list[FlightLog]) -> list[FlightLog]:
        """Step 2: each log without the samples something other than the thrust held up or pushed
        (:func:`discovery.left_out.leave_out_contact`), with a note for each."""
        found = leave_out_contact(logs, minimum_duration(self.window_s, self.horizon_s))
        self.left_out_: list[dict] = found.records
        self._contact_limits: list[dict] = found.limits
        self.notes_ += found.notes
        return found.logs

    def _checked_scene(self, data: FlightData, airborne: list[FlightLog]
                       ) -> tuple[FlightData, list[FlightLog], set[str]]:
        """Step 3: rotors behind a wall, under the ground or above the ceiling mean the scene is wrong.

        A wall whose normal points into it (most of the flight behind it) is turned round and the logs
        prepared again, so the wall's effects are fitted on the corrected geometry; for any other
        impossible surface, the effects that act against it are not fitted at all. The report says which."""
        problems = scene_problems(regressors(data), data.times)
        flipped = sorted({p["wall"] for p in problems if p["reversed"]})
        corrected = []
        if flipped:
            fixed = []
            for log in airborne:
                walls = tuple(replace(w, normal=(-w.normal[0], -w.normal[1], -w.normal[2])) if k in flipped else w
                              for k, w in enumerate(log.scene.walls))
                fixed.append(replace(log, scene=replace(log.scene, walls=walls)))
            airborne = fixed
            data = prepare(airborne, window_s=self.window_s, block_s=self.block_s, n_folds=self.n_folds)
            for p in problems:
                if p["reversed"]:
                    corrected.append({**p, "corrected": True})
                    self.notes_.append(p["message"] + "; discovery fitted the wall's effects with that normal "
                                       "flipped (the scene the flight shows); correct the sidecar")
            problems = scene_problems(regressors(data), data.times)
        excluded = {e for p in problems if not p.get("corrected") for e in p["effects"]}
        for effect in sorted(excluded):
            self.notes_.append(f"{effect} not fitted: it acts against a surface the scene has wrong (see the "
                               "sidecar warning), and fitted on that geometry it would describe the error")
        self.scene_problems_ = corrected + problems
        return data, airborne, excluded

    def _candidates(self, excluded: set[str]) -> list[Effect]:
        """The candidate effects: the templates less those ``excluded`` (on a wrong scene) and the ground or ceiling
        effect of a surface the flight never came near (:func:`~discovery.coverage.far_surfaces`), which it cannot
        determine."""
        far = far_surfaces(self.regressors_)
        return [t for t in self._templates if t.name not in excluded and t.name not in far]

    def _choose(self, data: FlightData, look_for_lag: bool, excluded: set[str] = frozenset()  # type: ignore[assignment]
                ) -> tuple[list[np.ndarray], Selection]:
        """Steps 4-7 on prepared data: the nominal residual, where it is, and what explains it."""
        nominal = FlightModel(data.vehicle.to_vehicle_params(), [])
        r_nom = data.residuals(nominal.aero_model())
        self.regressors_ = regressors(data)
        self.limits_ = flight_limits(self.regressors_, data.concat([seg.thrust for seg in data.segments]),
                                     self.effect)
        self.limits_ += self._contact_limits

        # 4: residual and where it is
        self.residual_before_ = data.concat(r_nom)
        self.where_before_ = localise_residual(data, self.residual_before_, self.regressors_)

        # 5-7: what
        if self.effect is not None:
            self._say(f"fitting {self.effect} only")
            return r_nom, fit_only(data, r_nom, self._template(self.effect))
        return r_nom, forward_selection(data, r_nom, self._candidates(excluded), self.max_effects, progress=self._say,
                                        look_for_lag=look_for_lag)

    def _suction_bound(self, selection: Selection, excluded: set[str]) -> None:
        """Near a wall with no wall suction kept: the limit saying how strong a suction the flight could miss."""
        closest = nearest_wall(self.regressors_)
        if (selection.fitter is None or self.final_ is None or closest is None or not closest <= NEAR_SURFACE
                or "wall_suction" in excluded or any(e.name == "wall_suction" for e in self.final_.fit.effects)):
            return
        limit = suction_bound(selection.fitter, self.final_, closest, self._hold)
        if limit is not None:
            self.limits_.append(limit)

    def _lag_limits(self, lag: dict | None) -> None:
        if lag is not None and not lag["kept"] and lag["reason"].startswith(UNDETERMINED_LAG):
            self.limits_.append({"effects": [LAG_KEY], "reason": f"a motor lag would pay for itself but {lag['reason']}"
                                 " (a lag and a vertical drag look alike on a climb and descent at one pace)",
                                 "manoeuvre": determining_manoeuvre(LAG_KEY, "time_constant")})
        elif lag is not None and not lag["kept"] and lag["determined"] and lag["moves"]:
            move = lag["moves"]
            self.limits_.append({
                "effects": [LAG_KEY, move["effect"]],
                "reason": f"a motor lag of {1e3 * lag['time_constant_s']:.3g} +- {1e3 * lag['std_s']:.2g} ms fits this "
                          f"flight but does not lower the held-out score, and with it {move['effect']} "
                          f"{move['parameter']} would be {move['with']:.4g} instead of {move['without']:.4g}: the "
                          "flight cannot tell the lag from that effect",
                "manoeuvre": determining_manoeuvre(LAG_KEY, "time_constant")})

    # ------------------------------------------------------------------ a fitted model on other flights
    def _prepared(self, logs: list[FlightLog] | FlightLog) -> tuple[FlightData, list[int]]:
        """``logs`` as the fitted model sees them (ground contact left out, the model's motor lag applied), and for
        each prepared log the index of the log it came from."""
        if not hasattr(self, "final_") or self.final_ is None:
            raise RuntimeError("call fit(logs) before predict or score")
        logs = self._checked(logs)
        tau = self.model_.vehicle.motor_time_constant
        kept, origin = [], []
        for i, log in enumerate(logs):
            resting, contact = ground_contact(log)
            if (~(resting | contact)).sum() >= 2:
                part = log.select(~(resting | contact))
                kept.append(replace(part, vehicle=replace(part.vehicle, motor_time_constant=tau)) if tau > 0 else part)
                origin.append(i)
        if not kept:
            raise ValueError("the logs hold no airborne flight to predict")
        return prepare(kept, window_s=self.window_s, block_s=self.block_s, n_folds=self.n_folds), origin

    def _final_templates(self) -> list[Effect]:
        assert self.final_ is not None
        fitter = self.selection_.fitter if self.selection_ is not None else None
        return [fitter.templates[k] for k in self.final_.names] if fitter else list(self.final_.fit.effects)

    def predict(self, logs: list[FlightLog] | FlightLog, given: dict[str, dict[str, Any]] | None = None
                ) -> np.ndarray:
        """The aerodynamic force (N, world frame, smoothed as the residual is) the fitted model predicts at every
        sample of ``logs`` (concatenated), NaN where a sample is left out (ground contact, a segment too short).

        The model's shared parameters are used as fitted; a flight's own conditions (a steady wind of
        ``quadratic_drag`` with wind) are taken from ``given`` (``{"quadratic_drag": {"w": [...]}}``) or, when not
        given, fitted on the flight itself with everything else held (:attr:`conditions_` says which,
        :func:`discovery.flights.model_on`)."""
        logs = [logs] if isinstance(logs, FlightLog) else list(logs)
        data, origin = self._prepared(logs)
        assert self.final_ is not None
        r_nom, residual, self.conditions_ = model_on(data, self.final_, self._final_templates(), given)
        out = [np.full((log.n_samples, 3), np.nan) for log in logs]
        for seg, left in zip(data.segments, residual):
            log = origin[seg.log_index]
            out[log][np.searchsorted(logs[log].t, seg.t)] = seg.measured_force - left
        return np.concatenate(out)

    def score(self, logs: list[FlightLog] | FlightLog, given: dict[str, dict[str, Any]] | None = None) -> float:
        """The share of the nominal model's force-gap energy the fitted model explains on ``logs``: 1 for a perfect
        model, 0 for one no better than the nominal, negative for a worse one (the scikit-learn convention: higher
        is better). ``given`` as in :meth:`predict`."""
        data, _ = self._prepared(logs)
        assert self.final_ is not None
        r_nom, residual, self.conditions_ = model_on(data, self.final_, self._final_templates(), given)
        before = float(np.sum(data.concat(r_nom) ** 2))
        return 1.0 - float(np.sum(data.concat(residual) ** 2)) / before if before > 0 else 0.0

    def _predictions(self, data: FlightData, final: Candidate, vehicle) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Held-out open-loop predictions of the final model: each fold's parameters (each flight's own wind),
        the library's effects through their model and an affine thrust map on the replayed thrust."""
        layout = final.fit.layout
        if not final.names or layout is None:
            model = FlightModel(vehicle, []).aero_model()
            return prediction_pairs(data, model, None, self.horizon_s, self.stride_s)
        # the library's effects as the model file holds them (a wall that ends is the scene's plane there)
        library = [plain_wall(e) for e in final.fit.effects if not isinstance(e, ThrustMap)]
        model = FlightModel(vehicle, library).aero_model()
        fold_theta: dict[int, list[np.ndarray]] = {}
        thrust_maps: dict[int, list[np.ndarray]] = {}
        for f in range(data.n_flights):
            fold_theta[f], thrust_maps[f] = [], []
            for theta_k in final.fit.fold_theta:
                effects = layout.effects(theta_k, f)
                fold_theta[f].append(FlightModel(vehicle, [plain_wall(e) for e in effects
                                                           if not isinstance(e, ThrustMap)]).aero_model().theta())
                maps = [e for e in effects if isinstance(e, ThrustMap)]
                thrust_maps[f].append(maps[0].param_vector() if maps else np.array([1.0, 0.0]))
        has_map = any(isinstance(e, ThrustMap) for e in final.fit.effects)
        return prediction_pairs(data, model, fold_theta, self.horizon_s, self.stride_s,
                                thrust_maps=thrust_maps if has_map else None)

    def _shape(self, where: dict) -> dict | None:
        """The unexplained residual along its mean direction, piecewise linear in its localising quantity."""
        reg = next((r for r in self.regressors_ if r.name == where.get("regressor")), None)
        direction = where.get("direction_world")
        if reg is None or direction is None:
            return None
        along = self.residual_after_ @ np.asarray(direction, dtype=float)
        shape = piecewise_linear(reg.values, along)
        if shape is None:
            return None
        return {"regressor": reg.name, "unit": reg.unit, "direction_world": direction,
                "force_N_at_knots": shape["values"], "knots": shape["knots"],
                "explained_fraction": shape["explained_fraction"]}

    def _nothing_to_fit(self, reason: str, started: float) -> Discovery:
        """Results of a run whose logs hold nothing to fit: no effects, the nominal model, and why."""
        self.usable_ = False
        self.notes_.append(reason)
        vehicle = self.logs_[0].vehicle.to_vehicle_params()
        self.effects_, self.param_std_, self.explained_fraction_, self.undetermined_ = [], [], {}, []
        self.widened_by_lag_ = set()
        self.model_ = FlightModel(vehicle, [], {}, self.logs_[0].vehicle.vehicle_fields())
        self.selection_ = None
        self.final_ = None
        self.motor_lag_ = None
        self.withheld_ = None
        self.scene_problems_ = []
        self.flights_ = {"conditions": [], "held_out": []}
        self.limits_ = [{"effects": sorted(EFFECTS), "reason": reason,
                         "manoeuvre": "fly: take off and hover, move along each body axis at 1 m/s or more, and "
                                      "pass close to the walls, ground and ceiling of the scene"}]
        self.where_, self.where_before_, self.where_after_, self.effect_forces_ = {}, {}, {}, {}
        self.unexplained_ = None
        self.noise_ = {"floor_N": float("nan")}
        self.stand_ins_, self.written_notes_ = [], []
        self.wall_edge_ = None
        self.cancelling_ = []
        if not hasattr(self, "left_out_"):
            self.left_out_ = []
        nan = float("nan")
        self.gap_before_ = {"force_rms_N": nan, "prediction_rms_m": nan}
        self.gap_after_ = dict(self.gap_before_)
        self.prediction_errors_before_ = np.zeros(0)
        self.runtime_s_ = time.perf_counter() - started
        return self

    # ------------------------------------------------------------------ results
    @property
    def names_(self) -> list[str]:
        return [e.name for e in self.effects_]

    def report(self, model_path: str | None = None) -> dict[str, Any]:
        """The JSON report (see :mod:`discovery.report`)."""
        from discovery.report import build_report

        return build_report(self, model_path)

    def __repr__(self) -> str:
        if not hasattr(self, "effects_"):
            return f"Discovery(candidates={self.candidates}, effect={self.effect})"
        return f"Discovery(found={self.names_}, gap_before={self.gap_before_}, gap_after={self.gap_after_})"


def _with_lag_uncertainty(effect: Effect, std: dict, beside_lag: dict[str, dict]) -> tuple[dict, list[str]]:
    """An effect's standard errors ``std`` fitted with a found motor lag taken as the vehicle's, each at least the one
    it had fitted beside the lag (``beside_lag``: per effect name, :func:`discovery.selection._motor_lag`'s
    ``effect_std``), and the entries (``D[2]``) whose error that widened by more than sqrt 2 (the lag's share of
    their variance more than the rest's). Taken as known, the lag's own uncertainty is not in ``std``: on a climb and
    descent a vertical drag moves with the lag (0.30 N s/m for 35 ms), and a 5 ms error in the lag, 1.6 of its
    standard errors, put the drag 10 % off with a standard error of 1.4 % (the second simulator, a 2 kg vehicle)."""
    joint = beside_lag.get(effect.name, {})
    parameters = {p.name: p for p in effect.parameters}
    out = dict(std)
    widened: list[str] = []
    for key, value in std.items():
        other = joint.get(key)
        if other is None or np.shape(other) != np.shape(value):
            continue
        own = np.asarray(value, dtype=float)
        wider = np.where(np.isnan(own), own, np.fmax(own, np.asarray(other, dtype=float)))  # a held entry stays NaN
        out[key] = wider.tolist() if np.ndim(wider) else float(wider)
        # the lag's share of the variance more than the rest's
        mostly = np.atleast_1d(wider > np.sqrt(2.0) * own)
        widened += [parameters[key].entry_name(int(i)) for i in np.flatnonzero(mostly)]
    return out, widened


def _with_shift(std: dict, shift: dict) -> dict:
    """Standard errors ``std`` with the shifts ``shift`` (per parameter, the same shape) added in quadrature: an
    uncertainty the fit's own errors do not hold (:func:`discovery.form_range.leakage_shift`)."""
    out = dict(std)
    for key, moved in shift.items():
        if key in std:
            wider = np.hypot(np.asarray(std[key], dtype=float), np.asarray(moved, dtype=float))  # NaN (held) stays
            out[key] = wider.tolist() if np.ndim(wider) else float(wider)
    return out


def _written_std(written: list[Effect], fitted: list[Effect], stds: list[dict]) -> dict[str, dict]:
    """Standard errors of the written effects' parameters, where a fitted effect of that name has them."""
    by_name = {e.name: std for e, std in zip(fitted, stds)}
    return {e.name: {p.name: by_name[e.name][p.name] for p in e.parameters if p.name in by_name[e.name]}
            for e in written if e.name in by_name}


def _params_text(params: dict[str, Any]) -> str:
    return ", ".join(f"{k}={np.round(v, 4).tolist() if isinstance(v, list) else f'{v:.4g}'}" for k, v in params.items())


def _public_where(where: dict) -> dict:
    return {k: v for k, v in where.items() if k != "ranking"}
