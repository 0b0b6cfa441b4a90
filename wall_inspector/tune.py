"""``wall-inspector tune``: tune a controller's gains or weights on a task within a stated budget.

Examples::

    wall-inspector tune --env WallSweep-v0 --method scmpc                  # default budget: 50 trials, <= 20 min
    wall-inspector tune --env WallSweep-v0 --method pid --budget-trials 20 --out runs/tune-pid
    wall-inspector tune --objective paper-table-i --set standoff=0.15       # the paper-sim preset
    wall-inspector tune --env WallSweep-v0 --method scmpc --conditions realistic   # ideal and realistic flights

The study (Optuna, seeded TPE, :mod:`controllers.tuning`) is stored in
``OUT/study.db``; Ctrl-C stops it and the same command resumes it. When the budget is
spent the best settings fly the held-out seeds, and ``OUT/preset.yaml`` (a preset with
its provenance: task, seeds, budget, objective values, command, commit) and
``OUT/report.json`` are written; ``--ship`` also copies the preset to
``controllers/presets/tuned/<task>_<method>.yaml`` (``paper-sim.yaml`` for the Table I
objective), where ``from_env`` and ``compare`` find it.

``--ray [ADDRESS]`` runs the same study through Ray Tune's Optuna searcher, trials side
by side on this machine or a cluster (:mod:`wall_inspector.tune_on_ray`).
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import sys
from pathlib import Path
from typing import Any

_DEFAULT_TRAIN_SEEDS = "1000-1002"
_DEFAULT_HELDOUT_SEEDS = "2000-2009"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default="WallInspector/WallSweep-v0",
                        help="task to tune on (env id or task name; default WallSweep-v0)")
    parser.add_argument("--method", choices=("pid", "mpc", "scmpc"),
                        help="controller to tune (required for the tracking objective)")
    parser.add_argument("--objective", choices=("tracking", "paper-table-i"), default="tracking",
                        help="tracking: wall-normal RMSE + contact and effort prices on the task (default); "
                             "paper-table-i: MPC/SC-MPC sigmas that reproduce the paper's Table I")
    parser.add_argument("--budget-trials", type=int, default=50, help="trials of the whole study (default 50)")
    parser.add_argument("--budget-minutes", type=float, default=20.0,
                        help="wall-time budget of the whole study in minutes (default 20; 0 for none)")
    parser.add_argument("--seeds", default=_DEFAULT_TRAIN_SEEDS, help="training seeds, e.g. 1000-1002 or 1,2,3")
    parser.add_argument("--heldout-seeds", default=_DEFAULT_HELDOUT_SEEDS,
                        help="seeds the result is reported on (must differ from --seeds)")
    parser.add_argument("--horizon-steps", default="",
                        help="MPC horizon lengths N to choose from, e.g. 10,20,30 (default: keep N = 20)")
    parser.add_argument("--fixed-dt", action="store_true", help="keep the MPC step dt = 0.01 s (default: tune it)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="environment keyword, e.g. k_s=10 or standoff=0.14 (repeatable)")
    parser.add_argument("--conditions", default="", metavar="PROFILE[,PROFILE]",
                        help="also fly every seed under these flight-condition profiles (e.g. realistic: sensing "
                             "error, latency, motor lag, turbulence) and average the cost over all flights")
    parser.add_argument("--sampler-seed", type=int, default=0, help="seed of the TPE sampler (default 0)")
    parser.add_argument("--start", action="append", default=[], metavar="PRESET",
                        help="also fly this preset's settings first (a name or file; repeatable); the authors' "
                             "settings are always the first trial")
    parser.add_argument("--out", default=None, help="run folder (default runs/tune/<task>_<method>)")
    parser.add_argument("--ship", action="store_true", help="copy the preset into controllers/presets")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    from wall_inspector import ray_backend

    ray_backend.add_arguments(parser, "every trial is a Ray Tune trial, searched by Ray Tune's Optuna searcher")
    parser.add_argument("--cpus-per-trial", type=float, default=1.0,
                        help="with --ray: CPUs Ray reserves for each trial (default 1: a trial flies one flight at a time)")


def parse_seeds(text: str, option: str) -> list[int]:
    """``"1000-1002"`` or ``"1,2,5"`` (or a mix) to a list of seeds; ``ValueError`` naming ``option``."""
    seeds: list[int] = []
    try:
        for part in filter(None, (p.strip() for p in text.split(","))):
            if "-" in part[1:]:
                low, high = part.split("-", 1) if not part.startswith("-") else (part, part)
                low_i, high_i = int(low), int(high)
                if high_i < low_i or high_i - low_i > 10000:
                    raise ValueError
                seeds += list(range(low_i, high_i + 1))
            else:
                seeds.append(int(part))
    except ValueError:
        raise ValueError(f"{option} must be seeds such as 1000-1002 or 1,2,3, got {text!r}") from None
    if not seeds or any(s < 0 for s in seeds):
        raise ValueError(f"{option} must name at least one non-negative seed, got {text!r}")
    return seeds


def recorded_command(arguments: list[str]) -> str:
    """The command line as a preset's provenance records it: absolute paths (this machine's
    folders) shortened to their file names, relative ones kept."""
    return " ".join(["wall-inspector", "tune", *(shlex.quote(Path(a).name if Path(a).is_absolute() else a)
                                                 for a in arguments)])


def _env_kwargs(items: list[str]) -> dict:
    import yaml

    out = {"noise": True, "terminate_on_collision": False}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--set takes KEY=VALUE, got {item!r}")
        try:
            out[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError:
            raise ValueError(f"--set {key}: cannot read the value {value!r}") from None
    return out


def _conditions(text: str, objective: str, env_kwargs: dict) -> list[str]:
    """``--conditions``: profile names, checked against :data:`wall_env.conditions.PROFILES`."""
    from wall_env.conditions import PROFILES

    names = [c.strip() for c in text.split(",") if c.strip()]
    allowed = sorted(set(PROFILES) - {"ideal"})
    for name in names:
        if name not in allowed:
            raise ValueError(f"--conditions takes flight-condition profiles of {allowed}, got {name!r}")
    if names and objective != "tracking":
        raise ValueError("--conditions applies to the tracking objective")
    if names and "conditions" in env_kwargs:
        raise ValueError("give the flight conditions either as --set conditions=... (every flight) or as "
                         "--conditions (flown besides the task's world), not both")
    if len(set(names)) != len(names):
        raise ValueError(f"--conditions names a profile twice: {text!r}")
    return names


def run(args: argparse.Namespace) -> int:
    import gymnasium as gym

    import wall_env  # noqa: F401  (registers the environments)
    from controllers.presets import load_preset
    from controllers.tuning import SearchSpace, Tuner, default_objective
    from wall_env.tasks import task_env_id, task_slug
    from wall_env.validation import check_output_folder

    # ---------------------------------------------------------- every argument checked before any work
    try:
        if args.objective == "paper-table-i":
            env_id, method = "WallInspector/WallCircle-v0", "mpc+scmpc"
        else:
            if args.method is None:
                raise ValueError("--method is required for the tracking objective (pid, mpc or scmpc)")
            env_id, method = task_env_id(args.env), args.method
        train = parse_seeds(args.seeds, "--seeds")
        heldout = parse_seeds(args.heldout_seeds, "--heldout-seeds")
        if set(train) & set(heldout):
            raise ValueError(f"--heldout-seeds must differ from --seeds; both have {sorted(set(train) & set(heldout))}")
        if not 1 <= args.budget_trials <= 100000:
            raise ValueError(f"--budget-trials must be in [1, 100000], got {args.budget_trials}")
        if not 0 <= args.budget_minutes <= 100000:
            raise ValueError(f"--budget-minutes must be in [0, 100000] (0 for no limit), got {args.budget_minutes}")
        try:
            steps = [int(n) for n in args.horizon_steps.split(",") if n.strip()] if args.horizon_steps else []
        except ValueError:
            raise ValueError(f"--horizon-steps takes whole numbers of steps separated by commas, e.g. 15,20,30; "
                             f"got {args.horizon_steps!r}") from None
        if method == "pid" and (steps or args.fixed_dt):
            raise ValueError("--horizon-steps and --fixed-dt apply to the MPCs, not to pid")
        env_kwargs = _env_kwargs(args.set)
        conditions = _conditions(args.conditions, args.objective, env_kwargs)
        probe = gym.make(env_id, **env_kwargs)  # the env's own checks name a bad keyword and its range
        probe.close()
        space_method = "mpc" if method == "mpc+scmpc" else method
        space = SearchSpace(space_method, load_preset("paper", method=space_method).methods[space_method],
                            tune_dt=not args.fixed_dt, horizon_steps=tuple(steps))
        for start in args.start:
            load_preset(start, method=space_method)
        slug = "paper_table_i" if method == "mpc+scmpc" else f"{task_slug(env_id)}_{method}"
        out = check_output_folder(Path(args.out) if args.out else Path("runs") / "tune" / slug)
        from wall_inspector import ray_backend

        ray_backend.check_arguments(args)
        if not 0.01 <= args.cpus_per_trial <= 1024:
            raise ValueError(f"--cpus-per-trial must be in [0.01, 1024], got {args.cpus_per_trial}")
    except (ValueError, TypeError) as exc:
        raise SystemExit(str(exc)) from None  # one line, exit status 2 (wall_inspector.cli)

    command = recorded_command(sys.argv[2:]) if len(sys.argv) > 1 and sys.argv[1] == "tune" \
        else f"wall-inspector tune --env {env_id} --method {method}"
    objective = default_objective(args.objective, env_id, method, train, env_kwargs, conditions=conditions)
    tuner = Tuner(objective, heldout, out, budget_trials=args.budget_trials,
                  budget_minutes=args.budget_minutes or None, seed=args.sampler_seed, space=space, command=command,
                  progress=not args.no_progress, start=args.start)
    from wall_inspector.cli import lock_run_folder

    lock = lock_run_folder(out, "wall-inspector tune")  # a second run into the folder refuses, naming this one
    try:
        tuner.open_study()  # a folder holding another method's or objective's study is refused here
    except ValueError as exc:
        lock.release()
        raise SystemExit(str(exc)) from None
    try:
        return _tune(args, tuner, out, env_id, method, heldout, ray_backend)
    finally:
        lock.release()


def _tune(args: argparse.Namespace, tuner: Any, out: Path, env_id: str, method: str, heldout: list[int],
          ray_backend: Any) -> int:
    from controllers.presets import PRESET_DIR, tuned_preset_path

    try:
        if args.ray is None:
            result = tuner.run()
        else:
            from wall_inspector import tune_on_ray

            with ray_backend.session(args.ray, args.ray_cpus):
                result = tune_on_ray.run(tuner, cpus_per_trial=args.cpus_per_trial, progress=not args.no_progress)
    except (KeyboardInterrupt, Exception) as exc:
        from wall_env import interrupts

        if not interrupts.is_interrupt(exc):  # a real error; one raised after Ctrl-C is the interrupt's
            raise
        print(f"\ninterrupted: the study is stored in {out / 'study.db'}; run the same command again to resume",
              file=sys.stderr)
        return 130
    used = result.preset.provenance["used"]
    print(f"{method} on {env_id}: best training objective {result.train_value:.4g}; held-out seeds "
          f"{heldout[0]}..{heldout[-1]}: {result.heldout.value:.4g} (the authors' settings: "
          f"{result.baseline_heldout.value:.4g})")
    print(f"budget used: {used['trials']} trials, {used['env_steps']:,} env steps, {used['wall_time_s'] / 60:.1f} min")
    print(f"wrote {result.paths['preset']} and {result.paths['report']}")
    if args.ship:
        target = PRESET_DIR / "paper-sim.yaml" if method == "mpc+scmpc" else tuned_preset_path(env_id, method)
        shutil.copyfile(result.paths["preset"], target)
        print(f"shipped {target}")
    return 0
