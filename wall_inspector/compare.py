"""``wall-inspector compare``: the paper's Tables I and II in simulation, and the structures, with PID, MPC, SC-MPC
and PPO.

Flies every method on the scenarios of :mod:`controllers.paper_tables` (a progress
bar counts the flights), prints the Markdown tables and the acceptance checks, and
writes to ``--out``:

- ``tables.md``: the tables, the tuning budgets and the checks
  (``wall-inspector readme --set compare=OUT/tables.md`` copies them into the README);
- ``results.json``: pooled and per-flight metrics of every run, the budgets and the checks: the same
  seeds and settings give the same file, byte for byte, wherever the flights ran;
- ``timing.json``: what measures time, so differs from run to run: the MPCs' solve times
  (pooled and per flight), the wall time of the flights and (with ``--ray``) each
  flight's seconds on its worker;
- ``table_i_circle.png`` (paper Fig. 6), ``table_ii_sweep.png`` (paper Fig. 10) and ``structures.png``
  (the facade and the pier: paths and wall-normal errors).

Beyond the paper's tables (``--tables all``, the default), the structures: ``Facade-v0`` and
``Pier-v0`` (:data:`controllers.paper_tables.STRUCTURES`), each rotor's suction read from the
nearest surfaces of their bodies; ``--tables both`` flies the paper's two only.

Controllers fly the preset of ``--weights`` (:mod:`controllers.presets`): by default
``tuned``, each method's preset tuned by ``wall-inspector tune`` on the scenario's
task with the same budget for every method, with the authors' released settings as
extra rows labelled "(authors')"; SC-MPC flies in both formulations ("SC-MPC" is the
default ``dynamics+attitude``, "SC-MPC (dynamics only)" the paper's). ``--weights
paper-sim`` flies the weights that reproduce the paper's Table I and adds the checks
of that match. The shipped PPO agents (``agents/pretrained``) fly through the same
evaluation function and seeds: the circle agent in Table I, the sweep agent in Table
II, and in Table II also the residual agent that corrects SC-MPC ("PPO + SC-MPC"; its
SC-MPC base keeps the settings it was trained with). ``--no-ppo`` leaves them out. A
table of each method's optimisation budget (tuning trials, env steps, wall time;
PPO's training) stands beside the results.

``--ray [ADDRESS]`` flies every (method, scenario, seed) flight as a Ray task
(:mod:`wall_inspector.ray_backend`): on an embedded Ray of this machine, or on a cluster.

Nothing is lost on Ctrl-C: without ``--ray`` each finished flight is saved into
``OUT/.flights/`` as it lands, and the same command run again flies only the flights that
are missing (the tables are the same, byte for byte, as an uninterrupted run's); the folder
is emptied of them when the run completes. A folder holding the unfinished flights of a run
with other settings is refused. The run holds the folder's lock
(:mod:`wall_env.run_lock`): a second run into it refuses, naming the first.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
import time
from typing import Any


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out/compare", help="folder for tables, JSON and figures")
    parser.add_argument("--tables", choices=("I", "II", "both", "structures", "all"), default="all",
                        help="which table(s) to fly: the paper's I, II or both, the structures (Facade-v0, Pier-v0), "
                             "or all (default)")
    parser.add_argument("--seeds-i", type=int, default=5, help="seeds per row of Table I (default 5)")
    parser.add_argument("--seeds-ii", type=int, default=10, help="seeds of Table II (default 10)")
    parser.add_argument("--seeds-structures", type=int, default=10, help="seeds of each structure task (default 10)")
    parser.add_argument("--duration", type=float, default=None,
                        help="shorten every flight to this many seconds (a quick look; not the paper's tables)")
    parser.add_argument("--weights", default="tuned", metavar="PRESET",
                        help="controller preset: tuned (default; per task and method), paper (the authors' release), "
                             "paper-sim (reproduces the paper's Table I) or a preset YAML file")
    parser.add_argument("--no-authors", action="store_true",
                        help="leave out the extra rows flown with the authors' settings")
    parser.add_argument("--mpc-sigma", action="append", default=[], metavar="NAME=V[/V...]",
                        help="replace one of the MPCs' sigmas (both MPC and SC-MPC), e.g. position=0.07/0.07/0.093; "
                             "names are the fields of controllers.mpc.MPCWeights (sensitivity studies, not the paper)")
    parser.add_argument("--no-ppo", action="store_true", help="leave out the shipped PPO agents")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    from wall_inspector import ray_backend

    ray_backend.add_arguments(parser, "every (method, scenario, seed) flight is a Ray task; same tables and JSON")


class UsageError(ValueError):
    """A bad command-line value: reported in one line, exit code 2."""


def _sigma_changes(items: list[str]) -> dict[str, Any]:
    """``--mpc-sigma`` items as replacements of :class:`MPCWeights` fields (checked)."""
    from controllers.mpc.cost import MPCWeights

    fields = {f.name for f in dataclasses.fields(MPCWeights)}
    changes: dict[str, Any] = {}
    for item in items:
        name, sep, values = item.partition("=")
        if not sep or name not in fields:
            raise UsageError(f"--mpc-sigma takes NAME=V[/V...] with NAME one of {sorted(fields)}, got {item!r}")
        try:
            numbers = [float(v) for v in values.split("/")]
        except ValueError:
            raise UsageError(f"--mpc-sigma {name}: values must be numbers, got {values!r}") from None
        changes[name] = numbers[0] if len(numbers) == 1 else tuple(numbers)
    try:
        dataclasses.replace(MPCWeights(), **changes)
    except ValueError as exc:
        raise UsageError(f"--mpc-sigma: {exc}") from None
    return changes


FLIGHT_CACHE = ".flights"


class FinishedFlights:
    """The flights of one run saved as they land (``OUT/.flights/<key>.npz``), for a rerun to skip.

    ``signature`` (the run's settings) is written beside them; flights of a run with another
    signature are refused rather than mixed in.
    """

    def __init__(self, out: Any, signature: dict[str, Any]):
        from pathlib import Path

        self.folder = Path(out) / FLIGHT_CACHE
        self.signature = json.dumps(signature, sort_keys=True)
        stored = self.folder / "settings.json"
        if stored.is_file() and stored.read_text() != self.signature:
            raise UsageError(f"--out {out} holds the unfinished flights of a compare run with other settings "
                             f"({stored}); run that command again to finish it, or choose another --out")

    @staticmethod
    def key(flight: Any) -> str:
        """A file name for one flight of the tables (scenario, policy, seed)."""
        import hashlib

        text = json.dumps([flight.scenario.name, flight.scenario.env_id, flight.policy, int(flight.seed)])
        return hashlib.sha256(text.encode()).hexdigest()[:20]

    def load(self, key: str) -> Any:
        from controllers.evaluation import EpisodeRecord

        path = self.folder / f"{key}.npz"
        if not path.is_file():
            return None
        try:
            with np_load(path) as data:
                fields = {k: data[k] for k in data.files}
        except (OSError, ValueError):  # a flight cut off while it was being saved: fly it again
            return None
        scalars = {"seed": int(fields.pop("seed")), "hover_thrust": float(fields.pop("hover_thrust")),
                   "terminated": bool(fields.pop("terminated")), "solve_times": fields.pop("solve_times").tolist()}
        return EpisodeRecord(**scalars, **fields)

    def save(self, key: str, record: Any) -> None:
        import dataclasses
        import os

        import numpy as np

        self.folder.mkdir(parents=True, exist_ok=True)
        stored = self.folder / "settings.json"
        if not stored.is_file():  # written whole or not at all: a half-written one would refuse every rerun
            temporary = self.folder / ".settings.tmp.json"
            temporary.write_text(self.signature)
            os.replace(temporary, stored)
        values = {f.name: np.asarray(getattr(record, f.name)) for f in dataclasses.fields(record)}
        temporary = self.folder / f".{key}.tmp.npz"
        np.savez(temporary, **values)  # type: ignore[arg-type]  # keyword arrays
        os.replace(temporary, self.folder / f"{key}.npz")  # whole or not at all

    def clear(self) -> None:
        import shutil

        shutil.rmtree(self.folder, ignore_errors=True)


def np_load(path: Any) -> Any:
    import numpy as np

    return np.load(path, allow_pickle=False)


def resuming_executor(finished: FinishedFlights):
    """A :data:`controllers.paper_tables.FlightExecutor` that flies in this process, saving each flight as it
    lands and taking the ones a previous, interrupted run saved."""
    from controllers.paper_tables import fly

    def run(flights, on_flight):
        records = []
        for flight in flights:
            key = finished.key(flight)
            record = finished.load(key)
            if record is None:
                record = fly(flight)
                finished.save(key, record)
            records.append(record)
            on_flight()
        return records

    return run


def _preset_note(preset: str, changes: dict[str, Any]) -> str:
    from controllers.presets import load_preset

    if preset == "tuned":
        note = ("**Tuned presets** (`--weights tuned`, the default): each method's gains or sigmas and horizon tuned "
                "by `wall-inspector tune` on the scenario's task, the same budget for every method (below); rows "
                "marked (authors') fly the authors' released settings.")
    elif preset == "paper":
        note = "**The authors' released settings** (`--weights paper`)."
    else:
        loaded = load_preset(preset)
        note = (f"**Preset `{loaded.name}`** (`--weights {preset}`): {loaded.description}; methods it does not set "
                "fly the authors' settings; rows marked (authors') fly the authors' released settings.")
    if changes:
        note += (" **Not the preset's MPC weights**: sigmas changed to "
                 + ", ".join(f"{k} = {v}" for k, v in changes.items()) + " (sensitivity study).")
    return note


def _check_preset(preset: str, tasks: list[str]) -> None:
    """Fail before any flight if the preset cannot be read for the tasks flown."""
    from controllers import paper_tables as pt

    for task in tasks:
        for method in ("pid", "mpc", "scmpc"):
            try:
                pt._preset_for(preset, method, task)
            except ValueError as exc:
                raise UsageError(f"--weights {preset}: {exc}") from None


def _ppo_policies(env_id: str, residual: bool) -> dict:
    """The shipped agents for ``env_id``'s task (and its SC-MPC residual agent), if shipped."""
    from agents import policy_factory, pretrained_path

    task = env_id.split("/")[-1]
    policies = {}
    if pretrained_path(task).is_dir():
        policies["PPO"] = policy_factory()
    else:
        print(f"no shipped PPO agent for {task} ({pretrained_path(task)}): PPO left out", file=sys.stderr)
    if residual and pretrained_path(task, "residual_scmpc").is_dir():
        policies["PPO + SC-MPC"] = policy_factory(variant="residual_scmpc")
    if pretrained_path(task, "teacher_scmpc").is_dir():  # its own row: it learned from SC-MPC, not alone
        policies["SC-MPC distilled (DAgger)"] = policy_factory(variant="teacher_scmpc")
    return policies


def _ppo_acceptance(results) -> list[dict]:
    """The shipped sweep agent has at most one collision in the Table II scenario."""
    for r in results:
        if r.scenario.table == "II" and r.policy == "PPO":
            m = r.metrics()
            return [{"check": "Table II: PPO has at most 1 collision (contact steps)", "value": m["collisions"],
                     "pass": m["collisions"] <= 1}]
    return []


def budgets(preset: str, tasks: list[str], with_ppo: bool) -> list[dict[str, Any]]:
    """Each method's optimisation budget per task: the tuning study of its preset, PPO's training."""
    from controllers import paper_tables as pt
    from controllers.presets import METHOD_LABELS, load_preset
    from controllers.tuning.study import spent_budget

    rows = []
    for task in tasks:
        for method, label in METHOD_LABELS.items():
            chosen = pt._preset_for(preset, method, task)
            loaded = load_preset(chosen, method=method, task=task)
            used = spent_budget(loaded)  # a study that started from a tuned preset counts that preset's study too
            rows.append({"task": task, "method": label, "settings": loaded.name,
                         "trials": used.get("trials"), "env_steps": used.get("env_steps"),
                         "wall_time_s": used.get("wall_time_s")})
        if with_ppo:
            from agents import pretrained_path
            from agents.checkpoints import training_env_steps

            card_path = pretrained_path(task) / "model_card.json"
            if card_path.is_file():
                card = json.loads(card_path.read_text())
                training = card["training"]
                # a warm start's demonstrations count as env steps of the training (training_env_steps); its
                # controller's own tuning is that controller's row
                warm = training.get("warm_start") or {}
                settings = "shipped agent" + (f", warm-started from {METHOD_LABELS.get(warm['controller'], warm['controller'])} "
                                              "demonstrations" if warm.get("controller") else "")
                rows.append({"task": task, "method": "PPO", "settings": settings, "trials": None,
                             "env_steps": training_env_steps(training),
                             "wall_time_s": training["total_wall_time_s"]})
                runs = (card.get("development") or {}).get("runs") or []
                if runs:  # the runs that chose the shipped configuration count too
                    named = f"{len(runs)} development run" + ("s" if len(runs) != 1 else "")
                    rows.append({"task": task, "method": "PPO", "settings": f"{named} (not shipped)",
                                 "trials": None, "env_steps": sum(int(r["env_steps"]) for r in runs),
                                 "wall_time_s": sum(float(r["wall_time_s"]) for r in runs)})
    return rows


def budget_markdown(rows: list[dict[str, Any]]) -> str:
    def number(v, fmt):
        return "-" if v is None else format(v, fmt)

    lines = ["**Optimisation budget** of each method: the tuning study of its preset (`wall-inspector tune`; "
             "the authors' settings had none here) and PPO's training (a warm start's demonstrations included).", "",
             "| task | method | settings | tuning trials | env steps | wall time (min) |", "|---|---|---|---:|---:|---:|"]
    for r in rows:
        minutes = None if r["wall_time_s"] is None else r["wall_time_s"] / 60
        lines.append(f"| {r['task']} | {r['method']} | {r['settings']} | {number(r['trials'], 'd')} | "
                     f"{number(r['env_steps'], ',d')} | {number(minutes, '.1f')} |")
    return "\n".join(lines) + "\n"



def run(args: argparse.Namespace) -> int:
    from controllers import paper_tables as pt
    from wall_env.validation import check_output_folder

    try:
        for name in ("seeds_i", "seeds_ii", "seeds_structures"):
            if not 1 <= getattr(args, name) <= 1000:
                raise UsageError(f"--{name.replace('_', '-')} must be in [1, 1000], got {getattr(args, name)}")
        extra: dict[str, Any] = {}
        if args.duration is not None:
            if not 0.05 <= args.duration <= 3600:
                raise UsageError(f"--duration must be in [0.05, 3600] s, got {args.duration}")
            extra["duration"] = args.duration
        changes = _sigma_changes(args.mpc_sigma)
        scenarios = []
        if args.tables in ("I", "both", "all"):
            scenarios += [dataclasses.replace(s, seeds=tuple(range(args.seeds_i)), env_kwargs={**s.env_kwargs, **extra})
                          for s in pt.TABLE_I]
        if args.tables in ("II", "both", "all"):
            scenarios += [dataclasses.replace(s, seeds=tuple(range(args.seeds_ii)),
                                              env_kwargs={**s.env_kwargs, **extra}) for s in pt.TABLE_II]
        if args.tables in ("structures", "all"):
            scenarios += [dataclasses.replace(s, seeds=tuple(range(args.seeds_structures)),
                                              env_kwargs={**s.env_kwargs, **extra}) for s in pt.STRUCTURES]
        tasks = sorted({s.env_id.split("/")[-1].removesuffix("-v0") for s in scenarios})
        _check_preset(args.weights, tasks)
        out = check_output_folder(args.out)
        from wall_inspector import ray_backend

        ray_backend.check_arguments(args)
        from wall_inspector.cli import lock_run_folder

        lock = lock_run_folder(out, "wall-inspector compare")
        signature = {k: v for k, v in sorted(vars(args).items()) if k not in ("out", "no_progress", "ray", "ray_cpus")}
        finished = FinishedFlights(out, signature)
    except (UsageError, ValueError) as exc:
        raise SystemExit(str(exc)) from None  # one line, exit status 2 (wall_inspector.cli)
    try:
        return _run(args, scenarios, tasks, changes, out, finished)
    finally:
        lock.release()


def _run(args: argparse.Namespace, scenarios: list, tasks: list[str], changes: dict[str, Any], out: Any,
         finished: FinishedFlights) -> int:
    from controllers import paper_tables as pt

    mpc_weights = (lambda w: dataclasses.replace(w, **changes)) if changes else None
    policies = pt.controller_policies(args.weights, mpc_weights=mpc_weights)
    if args.weights != "paper" and not args.no_authors:
        authors = pt.controller_policies("paper", label_suffix=pt.AUTHORS, dynamics_only=False)
        for method, label in (("pid", "PID"), ("mpc", "MPC"), ("scmpc", "SC-MPC")):
            if all(pt._preset_for(args.weights, method, task) == "paper" for task in tasks):
                del authors[label + pt.AUTHORS]  # its main row already flies the authors' settings
        policies.update(authors)
    note = _preset_note(args.weights, changes)
    with contextlib.ExitStack() as stack:
        executor: Any = resuming_executor(finished)
        if args.ray is not None:
            from wall_inspector import ray_backend

            stack.enter_context(ray_backend.session(args.ray, args.ray_cpus))
            executor = ray_backend.flight_executor()
        t0 = time.perf_counter()
        results = []
        groups = [[s for s in scenarios if s.table == table] for table in ("I", "II")]
        groups += [[s] for s in scenarios if s.table == "S"]  # one group per structure: each has its own agent
        for chosen in filter(None, groups):
            ppo = {} if args.no_ppo else _ppo_policies(chosen[0].env_id, residual=chosen[0].table == "II")
            results += pt.run_scenarios(chosen, {**policies, **ppo}, progress=not args.no_progress,
                                        executor=executor)
        flying_s = time.perf_counter() - t0
    budget_rows = budgets(args.weights, tasks, with_ppo=not args.no_ppo)
    paths = pt.write_outputs(results, out, note, extra_checks=_ppo_acceptance(results),
                             table_i_paper_match=args.weights == "paper-sim",
                             extra_markdown=budget_markdown(budget_rows))
    data = json.loads(paths["json"].read_text())
    data["budgets"] = budget_rows
    data["preset"] = args.weights
    paths["json"].write_text(json.dumps(data, indent=2))
    timing = json.loads(paths["timing"].read_text())
    flights = sum(len(r.evaluation.episodes) for r in results)
    timing["flights"] = {"count": flights, "wall_time_s": round(flying_s, 3),
                         "executor": "in this process" if args.ray is None else f"Ray ({args.ray})"}
    if args.ray is not None:  # each flight's seconds on its worker, in the order of the tables
        timing["flights"]["seconds_each"] = [round(s, 3) for s in executor.seconds]
    paths["timing"].write_text(json.dumps(timing, indent=2))
    finished.clear()
    print(paths["markdown"].read_text())
    print(f"{len(results)} runs ({flights} flights) in {flying_s:.0f} s; wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
