"""Tuning the controllers with a stated budget: search spaces, objectives and the Optuna study.

``wall-inspector tune`` (:mod:`wall_inspector.tune`) is the command; in Python::

    from controllers.tuning import Tuner, default_objective

    objective = default_objective("tracking", "WallInspector/WallSweep-v0", "scmpc", seeds=[1000, 1001, 1002],
                                  env_kwargs={"noise": True, "terminate_on_collision": False})
    result = Tuner(objective, heldout_seeds=range(2000, 2010), run_dir="runs/tune-sweep-scmpc",
                   budget_trials=50).run()
    result.preset.save("my_preset.yaml")

=============  ================================================================
module         what
=============  ================================================================
``space``      the searched parameters of each method and their ranges
``objective``  what a set of flights costs (wall-normal RMSE + prices), and
               the paper's Table I match that makes ``paper-sim``
``study``      :class:`Tuner`: seeded TPE search in a resumable SQLite study,
               held-out report, preset with provenance
=============  ================================================================
"""

from controllers.tuning.objective import OBJECTIVES, PaperTableIObjective, TrackingObjective, flight_cost
from controllers.tuning.space import SearchSpace
from controllers.tuning.study import Tuner, TuningResult, build_policy, default_objective

__all__ = ["Tuner", "TuningResult", "SearchSpace", "TrackingObjective", "PaperTableIObjective", "flight_cost",
           "build_policy", "default_objective", "OBJECTIVES"]
