"""``wall-inspector tune --ray``: the tuning study through Ray Tune's Optuna searcher.

The same study as the local ``tune`` (:class:`controllers.tuning.Tuner`): the same search
space (asked of the Optuna trial by the same :meth:`SearchSpace.suggest`, as a
define-by-run space of :class:`ray.tune.search.optuna.OptunaSearch`), the same seeded TPE
sampler, the same first trials (the authors' settings, then ``--start`` presets), the
same objective on the same training seeds, the same budget (trials and minutes, counted
over the whole study) and the same output: every finished trial is written into
``RUN/study.db`` and :meth:`Tuner.finish` flies the best one on the held-out seeds and
writes ``preset.yaml`` and ``report.json``.

What differs: trials run side by side (one per ``cpus_per_trial`` CPUs of the cluster),
so TPE proposes a trial before the ones still running have told it their results, and
the sequence of trials is not the local one; and no trial is pruned (the local study's
median pruner needs the running trials' intermediate values in order): every trial flies
every training seed. Ray Tune's own files (trial logs) go to ``RUN/ray/``.

Threads: a trial flies its seeds through :func:`controllers.evaluation.evaluate`, which holds
PyTorch and BLAS at the one thread that the thread rule (:mod:`controllers.threads`) gives a
policy acting on one observation at a time, as the local study's trials do.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

METRIC = "objective"


class _DefineByRun:
    """Optuna define-by-run space for :class:`OptunaSearch`: asks the trial what ``SearchSpace.suggest`` asks."""

    def __init__(self, space: Any):
        self.space = space

    def __call__(self, trial: Any) -> None:
        self.space.suggest(trial)
        return None


def _trial(config: dict[str, Any], objective: Any, space: Any) -> None:
    """One Ray Tune trial: fly the objective's training seeds with the searched values in ``config``."""
    from ray import tune

    flights = objective.evaluate(space.settings(config))
    tune.report({METRIC: flights.value, "env_steps": flights.env_steps,
                 "flights": len(flights.details.get("flights", flights.details.get("cells", ())))})


def run(tuner: Any, cpus_per_trial: float = 1.0, progress: bool = True) -> Any:
    """Run ``tuner``'s study on the connected Ray cluster until its budget is spent; return the
    :class:`~controllers.tuning.TuningResult` (as :meth:`Tuner.run` does).

    The searcher works on the stored study itself (``RUN/study.db``), so every trial lands
    there as it ends, and a stopped study resumes where it was (locally or on Ray).
    ``KeyboardInterrupt`` if trials were cut short before the budget was spent.
    """
    import optuna
    import ray
    from ray import tune
    from ray.tune.search import ConcurrencyLimiter
    from ray.tune.search.optuna import OptunaSearch

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = tuner.open_study()
    left_trials, left_seconds = tuner.remaining(study)
    if (left_trials is None or left_trials > 0) and (left_seconds is None or left_seconds > 0):
        storage = optuna.storages.RDBStorage(f"sqlite:///{(Path(tuner.run_dir) / 'study.db').resolve()}")
        searcher = OptunaSearch(space=_DefineByRun(tuner.space), metric=METRIC, mode="min",
                                sampler=optuna.samplers.TPESampler(seed=tuner.seed), study_name=study.study_name,
                                storage=storage,
                                points_to_evaluate=None if study.trials else tuner.start_values())
        slots = max(1, int(float(ray.cluster_resources().get("CPU", 1.0)) // cpus_per_trial))
        trainable = tune.with_resources(tune.with_parameters(_trial, objective=tuner.objective, space=tuner.space),
                                        {"cpu": cpus_per_trial})
        ray_tuner = tune.Tuner(
            trainable,
            tune_config=tune.TuneConfig(search_alg=ConcurrencyLimiter(searcher, max_concurrent=slots),
                                        num_samples=-1 if left_trials is None else left_trials,
                                        time_budget_s=left_seconds),
            run_config=tune.RunConfig(name="ray", storage_path=str((Path(tuner.run_dir) / "ray").resolve()),
                                      verbose=1 if progress else 0),
        )
        t0 = time.perf_counter()
        grid = ray_tuner.fit()
        elapsed = time.perf_counter() - t0
        results = [(grid[i].metrics or {}) for i in range(len(grid))]
        study = tuner.open_study()  # again: the searcher wrote the trials through its own connection
        study.set_user_attr("wall_time_s", float(study.user_attrs.get("wall_time_s", 0.0)) + elapsed)
        study.set_user_attr("env_steps", int(study.user_attrs.get("env_steps", 0))
                            + sum(int(m.get("env_steps", 0)) for m in results))
        unfinished = sum(METRIC not in m for m in results)
        left_trials, left_seconds = tuner.remaining(study)
        if unfinished and (left_trials is None or left_trials > 0) and (left_seconds is None or left_seconds > 0):
            raise KeyboardInterrupt(f"{unfinished} trials did not finish")
    return tuner.finish(study)
