"""The discovery workflow as one object: ``Discovery().fit(logs)``, then inspect what it found.

::

    from discovery import Discovery, read_log

    found = Discovery().fit([read_log("flight.csv")])
    found.effects_            # named effects with fitted parameters
    found.gap_before_, found.gap_after_
    found.model_.save("model.json")   # loads in the env (model=...) and in SC-MPC
    found.report()            # the JSON report as a dict

The five steps:

1. **Residuals**: the force residual of paper Eq. 28 at every sample against the
   nominal model (:mod:`discovery.residuals`) and the open-loop prediction error over a
   fixed horizon replaying the logged thrust (:mod:`discovery.prediction`).
2. **Where**: which candidate regressor the residual depends on, where it is large
   and in which direction (:mod:`discovery.regressors`).
3. **What**: every effect of the library fitted by least squares and ranked on
   held-out data, added greedily while it pays for itself (:mod:`discovery.selection`).
4. **The fix**: a model file, the nominal vehicle plus the named effects with fitted
   parameters and standard errors (:class:`wall_env.model_file.FlightModel`).
5. **The proof**: the held-out gaps before and after (``force_rms_N``,
   ``prediction_rms_m``) and plots (:mod:`discovery.plots`).

All held-out figures use the same cross-validation folds: each time block is predicted
by parameters fitted without it. A significant residual left after the chosen
effects (its cross-validated bin means against some regressor predict at least
``unexplained_threshold`` of it) is reported as ``unexplained`` with where it is and its
shape: the residual along its mean direction, piecewise linear in the localising
quantity (:func:`discovery.regressors.piecewise_linear`, plotted by
:mod:`discovery.plots`).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from discovery.coverage import REST_THRUST_SHARE, flight_limits, resting_on_ground, scene_problems
from discovery.determination import determined, determining_manoeuvre, restrict
from discovery.fitting import out_of_fold_residuals
from discovery.flight_log import FlightLog
from discovery.motor_lag import LAG_KEY, UNDETERMINED_LAG
from discovery.prediction import DEFAULT_HORIZON_S, DEFAULT_STRIDE_S, prediction_pairs
from discovery.regressors import describe_force, localise_residual, piecewise_linear, regressors
from discovery.residuals import DEFAULT_BLOCK_S, DEFAULT_WINDOW_S, FlightData, prepare
from discovery.selection import Selection, fit_only, forward_selection
from wall_env.aero import AeroModel
from wall_env.effects import EFFECTS, Effect, make_effect
from wall_env.model_file import FlightModel

__all__ = ["Discovery", "DEFAULT_WINDOW_S", "DEFAULT_BLOCK_S"]

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


class Discovery:
    """Find what the nominal model misses in flight logs, name it from the effects library and fit it.

    Parameters
    ----------
    candidates: effect names to consider (default: the whole library).
    effect: fit only this effect, without selection (the paper's identification, Sec. 3.4).
    window_s: smoothing window of the differentiator and of the matched force kernel (s).
    block_s, n_folds: cross-validation time blocks (s) and folds.
    horizon_s, stride_s: open-loop prediction horizon and spacing of its start points (s).
    max_effects: at most this many effects are added.
    unexplained_threshold: share of the final held-out residual that regressor bin means
        must predict for it to be reported as ``unexplained``.
    options: effect options for candidates, e.g. ``{"wall_suction": {"thrust_scaling": True}}``.
    motor_lag: look for a motor lag next to the chosen effects when the vehicle block gives no
        ``motor_time_constant`` (:mod:`discovery.motor_lag`); one found becomes the model's
        vehicle ``motor_time_constant`` and the effects are chosen again with it.
    progress: a callable receiving short status strings (e.g. ``print``), or None.
    """

    residual_before_: np.ndarray  # (n, 3) N, the nominal model's held-out force residual
    where_before_: dict  # where that residual is (discovery.regressors.localise_residual)

    def __init__(self, candidates: list[str] | None = None, effect: str | None = None, *,
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
        names = list(EFFECTS) if candidates is None else list(candidates)
        unknown = sorted(set(names) - set(EFFECTS)) + ([effect] if effect is not None and effect not in EFFECTS else [])
        if unknown:
            raise ValueError(f"unknown effect(s) {unknown}; the library has {sorted(EFFECTS)}")
        self.candidates = names
        self.effect = effect
        self.window_s = float(window_s)
        self.block_s = float(block_s)
        self.n_folds = int(n_folds)
        self.horizon_s = float(horizon_s)
        self.stride_s = float(stride_s)
        self.max_effects = int(max_effects)
        self.unexplained_threshold = float(unexplained_threshold)
        self.options = dict(options or {})
        if not isinstance(motor_lag, bool):
            raise ValueError(f"motor_lag must be True or False, got {motor_lag!r}")
        self.motor_lag = motor_lag
        self.progress = progress

    # ------------------------------------------------------------------ fitting
    def _say(self, text: str) -> None:
        if self.progress is not None:
            self.progress(text)

    def _template(self, name: str) -> Effect:
        return make_effect(name, **self.options.get(name, {}))

    def fit(self, logs: list[FlightLog] | FlightLog) -> Discovery:
        """Run the five steps on ``logs``; results land in the attributes ending in ``_``.

        BLAS runs on one thread meanwhile: the least-squares matrices have a few thousand rows
        and at most a dozen columns, so threads gain nothing, and on a busy machine their
        waiting made each small SVD 70 times slower (fitting a one-minute log took 6 s
        instead of 2 s at load 3 on two cores).
        """
        with threadpool_limits(limits=1, user_api="blas"):
            return self._fit(logs)

    def _fit(self, logs: list[FlightLog] | FlightLog) -> Discovery:
        started = time.perf_counter()
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
        self.logs_ = logs
        self.notes_: list[str] = []
        airborne = []
        for log in logs:
            resting = resting_on_ground(log)
            if resting.any():
                dt = float(np.median(np.diff(log.t)))
                self.notes_.append(
                    f"{log.source}: {resting.sum() * dt:.1f} s of {log.duration:.1f} s held up by something "
                    f"else: the thrust carries less than {100 * REST_THRUST_SHARE:.0f} % of the weight and the vehicle "
                    "does not fall (on the ground or held): "
                    "left out, that force is not aerodynamic")
            if (~resting).sum() >= 2 and not resting.all():
                kept = log.select(~resting)
                if kept.duration >= shortest:
                    airborne.append(kept)
        self._say("preparing residuals")
        try:
            data = prepare(airborne, window_s=self.window_s, block_s=self.block_s, n_folds=self.n_folds)
        except ValueError:
            if airborne:
                raise
            return self._nothing_to_fit(f"no airborne stretch of at least {shortest:.3g} s: nothing to fit",
                                        started)
        self.usable_ = True
        look_for_lag = self.motor_lag and self.effect is None and data.vehicle.motor_time_constant == 0
        r_nom, selection = self._choose(data, look_for_lag)
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
            r_nom, selection = self._choose(data, False)
            selection.motor_lag = lag
            self.residual_before_, self.where_before_ = residual_before, where_before
        self.motor_lag_ = lag
        self.data_ = data
        vehicle = data.vehicle.to_vehicle_params()
        self.notes_ += scene_problems(self.regressors_, data.times)
        self.selection_: Selection | None = selection
        self.limits_ += selection.form_limits
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
        chosen = selection.chosen
        # only what the flight determined goes into the model (discovery.determination)
        self.effects_, self.param_std_, self.undetermined_ = determined(list(chosen.fit.effects),
                                                                        chosen.fit.std_dicts())
        kept_names = {e.name for e in self.effects_}
        self.explained_fraction_ = {k: v for k, v in selection.explained.items() if k in kept_names}
        fold_theta = [self._restricted_theta(chosen.fit.effects, theta_k) for theta_k in chosen.fit.fold_theta]

        # 4: the fix
        self.model_ = FlightModel(vehicle, list(self.effects_),
                                  {e.name: std for e, std in zip(self.effects_, self.param_std_)})

        # 5: the proof, on held-out data
        self._say("open-loop predictions")
        self.residual_after_ = data.concat(out_of_fold_residuals(data, self.effects_, fold_theta, r_nom))
        self.prediction_before_ = prediction_pairs(data_before, nominal_before.aero_model(), None, self.horizon_s,
                                                   self.stride_s)
        fold_models = self._fold_theta(fold_theta)
        self.prediction_after_ = prediction_pairs(data, self.model_.aero_model(), fold_models, self.horizon_s,
                                                  self.stride_s)
        self.prediction_errors_before_ = np.linalg.norm(self.prediction_before_[1] - self.prediction_before_[2], axis=1)
        self.prediction_errors_after_ = np.linalg.norm(self.prediction_after_[1] - self.prediction_after_[2], axis=1)
        self.gap_before_ = {"force_rms_N": _rms(self.residual_before_),
                            "prediction_rms_m": _rms(self.prediction_errors_before_)}
        self.gap_after_ = {"force_rms_N": _rms(self.residual_after_),
                           "prediction_rms_m": _rms(self.prediction_errors_after_)}

        # where each effect acts, and what is left
        self.effect_forces_ = {}
        self.where_ = {}
        for effect in self.effects_:
            force = data.concat(data.model_force(AeroModel([effect])))
            self.effect_forces_[effect.name] = force
            self.where_[effect.name] = describe_force(data, force, self.regressors_)
        left = localise_residual(data, self.residual_after_, self.regressors_)
        self.where_after_ = left
        self.unexplained_ = None
        if left["regressor"] is not None and left["explained_fraction"] >= self.unexplained_threshold \
                and left.get("range") is not None:
            self.unexplained_ = {"force_rms_N": _rms(self.residual_after_), "where": _public_where(left),
                                 "shape": self._shape(left)}
        self.runtime_s_ = time.perf_counter() - started
        return self

    def _choose(self, data: FlightData, look_for_lag: bool) -> tuple[list[np.ndarray], Selection]:
        """Steps 1-3 on prepared data: the nominal residual, where it is, and what explains it."""
        nominal = FlightModel(data.vehicle.to_vehicle_params(), [])
        r_nom = data.residuals(nominal.aero_model())
        self.regressors_ = regressors(data)
        self.limits_ = flight_limits(self.regressors_, data.concat([seg.thrust for seg in data.segments]))

        # 1-2: residual and where it is
        self.residual_before_ = data.concat(r_nom)
        self.where_before_ = localise_residual(data, self.residual_before_, self.regressors_)

        # 3: what
        if self.effect is not None:
            self._say(f"fitting {self.effect} only")
            return r_nom, fit_only(data, r_nom, self._template(self.effect))
        templates = [self._template(n) for n in self.candidates]
        return r_nom, forward_selection(data, r_nom, templates, self.max_effects, progress=self._say,
                                        look_for_lag=look_for_lag)

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
        self.model_ = FlightModel(vehicle, [])
        self.selection_ = None
        self.motor_lag_ = None
        self.limits_ = [{"effects": sorted(EFFECTS), "reason": reason,
                         "manoeuvre": "fly: take off and hover, move along each body axis at 1 m/s or more, and "
                                      "pass close to the walls, ground and ceiling of the scene"}]
        self.where_, self.where_before_, self.where_after_, self.effect_forces_ = {}, {}, {}, {}
        self.unexplained_ = None
        nan = float("nan")
        self.gap_before_ = {"force_rms_N": nan, "prediction_rms_m": nan}
        self.gap_after_ = dict(self.gap_before_)
        self.prediction_errors_before_ = np.zeros(0)
        self.runtime_s_ = time.perf_counter() - started
        return self

    def _restricted_theta(self, effects: list[Effect], theta: np.ndarray) -> np.ndarray:
        """One fold's parameters of ``effects`` with the same undetermined entries nulled or left out."""
        fold_effects, index = [], 0
        for effect in effects:
            fold_effects.append(effect.with_params(theta[index:index + effect.param_size]))
            index += effect.param_size
        kept = restrict(fold_effects, self.undetermined_)
        return np.concatenate([e.param_vector() for e in kept]) if kept else np.zeros(0)

    def _fold_theta(self, fold_theta: list[np.ndarray]) -> list[np.ndarray] | None:
        """Per-fold parameters of the full model (nominal drag plus effects) for predictions."""
        if not fold_theta:
            return None
        full = self.model_.aero_model()
        out = []
        for theta_k in fold_theta:
            effects = []
            index = 0
            for effect in self.effects_:
                effects.append(effect.with_params(theta_k[index:index + effect.param_size]))
                index += effect.param_size
            fold_model = FlightModel(self.model_.vehicle, effects).aero_model()
            if fold_model.structure_key != full.structure_key:
                raise RuntimeError("fold model structure differs from the full model")
            out.append(fold_model.theta())
        return out

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


def _public_where(where: dict) -> dict:
    return {k: v for k, v in where.items() if k != "ranking"}
