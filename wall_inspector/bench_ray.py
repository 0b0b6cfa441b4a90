"""``wall-inspector bench-ray``: what Ray gains and costs for ``compare --ray``.

Two figures, measured in one run on an embedded Ray of this machine:

* **speed-up**: the default Table II of ``compare`` (every method of ``compare``'s
  defaults: the tuned presets, the authors' settings, both SC-MPC forms, the shipped PPO
  agents; 10 seeds) flown as Ray tasks on an embedded Ray with 1 CPU, then (a new Ray)
  with 2 CPUs (``--cpus``), then (``--rounds 2``, the default) with 2 and 1 again, so
  that a drift of the machine's load meets both alike; the wall time of the flights,
  Ray's start excluded, summed per CPU count, and the ratio. The two runs' ``results.json`` content is compared too (it must be identical).
* **the machine's own speed-up** at the same time, without Ray: equal pieces of
  pure-Python work in one process, then in two (a machine shared with other work may
  not give a second core's worth; this says how much of the speed-up there was to get).
* **overhead per flight**: one flight (SC-MPC on the sweep, seed 0) flown in this
  process and as a Ray task on a warm worker (Ray started, the worker's imports done by
  a first task), each ``--repeats`` times, interleaved; the overhead is the difference of
  the medians.
  The first task on a fresh worker (process start and imports) is reported too, and
  Ray's cost per task alone: the same difference for a 20-step flight.

Prints a table and writes ``OUT/bench_ray.json``. Figures depend on the machine's load:
``uptime``'s load average is printed with them.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path
from typing import Any

from wall_env.validation import check_output_folder

TARGETS = {"speedup_2_vs_1": 1.7, "overhead_s": 0.5}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cpus", default="1,2", help="CPU counts of the embedded Ray to compare (default 1,2)")
    parser.add_argument("--seeds", type=int, default=10, help="seeds of Table II (default 10, compare's default)")
    parser.add_argument("--duration", type=float, default=None, help="shorten every flight (s; default: the task's)")
    parser.add_argument("--repeats", type=int, default=9, help="repetitions of the single flight (default 9)")
    parser.add_argument("--skip-speedup", action="store_true", help="measure the overhead only")
    parser.add_argument("--rounds", type=int, choices=(1, 2), default=2,
                        help="2 (default): fly Table II with 1, 2, 2, 1 CPUs and compare the sums; 1: with 1, then 2")
    parser.add_argument("--out", default="out/bench-ray", help="folder for bench_ray.json")
    parser.add_argument("--plan", metavar="TIMING.json", default=None,
                        help="instead of measuring: estimate the wall time of the flights of a compare --ray run "
                             "(its timing.json) and of a training sweep on --machines machines")
    parser.add_argument("--machines", default="1,4,16", help="with --plan: machine counts (default 1,4,16)")
    parser.add_argument("--cpus-per-machine", type=int, default=2, help="with --plan: CPUs of a machine (default 2)")
    parser.add_argument("--trial-card", default=None, metavar="MODEL_CARD.json",
                        help="with --plan: the model card of a training run, whose measured wall time is the sweep's "
                             "per-run time (e.g. agents/pretrained/wall_sweep/model_card.json)")
    parser.add_argument("--trials", type=int, default=10, help="with --plan: training runs of the sweep (default 10)")
    parser.add_argument("--cpus-per-trial", type=int, default=2,
                        help="with --plan: CPUs a training run reserves (default 2, train's n_workers)")


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def _spin(_: int) -> float:
    """A fixed amount of pure-Python work; its seconds."""
    t0 = time.perf_counter()
    x = 0
    for i in range(3_000_000):
        x += i * i
    return time.perf_counter() - t0


def _warm_worker() -> None:
    """Import what flights need (a Ray task on each worker before timing), and hold the worker a moment so
    that the other warm-up tasks go to the other workers."""
    import agents.policy  # noqa: F401  (PPO: torch, Stable-Baselines3)
    import controllers.paper_tables  # noqa: F401

    time.sleep(1.0)


def _machine_speedup(jobs: int = 8) -> dict[str, Any]:
    """What this machine gives right now: ``jobs`` equal pieces of work in 1 process, then in 2 (no Ray)."""
    import multiprocessing

    t0 = time.perf_counter()
    for i in range(jobs):
        _spin(i)
    one = time.perf_counter() - t0
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        pool.map(_spin, range(2))  # start-up out of the timing
        t0 = time.perf_counter()
        pool.map(_spin, range(jobs), chunksize=1)
        two = time.perf_counter() - t0
    return {"one_process_s": round(one, 3), "two_processes_s": round(two, 3), "speedup": round(one / two, 3)}


def _table_ii(seeds: int, duration: float | None) -> tuple[list[Any], dict[str, Any]]:
    import dataclasses

    from controllers import paper_tables as pt
    from wall_inspector.compare import _ppo_policies

    extra = {} if duration is None else {"duration": duration}
    scenarios = [dataclasses.replace(s, seeds=tuple(range(seeds)), env_kwargs={**s.env_kwargs, **extra})
                 for s in pt.TABLE_II]
    policies = pt.controller_policies("tuned")
    policies.update(pt.controller_policies("paper", label_suffix=pt.AUTHORS, dynamics_only=False))
    policies.update(_ppo_policies(scenarios[0].env_id, residual=True))
    return scenarios, policies


def _speedup(cpu_counts: list[int], seeds: int, duration: float | None, rounds: int = 2) -> dict[str, Any]:
    from controllers import paper_tables as pt
    from wall_inspector import ray_backend

    scenarios, policies = _table_ii(seeds, duration)
    runs: list[dict[str, Any]] = []
    contents = []
    order = list(cpu_counts) + list(reversed(cpu_counts)) if rounds == 2 else list(cpu_counts)
    for cpus in order:  # with two rounds A B B A: a drift of the machine's load meets both alike
        with ray_backend.session(ray_backend.LOCAL, cpus) as ray:
            # Ray's start is not the flights': every worker imports what a flight needs before the clock starts
            warm = ray.remote(num_cpus=ray_backend.CPUS_PER_FLIGHT)(_warm_worker)
            ray.get([warm.remote() for _ in range(cpus)])
            t0 = time.perf_counter()
            executor = ray_backend.flight_executor()
            results = pt.run_scenarios(scenarios, policies, progress=False, executor=executor)
            seconds = time.perf_counter() - t0
        flights = sum(len(r.evaluation.episodes) for r in results)
        runs.append({"cpus": cpus, "flights": flights, "wall_time_s": round(seconds, 2),
                     "s_per_flight": round(seconds / flights, 3), "load_after": _load(),
                     # the flights' own seconds on their workers, summed: / wall time = flights flown at once
                     "flight_seconds_sum": round(sum(executor.seconds), 2)})
        contents.append(json.dumps(pt.results_json(results), sort_keys=True, default=float))
        print(f"{cpus} CPU(s): {flights} flights in {seconds:.1f} s, {sum(executor.seconds) / seconds:.2f} flying at "
              f"once on average, {sum(executor.seconds) / flights:.2f} s per flight on its worker (load {_load()})",
              flush=True)
    out: dict[str, Any] = {"runs": runs, "identical_results": len(set(contents)) == 1}
    totals = {c: sum(r["wall_time_s"] for r in runs if r["cpus"] == c) for c in cpu_counts}
    out["wall_time_s"] = {str(c): round(t, 2) for c, t in totals.items()}
    if len(cpu_counts) >= 2:
        out["speedup"] = round(totals[cpu_counts[0]] / totals[cpu_counts[-1]], 3)
    return out


def _local_and_remote_times(fly: Any, remote_fly: Any, flight: Any, repeats: int) -> tuple[list[float], list[float]]:
    """Seconds of ``repeats`` flights in this process and as Ray tasks, interleaved, so that a change
    of the machine's load meets both alike."""
    import ray

    local, remote = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fly(flight)
        local.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ray.get(remote_fly.remote(flight))
        remote.append(time.perf_counter() - t0)
    return local, remote


