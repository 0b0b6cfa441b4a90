"""An Optuna study that tunes one controller within a budget, resumes after an interrupt, and writes a preset.

:class:`Tuner` runs a seeded TPE search (Optuna's ``TPESampler``) over the method's
:class:`~controllers.tuning.space.SearchSpace`, starting from the authors' settings
(the first trial), with the objective of :mod:`controllers.tuning.objective` on the
training seeds. Each trial reports its running mean after every flight, so that
Optuna's median pruner stops trials that are clearly worse than the median of the
earlier ones (pruned trials count toward the budget).

The budget is a number of trials and/or minutes of wall time, both counted over the
whole study, across interrupts: the study lives in ``RUN/study.db`` (SQLite), the
time spent and the env steps flown in the study's attributes, so running the same
command again after Ctrl-C continues where it stopped. When the budget is spent the
best trial flies the held-out seeds, and ``RUN/preset.yaml`` (the preset with its
provenance) and ``RUN/report.json`` are written.

Every flight goes through :func:`controllers.evaluation.evaluate`, which runs it on the one
thread the thread rule (:mod:`controllers.threads`) gives a policy acting on one observation at a
time: a study never spins idle threads against the other work of its machine.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from controllers.presets import METHOD_LABELS, ControllerPreset, load_preset
from controllers.tuning.objective import (
    ALONG_WALL_PRICE,
    CONTACT_PRICE_CM,
    RATE_EFFORT_PRICE_CM,
    THRUST_EFFORT_PRICE_CM,
    FlightSet,
    PaperTableIObjective,
    TrackingObjective,
)
from controllers.tuning.space import SearchSpace
from wall_env.provenance import git_commit

__all__ = ["Tuner", "TuningResult", "build_policy", "spent_budget"]

_STUDY_NAME = "tune"


def build_policy(method: str, settings: dict[str, Any], env: Any):
    """A controller of ``method`` with the preset section ``settings`` for ``env``.

    SC-MPC is told the suction ``settings["k_s"]``, ``settings["d_thr"]`` if given, else
    the env's own (its ``k_s`` / ``d_thr`` keywords as the caller recorded them in the
    settings) or the paper's.
    """
    from controllers import MPC, PID, SCMPC

    section = {k: v for k, v in settings.items() if k not in ("k_s", "d_thr")}
    kwargs = ControllerPreset("trial", "", methods={method: section}).controller_kwargs(method)
    if method == "pid":
        return PID.from_env(env, preset=None, **kwargs)
    if method == "mpc":
        return MPC.from_env(env, preset=None, **kwargs)
    suction = {k: settings[k] for k in ("k_s", "d_thr") if k in settings}
    return SCMPC.from_env(env, preset=None, **suction, **kwargs)


@dataclass
class TuningResult:
    """What a finished study found: the preset, the figures on training and held-out seeds, the budget used."""

    preset: ControllerPreset
    train_value: float
    heldout: FlightSet
    baseline_heldout: FlightSet
    trials: int
    env_steps: int
    wall_time_s: float
    paths: dict[str, Path] = field(default_factory=dict)


class Tuner:
    """Tune ``method`` (``"pid"``, ``"mpc"``, ``"scmpc"`` or, for ``paper-table-i``, ``"mpc+scmpc"``).

    Parameters
    ----------
    objective: a :class:`TrackingObjective` or :class:`PaperTableIObjective` (training seeds inside).
    heldout_seeds: seeds the result is reported on (never flown during the search).
    run_dir: folder of the study (``study.db``), the preset and the report.
    budget_trials, budget_minutes: the budget (``None`` for no limit of that kind; at least one is needed).
    seed: seed of the TPE sampler.
    space: the search space (default: the method's, from the authors' settings).
    command: the command line recorded in the provenance.
    base_preset: the settings the first trial flies and that unsearched values keep (the authors').
    start: further presets (names or files) whose settings are flown as the next trials.
    """

    def __init__(self, objective: TrackingObjective | PaperTableIObjective, heldout_seeds: Sequence[int],
                 run_dir: str | Path, *, budget_trials: int | None = 50, budget_minutes: float | None = None,
                 seed: int = 0, space: SearchSpace | None = None, command: str = "", progress: bool = True,
                 base_preset: str | Path = "paper", start: Sequence[str | Path] = ()):
        if budget_trials is None and budget_minutes is None:
            raise ValueError("give a budget: budget_trials and/or budget_minutes")
        if budget_trials is not None and (isinstance(budget_trials, bool) or not 1 <= int(budget_trials) <= 100000):
            raise ValueError(f"budget_trials must be in [1, 100000], got {budget_trials!r}")
        if budget_minutes is not None and not 0.0 < float(budget_minutes) <= 100000.0:
            raise ValueError(f"budget_minutes must be in (0, 100000], got {budget_minutes!r}")
        overlap = sorted(set(objective.seeds) & set(heldout_seeds))
        if overlap:
            raise ValueError(f"held-out seeds must differ from the training seeds; both have {overlap}")
        self.objective = objective
        self.method = objective.method
        self.heldout_seeds = [int(s) for s in heldout_seeds]
        self.run_dir = Path(run_dir)
        self.budget_trials = None if budget_trials is None else int(budget_trials)
        self.budget_minutes = None if budget_minutes is None else float(budget_minutes)
        self.seed = int(seed)
        space_method = "mpc" if self.method == "mpc+scmpc" else self.method
        self.base = load_preset(base_preset, method=space_method)
        self.space = space or SearchSpace(space_method, self.base.methods[space_method])
        self.start = [load_preset(p, method=space_method) for p in start]
        self.command = command
        self.progress = progress

    # ------------------------------------------------------------------ the study
    def open_study(self):
        """The stored Optuna study of ``run_dir`` (created, or loaded to resume; its signature checked).

        For other drivers of the same study (e.g. Ray Tune in ``wall-inspector tune --ray``), with
        :meth:`start_values`, :meth:`remaining` and :meth:`finish`.
        """
        return self._study()

    def start_values(self) -> list[dict[str, Any]]:
        """The searched values of the first trials: the authors' settings, then each ``start`` preset's."""
        return [self.space.values_of(preset.methods[self.space.method]) for preset in [self.base, *self.start]]

    def finish(self, study) -> TuningResult:
        """Fly the best trial of ``study`` on the held-out seeds and write the preset and the report."""
        return self._finish(study)

    def _study(self):
        import optuna

        self.run_dir.mkdir(parents=True, exist_ok=True)
        storage = f"sqlite:///{(self.run_dir / 'study.db').resolve()}"
        sampler = optuna.samplers.TPESampler(seed=self.seed)
        pruner = optuna.pruners.MedianPruner(n_startup_trials=8, n_warmup_steps=0)
        study = optuna.create_study(study_name=_STUDY_NAME, storage=storage, sampler=sampler, pruner=pruner,
                                    direction="minimize", load_if_exists=True)
        signature = {"method": self.method, "objective": self.objective.name, "env_id": self.objective.env_id,
                     "train_seeds": [int(s) for s in self.objective.seeds]}
        if self.objective.conditions:
            signature["conditions"] = list(self.objective.conditions)
        recorded = study.user_attrs.get("signature")
        if recorded is None:
            study.set_user_attr("signature", signature)
            study.set_user_attr("commit", git_commit())  # the code the study runs (a resume may run later code)
        elif recorded != signature:
            raise ValueError(f"{self.run_dir} holds a study of {recorded}, not of {signature}; "
                             "use another --out folder")
        return study

    def _done(self, study) -> tuple[int, float, int]:
        import optuna

        finished = [t for t in study.trials if t.state in (optuna.trial.TrialState.COMPLETE,
                                                          optuna.trial.TrialState.PRUNED)]
        return len(finished), float(study.user_attrs.get("wall_time_s", 0.0)), int(study.user_attrs.get("env_steps", 0))

    def remaining(self, study) -> tuple[int | None, float | None]:
        """Trials and seconds left of the budget (``None`` where that kind is unlimited)."""
        trials, seconds, _ = self._done(study)
        left_trials = None if self.budget_trials is None else max(0, self.budget_trials - trials)
        left_seconds = None if self.budget_minutes is None else max(0.0, 60.0 * self.budget_minutes - seconds)
        return left_trials, left_seconds

    def run(self) -> TuningResult:
        """Search until the budget is spent (resuming a stored study), then report on the held-out seeds.

        ``KeyboardInterrupt`` leaves the study stored and propagates; run again to resume.
        """
        import optuna
        from tqdm import tqdm

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        study = self._study()
        if not study.trials:
            for preset, values in zip([self.base, *self.start], self.start_values()):
                study.enqueue_trial(values, user_attrs={"start": f"preset {preset.name}"})
        done, _, _ = self._done(study)
        left_trials, left_seconds = self.remaining(study)
        total = self.budget_trials if self.budget_trials is not None else None
        with tqdm(total=total, initial=done, unit="trial", disable=not self.progress, dynamic_ncols=True,
                  desc=f"tune {self.method} on {self.objective.env_id.split('/')[-1]}") as bar:
            while (left_trials is None or left_trials > 0) and (left_seconds is None or left_seconds > 0):
                t0 = time.perf_counter()
                steps = self._one_trial(study)
                _, spent, flown = self._done(study)
                study.set_user_attr("wall_time_s", spent + time.perf_counter() - t0)
                study.set_user_attr("env_steps", flown + steps)
                bar.update(1)
                bar.set_postfix(best=f"{study.best_value:.3f}")
                left_trials, left_seconds = self.remaining(study)
        return self._finish(study)

    def _one_trial(self, study) -> int:
        import optuna

        trial = study.ask()
        settings = self.space.suggest(trial)

        def report(i: int, value: float) -> bool:
            trial.report(value, i)
            return trial.should_prune()

        try:
            flights = self.objective.evaluate(settings, report=report)
        except BaseException:
            study.tell(trial, state=optuna.trial.TrialState.FAIL)
            raise
        steps = flights.env_steps
        trial.set_user_attr("env_steps", steps)
        trial.set_user_attr("details", _jsonable(flights.details))
        if isinstance(self.objective, TrackingObjective) and \
                len(flights.details.get("flights", ())) < self.objective.flights_per_trial():
            study.tell(trial, state=optuna.trial.TrialState.PRUNED)
        else:
            study.tell(trial, flights.value)
        return steps

    # ------------------------------------------------------------------ results
    def _finish(self, study) -> TuningResult:
        best = study.best_trial
        settings = self.space.settings({**self.space.values_of(self.space.base), **best.params})
        heldout = self.objective.evaluate(settings, seeds=self.heldout_seeds)
        baseline = self.objective.evaluate(self.space.base, seeds=self.heldout_seeds)
        trials, wall_time, env_steps = self._done(study)
        methods = {"mpc": settings, "scmpc": {**settings, "compensation": "dynamics+attitude"}} \
            if self.method == "mpc+scmpc" else {self.method: settings}
        label = METHOD_LABELS.get(self.method, "MPC and SC-MPC")
        provenance = {
            "task": self.objective.env_id,
            "env_kwargs": self.objective.env_kwargs,
            "method": self.method,
            "objective": {"name": self.objective.name, "definition": self._objective_definition(),
                          **({"conditions": list(self.objective.conditions)} if self.objective.conditions else {}),
                          "train_value": best.value, "heldout_value": heldout.value,
                          "authors_settings_heldout_value": baseline.value},
            "train_seeds": [int(s) for s in self.objective.seeds],
            "heldout_seeds": self.heldout_seeds,
            "budget": {"trials": self.budget_trials, "minutes": self.budget_minutes},
            "used": {"trials": trials, "env_steps": env_steps, "wall_time_s": round(wall_time, 1)},
            "used_with_start": _with_start({"trials": trials, "env_steps": env_steps, "wall_time_s": wall_time},
                                           self.start),
            "sampler": f"optuna TPESampler(seed={self.seed}), MedianPruner(n_startup_trials=8)",
            "start": [{"preset": p.name, "settings": p.methods[self.space.method]} for p in [self.base, *self.start]],
            "command": self.command,
            "commit": study.user_attrs.get("commit") or git_commit(),
            "date": time.strftime("%Y-%m-%d", time.gmtime()),
        }
        name = "paper-sim" if self.objective.name == "paper-table-i" else \
            f"tuned-{self.objective.env_id.split('/')[-1]}-{self.method}"
        description = (f"{label} tuned by `wall-inspector tune` on {self.objective.env_id} "
                       f"({self.objective.name} objective)")
        preset = ControllerPreset(name, description, _jsonable(provenance), _jsonable(methods))
        self.run_dir.mkdir(parents=True, exist_ok=True)
        paths = {"preset": preset.save(self.run_dir / "preset.yaml", comment=self._comment(heldout, baseline)),
                 "report": self.run_dir / "report.json"}
        report = {"preset": preset.to_dict(), "best_trial": best.number, "best_params": best.params,
                  "heldout": heldout.details, "authors_settings_heldout": baseline.details,
                  "trials": [{"number": t.number, "state": t.state.name, "value": t.value, "params": t.params}
                             for t in study.trials]}
        paths["report"].write_text(json.dumps(_jsonable(report), indent=2))
        return TuningResult(preset, best.value, heldout, baseline, trials, env_steps, wall_time, paths)

    def _objective_definition(self) -> str:
        if self.objective.name == "paper-table-i":
            return ("over Table I's MPC (k_s 1, 4, 10 N/m) and SC-MPC (k_s 10 N/m) cells: max |ln(wall-normal RMSE "
                    "/ paper RMSE)| + 0.1 mean ln(wall-normal RMSE / paper RMSE)^2")
        conditions = self.objective.conditions
        task = (f"wall-normal RMSE (cm) + {ALONG_WALL_PRICE} x RMSE along the wall (cm) + "
                f"{CONTACT_PRICE_CM} cm per contact step + "
                f"{RATE_EFFORT_PRICE_CM} cm per rad/s RMS body-rate command + {THRUST_EFFORT_PRICE_CM} cm per N "
                "RMS thrust command away from hover")
        if not conditions:
            return f"mean over flights of {task}"
        return (f"mean over flights, every seed flown in the task's world and under the flight conditions "
                f"{', '.join(repr(c) for c in conditions)}; a flight in the task's world costs {task}; one under "
                f"the conditions its wall-normal RMSE (cm) + {CONTACT_PRICE_CM} cm per contact step")

    def _comment(self, heldout: FlightSet, baseline: FlightSet) -> str:
        return (f"Made by `wall-inspector tune` ({self.objective.name} objective; see the provenance below).\n"
                f"Held-out seeds: objective {heldout.value:.4g} (the authors' settings: {baseline.value:.4g}).")


def spent_budget(preset: ControllerPreset) -> dict[str, Any]:
    """What making ``preset`` cost: its study's trials, env steps and wall time together with those of the tuned
    presets it started from (``used_with_start``; ``used`` for a preset that records only its own study)."""
    return dict(preset.provenance.get("used_with_start") or preset.provenance.get("used") or {})


def _with_start(used: dict[str, Any], start: Sequence[ControllerPreset]) -> dict[str, Any]:
    """``used`` plus the budget of every start preset that was itself tuned: a study that starts from a tuned
    preset builds on that preset's study, so a method's budget counts both."""
    total = {k: (0 if v is None else v) for k, v in used.items()}
    for preset in start:
        for key, value in spent_budget(preset).items():
            if key in total and value is not None:
                total[key] += value
    total["wall_time_s"] = round(float(total["wall_time_s"]), 1)
    return total


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if hasattr(value, "item") and callable(value.item):
        return _jsonable(value.item())
    return value


def default_objective(objective: str, env_id: str, method: str, seeds: Sequence[int], env_kwargs: dict[str, Any],
                      build: Callable[..., Any] = build_policy,
                      conditions: Sequence[str] = ()) -> TrackingObjective | PaperTableIObjective:
    """The objective named ``objective`` (``"tracking"`` or ``"paper-table-i"``); ``conditions``: flight-condition
    profiles the tracking objective flies every seed in too."""
    if objective == "paper-table-i":
        if conditions:
            raise ValueError("the paper-table-i objective flies the paper's ideal conditions; conditions apply to "
                             "the tracking objective")
        return PaperTableIObjective(seeds, env_kwargs, build)
    if objective != "tracking":
        raise ValueError(f"objective must be 'tracking' or 'paper-table-i', got {objective!r}")
    return TrackingObjective(env_id, method, seeds, env_kwargs, build, conditions=conditions)
