"""The closed-loop check: does the discovered model make the controller better in the log's world?

SC-MPC built from the discovered model file (``SCMPC.from_env(env, model=...)``, which
predicts with every effect the file holds) and the nominal MPC (the log's nominal
vehicle and its drag only) each fly the scenario the log came from, over the same
seeds (same start perturbations and command noise); :func:`controllers.evaluation.evaluate`
scores them. The headline figure is the wall-normal RMSE (error along the outward
normal of the wall nearest to the reference).

The world is the simulated truth of the log: the scenario file that ``wall-inspector
fly`` writes beside a log (:func:`discovery.fly.scenario_path`), with the effects that
were flown. Discovery never reads that file for anything else. For a real flight log
there is no such file; then give a scenario explicitly, and the world is built from
it (its ``effects`` are what the simulated world contains, e.g. the discovered ones).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from discovery.fly import prepare_flight
from wall_env.model_file import FlightModel
from wall_env.validation import read_json_object

__all__ = ["load_scenario", "closed_loop_check"]


def load_scenario(path: str | Path) -> dict[str, Any]:
    """A scenario record as written by ``wall-inspector fly``."""
    data = read_json_object(path, "scenario file")
    missing = sorted({"env_id", "env_kwargs", "effects"} - set(data))
    if missing:
        raise ValueError(f"scenario file {path} lacks {missing}")
    return data


def _summary(metrics: dict[str, Any]) -> dict[str, Any]:
    keys = ("wall_normal_rmse", "wall_normal_mae", "rmse_norm", "collisions", "terminated_early", "min_wall_clearance")
    out = {k: metrics.get(k) for k in keys}
    if "solve_ms" in metrics:
        out["solve_ms_median"] = metrics["solve_ms"]["median"]
    return out


def closed_loop_check(model: str | Path | FlightModel, scenario: dict[str, Any], seeds=(0,),
                      duration: float | None = None) -> dict[str, Any]:
    """Fly nominal MPC and SC-MPC from ``model`` in ``scenario``'s world; return both scores.

    ``duration`` shortens the flight (s; default the scenario's). Returns
    ``{"world", "env_id", "seeds", "duration_s", "nominal_mpc", "scmpc_discovered",
    "wall_normal_rmse_reduction", "summary"}`` with metrics from
    :func:`controllers.evaluation.evaluate`.
    """
    from controllers import MPC, SCMPC
    from controllers.evaluation import evaluate

    flight_model = model if isinstance(model, FlightModel) else FlightModel.load(model)
    env_kwargs = {k: v for k, v in dict(scenario["env_kwargs"]).items() if k not in ("duration",)}
    rate = 1.0 / float(env_kwargs.pop("control_dt", 0.01))
    scenario_duration = float(dict(scenario["env_kwargs"]).get("duration") or 0.0) or None
    flight_duration = duration if duration is not None else scenario_duration
    survey = scenario.get("survey")

    def factory():
        setup = prepare_flight(scenario["env_id"], scenario["effects"], env_kwargs, survey=survey,
                               duration=flight_duration, rate_hz=rate)
        return setup.env

    # the nominal MPC knows the log's nominal vehicle (its drag), not any drag that was flown
    nominal_vehicle = flight_model.vehicle
    nominal = FlightModel(nominal_vehicle, []).aero_model()
    probe = factory()
    duration_s = float(probe.unwrapped.duration)
    probe.close()
    results = {}
    for label, make in (
        ("nominal_mpc", lambda env: MPC.from_env(env, model=nominal, vehicle=nominal_vehicle)),
        ("scmpc_discovered", lambda env: SCMPC.from_env(env, model=flight_model)),
    ):
        result = evaluate(make, factory, seeds=list(seeds))
        results[label] = _summary(result.metrics())
    before = results["nominal_mpc"]["wall_normal_rmse"]
    after = results["scmpc_discovered"]["wall_normal_rmse"]
    reduction = (1.0 - after / before) if before and np.isfinite(before) and np.isfinite(after) else None
    summary = (f"closed loop ({scenario['env_id']}, {len(list(seeds))} seed(s), {duration_s:.1f} s): wall-normal RMSE "
               f"nominal MPC {100 * before:.2f} cm, SC-MPC from the discovered model {100 * after:.2f} cm")
    return {
        "world": "the log's simulated scenario (ground truth)" if scenario.get("note") else "the given scenario",
        "env_id": scenario["env_id"],
        "seeds": [int(s) for s in seeds],
        "duration_s": duration_s,
        **results,
        "wall_normal_rmse_reduction": reduction,
        "summary": summary,
    }