def _overhead(repeats: int, duration: float | None) -> dict[str, Any]:
    import dataclasses

    import ray

    from controllers import paper_tables as pt
    from wall_inspector import ray_backend

    scenarios, policies = _table_ii(1, duration)
    flight = pt.Flight(scenarios[0], "SC-MPC", policies["SC-MPC"], 0)
    steps = len(pt.fly(flight).time)  # warm: compiled code loaded, caches filled
    with ray_backend.session(ray_backend.LOCAL, 1):
        remote_fly = ray.remote(num_cpus=ray_backend.CPUS_PER_FLIGHT)(pt.fly)
        t0 = time.perf_counter()
        ray.get(remote_fly.remote(flight))
        cold = time.perf_counter() - t0
        local, remote = _local_and_remote_times(pt.fly, remote_fly, flight, repeats)
        short_scenario = dataclasses.replace(scenarios[0], env_kwargs={**scenarios[0].env_kwargs, "duration": 0.2})
        short = pt.Flight(short_scenario, "SC-MPC", policies["SC-MPC"], 0)
        short_local, short_remote = _local_and_remote_times(pt.fly, remote_fly, short, repeats)
    local_s, remote_s = statistics.median(local), statistics.median(remote)
    fixed_s = statistics.median(short_remote) - statistics.median(short_local)
    return {"flight": "SC-MPC, WallSweep-v0, seed 0", "steps": steps,
            "local_median_s": round(local_s, 4), "ray_median_s": round(remote_s, 4),
            "overhead_s": round(remote_s - local_s, 4), "first_task_s": round(cold, 3),
            "first_task_overhead_s": round(cold - local_s, 3), "repeats": repeats,
            "fixed_cost_s": round(fixed_s, 4)}  # the same for a 20-step flight: Ray's cost per task


