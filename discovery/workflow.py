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
``unexplained_threshold`` of it) is reported as ``unexplained`` with where it is.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from discovery.fitting import out_of_fold_residuals
from discovery.flight_log import FlightLog
from discovery.prediction import DEFAULT_HORIZON_S, DEFAULT_STRIDE_S, prediction_pairs
from discovery.regressors import describe_force, localise_residual, regressors
from discovery.residuals import DEFAULT_BLOCK_S, DEFAULT_WINDOW_S, prepare
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
    progress: a callable receiving short status strings (e.g. ``print``), or None.
    """

    def __init__(self, candidates: list[str] | None = None, effect: str | None = None, *,
                 window_s: float = DEFAULT_WINDOW_S, block_s: float = DEFAULT_BLOCK_S, n_folds: int = 5,
                 horizon_s: float = DEFAULT_HORIZON_S, stride_s: float = DEFAULT_STRIDE_S, max_effects: int = 3,
                 unexplained_threshold: float = 0.15, options: dict[str, dict[str, Any]] | None = None,
                 progress=None):
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
        self.progress = progress

    # ------------------------------------------------------------------ fitting
    def _say(self, text: str) -> None:
        if self.progress is not None:
            self.progress(text)

    def _template(self, name: str) -> Effect:
        return make_effect(name, **self.options.get(name, {}))

    def fit(self, logs: list[FlightLog] | FlightLog) -> Discovery:
        """Run the five steps on ``logs``; results land in the attributes ending in ``_``."""
        started = time.perf_counter()
        logs = [logs] if isinstance(logs, FlightLog) else list(logs)
        self._say("preparing residuals")
        data = prepare(logs, window_s=self.window_s, block_s=self.block_s, n_folds=self.n_folds)
        self.data_ = data
        self.logs_ = logs
        vehicle = data.vehicle.to_vehicle_params()
        nominal = FlightModel(vehicle, [])
        r_nom = data.residuals(nominal.aero_model())
        self.regressors_ = regressors(data)

        # 1-2: residual and where it is
        self.residual_before_ = data.concat(r_nom)
        self.where_before_ = localise_residual(data, self.residual_before_, self.regressors_)

        # 3: what
        if self.effect is not None:
            self._say(f"fitting {self.effect} only")
            selection = fit_only(data, r_nom, self._template(self.effect))
        else:
            templates = [self._template(n) for n in self.candidates]
            selection = forward_selection(data, r_nom, templates, self.max_effects, progress=self._say)
        self.selection_ = selection
        chosen = selection.chosen
        self.effects_ = list(chosen.fit.effects)
        self.param_std_ = chosen.fit.std_dicts()
        self.explained_fraction_ = dict(selection.explained)

        # 4: the fix
        self.model_ = FlightModel(vehicle, list(self.effects_),
                                  {e.name: std for e, std in zip(self.effects_, self.param_std_)})

        # 5: the proof, on held-out data
        self._say("open-loop predictions")
        self.residual_after_ = data.concat(out_of_fold_residuals(data, chosen.fit.effects, chosen.fit.fold_theta,
                                                                 r_nom))
        self.prediction_before_ = prediction_pairs(data, nominal.aero_model(), None, self.horizon_s, self.stride_s)
        fold_models = self._fold_theta(selection)
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
            self.unexplained_ = {"force_rms_N": _rms(self.residual_after_), "where": _public_where(left)}
        self.runtime_s_ = time.perf_counter() - started
        return self

    def _fold_theta(self, selection: Selection) -> list[np.ndarray] | None:
        """Per-fold parameters of the full model (nominal drag plus effects) for predictions."""
        fit = selection.chosen.fit
        if not fit.fold_theta:
            return None
        full = self.model_.aero_model()
        out = []
        for theta_k in fit.fold_theta:
            effects = []
            index = 0
            for effect in fit.effects:
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
