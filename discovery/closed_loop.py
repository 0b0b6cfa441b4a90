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

from discovery.flight_log import file_sha256
from discovery.fly import prepare_flight
from wall_env.model_file import FlightModel
from wall_env.validation import read_json_object

__all__ = ["load_scenario", "closed_loop_check", "scenario_match", "PATH_TOLERANCE_M"]

PATH_TOLERANCE_M = 0.2  # m rms between the log's positions and the scenario's reference for the scenario to match


def load_scenario(path: str | Path) -> dict[str, Any]:
    """A scenario record as written by ``wall-inspector fly``."""
    data = read_json_object(path, "scenario file")
    missing = sorted({"env_id", "env_kwargs", "effects"} - set(data))
    if missing:
        raise ValueError(f"scenario file {path} lacks {missing}")
    return data


def scenario_match(scenario: dict[str, Any], log, log_path: str | Path | None = None) -> tuple[list[str], bool]:
    """Whether ``scenario`` is the world ``log`` was flown in: ``(problems, own)``.

    ``problems`` lists what differs between the scenario's world and the log: the scene (walls, ground,
    ceiling), the nominal vehicle (mass, rotor positions, drag), the rate, and the path (the log's positions
    more than :data:`PATH_TOLERANCE_M` rms from the scenario's reference). ``own`` says whether the scenario
    records this very log (its SHA-256, which ``wall-inspector fly`` writes): only then is it ground truth."""
    env_kwargs = {k: v for k, v in dict(scenario["env_kwargs"]).items() if k not in ("duration",)}
    rate = 1.0 / float(env_kwargs.pop("control_dt", 0.01))
    duration = float(dict(scenario["env_kwargs"]).get("duration") or 0.0) or None
    setup = prepare_flight(scenario["env_id"], scenario["effects"], env_kwargs, survey=scenario.get("survey"),
                           rate_hz=rate, duration=max(duration or 0.0, float(log.t[-1])) or None)
    try:
        env = setup.env
        base: Any = env.unwrapped
        scene = base.scene
        reference = getattr(env, "reference", None) or base.reference
        problems = []
        if scene.to_dict() != log.scene.to_dict():
            ours, theirs = scene.to_dict(), log.scene.to_dict()
            if not _close(ours, theirs):
                problems.append(f"its scene {ours} is not the log's {theirs}")
        vehicle, nominal = setup.nominal_vehicle, log.vehicle
        for name, a, b in (("mass", vehicle.mass, nominal.mass), ("rotor_positions", vehicle.rotor_positions,
                                                                   nominal.rotor_positions),
                           ("drag", vehicle.drag, nominal.drag)):
            if not np.allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), rtol=1e-6, atol=1e-9):
                problems.append(f"its vehicle {name} {a} is not the log's {b}")
        if abs(rate - log.rate_hz) > 0.01 * rate:
            problems.append(f"its rate {rate:g} Hz is not the log's {log.rate_hz:.4g} Hz")
        p_ref = reference.sample(np.asarray(log.t, dtype=float))[0]
        distance = float(np.sqrt(np.mean(np.sum((np.asarray(log.p_world) - p_ref) ** 2, axis=1))))
        if distance > PATH_TOLERANCE_M:
            problems.append(f"the log's positions are {distance:.2f} m rms from its reference path (more than "
                            f"{PATH_TOLERANCE_M:g} m): another flight")
    finally:
        setup.env.close()
    own = bool(scenario.get("log_sha256")) and log_path is not None and Path(log_path).is_file() \
        and scenario["log_sha256"] == file_sha256(log_path)
    return problems, own


def _close(a: Any, b: Any) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if a is None or b is None:
        return a is b
    return bool(np.isclose(float(a), float(b), rtol=1e-6, atol=1e-6))


def _summary(metrics: dict[str, Any]) -> dict[str, Any]:
    keys = ("wall_normal_rmse", "wall_normal_mae", "rmse_norm", "collisions", "terminated_early", "min_wall_clearance")
    out = {k: metrics.get(k) for k in keys}
    if "solve_ms" in metrics:
        out["solve_ms_median"] = metrics["solve_ms"]["median"]
    return out


def closed_loop_check(model: str | Path | FlightModel, scenario: dict[str, Any], seeds=(0,),
                      duration: float | None = None, ground_truth: bool = False) -> dict[str, Any]:
    """Fly nominal MPC and SC-MPC from ``model`` in ``scenario``'s world; return both scores.

    ``duration`` shortens the flight (s; default the scenario's); ``ground_truth`` says the scenario is the
    log's own record (:func:`scenario_match`), and the report calls the world so only then. Returns
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
    world = ("the log's own simulated scenario (ground truth)" if ground_truth else
             "a given scenario whose scene, vehicle, rate and path match the log's (not the log's own record, "
             "so not ground truth)")
    summary = (f"closed loop ({scenario['env_id']}, {len(list(seeds))} seed(s), {duration_s:.1f} s, in {world}): "
               f"wall-normal RMSE nominal MPC {100 * before:.2f} cm, SC-MPC from the discovered model "
               f"{100 * after:.2f} cm")
    return {
        "world": world,
        "env_id": scenario["env_id"],
        "seeds": [int(s) for s in seeds],
        "duration_s": duration_s,
        **results,
        "wall_normal_rmse_reduction": reduction,
        "summary": summary,
    }