def makespan(seconds: list[float], slots: int) -> float:
    """Wall time of jobs of ``seconds`` each on ``slots`` equal workers, started in the given order as
    workers free up (Ray's way with tasks submitted at once)."""
    import heapq

    free = [0.0] * max(1, slots)
    for s in seconds:
        heapq.heapreplace(free, free[0] + s)
    return max(free)


def plan(args: argparse.Namespace) -> int:
    """``--plan``: the estimates of the README from measured per-flight and per-trial times."""
    try:
        machines = [int(m) for m in args.machines.split(",") if m.strip()]
        if not machines or any(m < 1 for m in machines):
            raise ValueError
    except ValueError:
        raise SystemExit(f"--machines must be machine counts such as 1,4,16; got {args.machines!r}") from None
    if not 1 <= args.cpus_per_machine <= 4096 or not 1 <= args.cpus_per_trial <= args.cpus_per_machine:
        raise SystemExit("--cpus-per-machine must be in [1, 4096] and --cpus-per-trial in [1, --cpus-per-machine]")
    try:
        timing = json.loads(Path(args.plan).read_text())
        seconds = [float(s) for s in timing["flights"]["seconds_each"]]
    except (OSError, ValueError, KeyError, TypeError):
        raise SystemExit(f"--plan {args.plan}: not the timing.json of a compare --ray run (flights.seconds_each)") \
            from None
    trial_minutes = None
    if args.trial_card is not None:
        from agents.checkpoints import training_env_steps

        try:
            training = json.loads(Path(args.trial_card).read_text())["training"]
            trial_minutes = float(training["total_wall_time_s"]) / 60
            trial_steps = training_env_steps(training)  # a warm start's demonstrations included
        except (OSError, ValueError, KeyError, TypeError):
            raise SystemExit(f"--trial-card {args.trial_card}: not a model card (training.total_wall_time_s)") from None
    lines = [f"| machines | CPUs | all flights of `compare` (min) | the same, one flight at a time per machine (min) | "
             f"{args.trials}-run training sweep (min) |", "|---:|---:|---:|---:|---:|"]
    rows = []
    for m in machines:
        flights_s = makespan(seconds, m * args.cpus_per_machine)
        row = {"machines": m, "cpus": m * args.cpus_per_machine, "flights_min": round(flights_s / 60, 2),
               "flights_one_per_machine_min": round(makespan(seconds, m) / 60, 2)}
        if trial_minutes is not None:
            per_machine = args.cpus_per_machine // args.cpus_per_trial
            row["sweep_min"] = round(makespan([trial_minutes] * args.trials, m * per_machine), 1)
        rows.append(row)
        sweep = f"{row['sweep_min']:.0f}" if "sweep_min" in row else "-"
        lines.append(f"| {m} | {row['cpus']} | {row['flights_min']:.1f} | {row['flights_one_per_machine_min']:.1f} | "
                     f"{sweep} |")
    note = (f"\nFrom {len(seconds)} flights measured by `compare --ray` ({sum(seconds) / 60:.1f} min of flying in all, "
            f"longest flight {max(seconds):.1f} s): each column is the list-scheduling makespan of the measured "
            f"per-flight times on machines x {args.cpus_per_machine} CPUs, one flight per CPU, in the order compare "
            "submits them (`wall-inspector bench-ray --plan`); the next column as if a machine flew one flight at a time "
            "(machines whose second CPU other work keeps busy: `bench-ray`'s control row tells how much of it a machine "
            "gives). "
            "Ray's start and per-flight overhead are not included")
    if trial_minutes is not None:
        note += (f"; the sweep is {args.trials} training runs of {trial_minutes:.1f} min each ({trial_steps:,} env steps: "
                 f"the measured wall time in `{args.trial_card}`), {args.cpus_per_trial} CPUs per run, so "
                 f"{args.cpus_per_machine // args.cpus_per_trial} run(s) at a time per machine")
    lines.append(note + ".")
    text = "\n".join(lines) + "\n"
    print(text)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "plan.md").write_text(text)
    print(f"wrote {out / 'plan.md'}")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.plan is not None:
        return plan(args)
    try:
        cpu_counts = [int(c) for c in args.cpus.split(",") if c.strip()]
        if not cpu_counts or any(not 1 <= c <= 4096 for c in cpu_counts):
            raise ValueError
    except ValueError:
        raise SystemExit(f"--cpus must be CPU counts in [1, 4096] such as 1,2; got {args.cpus!r}") from None
    if not 1 <= args.seeds <= 1000:
        raise SystemExit(f"--seeds must be in [1, 1000], got {args.seeds}")
    if not 1 <= args.repeats <= 100:
        raise SystemExit(f"--repeats must be in [1, 100], got {args.repeats}")
    if args.duration is not None and not 0.05 <= args.duration <= 3600:
        raise SystemExit(f"--duration must be in [0.05, 3600] s, got {args.duration}")
    try:
        out = check_output_folder(args.out)
    except ValueError as exc:
        raise SystemExit(str(exc)) from None
    try:
        import ray  # noqa: F401
    except ImportError:
        raise SystemExit('bench-ray needs Ray: pip install "wall-inspector[ray]"') from None

    figures: dict[str, Any] = {"machine": f"{os.cpu_count()} CPUs", "load_before": _load()}
    print(f"load average before: {figures['load_before']}", flush=True)
    figures["overhead"] = _overhead(args.repeats, args.duration)
    o = figures["overhead"]
    print(f"one flight ({o['steps']} steps): {o['local_median_s']:.3f} s in this process, {o['ray_median_s']:.3f} s as a "
          f"Ray task on a warm worker: overhead {o['overhead_s']:.3f} s (target <= {TARGETS['overhead_s']} s); "
          f"first task on a new worker {o['first_task_s']:.2f} s", flush=True)
    print(f"a 20-step flight: Ray's cost per task {o['fixed_cost_s']:.3f} s", flush=True)
    if not args.skip_speedup:
        figures["machine_speedup"] = _machine_speedup()
        m = figures["machine_speedup"]
        print(f"the machine itself, no Ray: the same pure-Python work in 1 process {m['one_process_s']:.2f} s, in 2 "
              f"{m['two_processes_s']:.2f} s: {m['speedup']:.2f}x", flush=True)
        figures["speedup"] = _speedup(cpu_counts, args.seeds, args.duration, args.rounds)
        s = figures["speedup"]
        if "speedup" in s:
            first, last = cpu_counts[0], cpu_counts[-1]
            print(f"Table II ({s['runs'][0]['flights']} flights, each CPU count {args.rounds} time(s)): "
                  f"{s['wall_time_s'][str(first)]:.1f} s with {first} CPU, {s['wall_time_s'][str(last)]:.1f} s with "
                  f"{last}: speed-up {s['speedup']:.2f}x (target >= {TARGETS['speedup_2_vs_1']}x); identical results: "
                  f"{s['identical_results']}")
    figures["load_after"] = _load()
    print(f"load average after: {figures['load_after']}")
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_ray.json").write_text(json.dumps(figures, indent=2))
    (out / "bench_ray.md").write_text(_markdown(figures))
    print(f"wrote {out / 'bench_ray.json'} and {out / 'bench_ray.md'}")
    return 0


