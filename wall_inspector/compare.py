"""``wall-inspector compare``: the paper's Tables I and II in simulation, with PID, MPC, SC-MPC and PPO.

Flies every method on the scenarios of :mod:`controllers.paper_tables` (a progress
bar counts the flights), prints the Markdown tables and the acceptance checks, and
writes to ``--out``:

- ``tables.md``: the tables (``wall-inspector readme --set compare=OUT/tables.md``
  copies them into the README);
- ``results.json``: pooled and per-flight metrics of every run and the checks;
- ``table_i_circle.png`` (paper Fig. 6) and ``table_ii_sweep.png`` (paper Fig. 10).

The shipped PPO agents (``agents/pretrained``) fly through the same evaluation
function and seeds: the circle agent in Table I, the sweep agent in Table II, and in
Table II also the residual agent that corrects SC-MPC ("PPO + SC-MPC"; its SC-MPC base
keeps the weights it was trained with). ``--no-ppo`` leaves them out.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from typing import Any


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out/compare", help="folder for tables, JSON and figures")
    parser.add_argument("--tables", choices=("I", "II", "both"), default="both", help="which table(s) to reproduce")
    parser.add_argument("--seeds-i", type=int, default=5, help="seeds per row of Table I (default 5)")
    parser.add_argument("--seeds-ii", type=int, default=10, help="seeds of Table II (default 10)")
    parser.add_argument("--duration", type=float, default=None,
                        help="shorten every flight to this many seconds (a quick look; not the paper's tables)")
    parser.add_argument("--weights", choices=("paper", "tuned"), default="paper",
                        help="MPC and SC-MPC weights: the authors' sigmas (default) or the tuned position sigmas of "
                             "controllers.mpc.cost.tuned_weights")
    parser.add_argument("--mpc-sigma", action="append", default=[], metavar="NAME=V[/V...]",
                        help="replace one of the MPCs' sigmas (both MPC and SC-MPC), e.g. position=0.07/0.07/0.093; "
                             "names are the fields of controllers.mpc.MPCWeights (sensitivity studies, not the paper)")
    parser.add_argument("--no-ppo", action="store_true", help="leave out the shipped PPO agents")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def _weights(preset: str, items: list[str]):
    """MPC weights of ``--weights`` with the ``--mpc-sigma`` replacements, and a note saying so
    (``None, ""`` for the authors' weights)."""
    from controllers.mpc.cost import MPCWeights, tuned_weights

    base = MPCWeights() if preset == "paper" else tuned_weights()
    base_note = "" if preset == "paper" else (
        "**Tuned MPC weights** (`--weights tuned`): the authors' sigmas with position sigma "
        f"{'/'.join(f'{v:.4g}' for v in base.position)} m and terminal position sigma "
        f"{base.terminal_position[0]:.4g} m instead of 0.15/0.15/0.20 and 0.05 m "
        "(see `controllers.mpc.cost.tuned_weights`).")
    if not items:
        return (None if preset == "paper" else base), base_note
    fields = {f.name for f in dataclasses.fields(MPCWeights)}
    changes: dict[str, Any] = {}
    for item in items:
        name, sep, values = item.partition("=")
        if not sep or name not in fields:
            raise SystemExit(f"--mpc-sigma takes NAME=V[/V...] with NAME one of {sorted(fields)}, got {item!r}")
        try:
            numbers = [float(v) for v in values.split("/")]
        except ValueError:
            raise SystemExit(f"--mpc-sigma {name}: values must be numbers, got {values!r}") from None
        changes[name] = numbers[0] if len(numbers) == 1 else tuple(numbers)
    try:
        weights = dataclasses.replace(base, **changes)
    except ValueError as exc:
        raise SystemExit(f"--mpc-sigma: {exc}") from None
    note = ("**Not the authors' MPC weights**: sigmas changed to "
            + ", ".join(f"{k} = {v}" for k, v in changes.items()) + " (sensitivity study).")
    return weights, " ".join(filter(None, [base_note, note]))


def _ppo_policies(env_id: str, residual: bool) -> dict:
    """The shipped agents for ``env_id``'s task (and its SC-MPC residual agent), if shipped."""
    from agents import policy_factory, pretrained_path

    task = env_id.split("/")[-1]
    policies = {}
    if pretrained_path(task).is_dir():
        policies["PPO"] = policy_factory()
    else:
        print(f"no shipped PPO agent for {task} ({pretrained_path(task)}): PPO left out")
    if residual and pretrained_path(task, "residual_scmpc").is_dir():
        policies["PPO + SC-MPC"] = policy_factory(variant="residual_scmpc")
    return policies


def _ppo_acceptance(results) -> list[dict]:
    """The shipped sweep agent has at most one collision in the Table II scenario."""
    for r in results:
        if r.scenario.table == "II" and r.policy == "PPO":
            m = r.metrics()
            return [{"check": "Table II: PPO has at most 1 collision (contact steps)", "value": m["collisions"],
                     "pass": m["collisions"] <= 1}]
    return []


def run(args: argparse.Namespace) -> int:
    from controllers import paper_tables as pt

    for name in ("seeds_i", "seeds_ii"):
        if not 1 <= getattr(args, name) <= 1000:
            raise SystemExit(f"--{name.replace('_', '-')} must be in [1, 1000], got {getattr(args, name)}")
    extra = {}
    if args.duration is not None:
        if not 0.05 <= args.duration <= 3600:
            raise SystemExit(f"--duration must be in [0.05, 3600] s, got {args.duration}")
        extra["duration"] = args.duration
    scenarios = []
    if args.tables in ("I", "both"):
        scenarios += [dataclasses.replace(s, seeds=tuple(range(args.seeds_i)), env_kwargs=extra) for s in pt.TABLE_I]
    if args.tables in ("II", "both"):
        scenarios += [dataclasses.replace(s, seeds=tuple(range(args.seeds_ii)), env_kwargs=extra) for s in pt.TABLE_II]
    weights, note = _weights(args.weights, args.mpc_sigma)
    t0 = time.perf_counter()
    policies = pt.paper_policies(weights)
    results = []
    for table in ("I", "II"):
        chosen = [s for s in scenarios if s.table == table]
        if chosen:
            extra = {} if args.no_ppo else _ppo_policies(chosen[0].env_id, residual=table == "II")
            results += pt.run_scenarios(chosen, {**policies, **extra}, progress=not args.no_progress)
    paths = pt.write_outputs(results, args.out, note, extra_checks=_ppo_acceptance(results))
    print(paths["markdown"].read_text())
    print(f"{len(results)} runs in {time.perf_counter() - t0:.0f} s; wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