def _markdown(figures: dict[str, Any]) -> str:
    o = figures["overhead"]
    lines = ["| figure | measured | target |", "|---|---:|---:|"]
    s = figures.get("speedup")
    if s and "speedup" in s:
        counts = list(s["wall_time_s"])
        first = s["runs"][0]
        times = " + ".join(f"{r['wall_time_s']:.0f} s ({r['cpus']})" for r in s["runs"])
        at_once = ", ".join(f"{r['flight_seconds_sum'] / r['wall_time_s']:.2f} ({r['cpus']})" for r in s["runs"]
                            if "flight_seconds_sum" in r)
        per_flight = ", ".join(f"{r['flight_seconds_sum'] / r['flights']:.2f} s ({r['cpus']})" for r in s["runs"]
                               if "flight_seconds_sum" in r)
        lines.append(f"| Table II, {first['flights']} flights per run, runs in this order (CPUs) | {times} | |")
        lines.append(f"| wall time with {counts[0]} CPU / {counts[-1]} CPUs (sums) | {s['wall_time_s'][counts[0]]:.0f} s / "
                     f"{s['wall_time_s'][counts[-1]]:.0f} s | |")
        lines.append(f"| speed-up | {s['speedup']:.2f}x | >= {TARGETS['speedup_2_vs_1']}x |")
        if at_once:
            lines.append(f"| flights flying at once on average (CPUs), and a flight's seconds on its worker | {at_once}; "
                         f"{per_flight} | |")
        lines.append(f"| same results.json content with {counts[0]} and {counts[-1]} CPUs | "
                     f"{'yes' if s['identical_results'] else 'NO'} | yes |")
    lines.append(f"| one flight ({o['steps']} steps): in this process / as a Ray task on a warm worker (median of "
                 f"{o['repeats']}) | {o['local_median_s']:.3f} s / {o['ray_median_s']:.3f} s | |")
    lines.append(f"| Ray's overhead per flight | {o['overhead_s']:.3f} s | <= {TARGETS['overhead_s']} s |")
    lines.append(f"| Ray's cost per task (the same for a 20-step flight) | {o['fixed_cost_s']:.3f} s | |")
    lines.append(f"| first task on a new worker (process start and imports included) | {o['first_task_s']:.2f} s | |")
    m = figures.get("machine_speedup")
    if m:
        lines.append(f"| control, no Ray: the same pure-Python work in 1 process / 2 processes | {m['one_process_s']:.2f} s"
                     f" / {m['two_processes_s']:.2f} s ({m['speedup']:.2f}x) | |")
    return ("\n".join(lines) + f"\n\nMeasured by `wall-inspector bench-ray` on {figures['machine']}, with load "
            f"averages {figures['load_before']} before and {figures['load_after']} after (1, 5, 15 min): the machine "
            "was shared with other work, which depresses the speed-up.\n")
