"""``wall-inspector train``: train an agent on a wall task (:mod:`agents.train`), and ``--ray`` for several runs at once.

::

    wall-inspector train --env WallInspector/WallSweep-v0 --timesteps 3000000 --n-envs 16 --seed 0 --out runs/sweep
    wall-inspector train --resume runs/sweep --timesteps 4000000     # continue to 4M steps
    wall-inspector train --env WallHover-v0 --residual pid --randomize --out runs/hover_res

The configuration comes from ``agents/configs/<task>.yaml`` (or ``--config FILE``), changed by
the flags and ``--set key=value``; every argument is checked before the run folder or any worker
exists, and a bad one stops the command with one line and exit status 2. The run itself is
:func:`agents.train.train` (its docstring says what it writes); Ctrl-C saves a checkpoint and
prints the ``--resume`` line. ``--ship`` copies the best checkpoint into ``agents/pretrained/``.

With ``--ray [ADDRESS]`` each training run is a Ray Tune trial (:mod:`wall_inspector.train_on_ray`):
one per seed of ``--seeds 0-9``, one per point of the grid of ``--sweep SPACE.yaml``, or both crossed.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from agents import train as agents_train
from agents.config import load_config, validate_config
from agents.train import TrainingInterrupted, _latest_checkpoint, card_written, check_observations, planned_timesteps, ship, train
from wall_env.validation import check_output_folder
from wall_inspector.train_arguments import _command, _config_from_args, _training_arguments


def _usage(args: argparse.Namespace) -> tuple[dict[str, Any], Path]:
    """The configuration and run folder the arguments ask for; ``ValueError`` for anything
    unusable, before any folder or process exists."""
    config, out = _resumed_run(args) if args.resume else _new_run(args)
    if args.ship:
        git = agents_train.git_state()  # looked up at call time (tests replace it)
        if git is not None and git["uncommitted"]:
            raise ValueError(f"--ship records the git commit in the model card, but {', '.join(git['uncommitted'])} "
                             "differ from it; commit first (or train without --ship and ship a clean run)")
    return config, out


def _resumed_run(args: argparse.Namespace) -> tuple[dict[str, Any], Path]:
    """The saved configuration of ``--resume DIR``, with the flags a resumed run may change."""
    run_dir = Path(args.resume)
    if not (run_dir / "config.yaml").is_file():
        raise ValueError(f"cannot resume: {run_dir / 'config.yaml'} does not exist")
    changing = [flag for flag, value in (("--env", args.env), ("--config", args.config), ("--n-envs", args.n_envs),
                                         ("--algo", args.algo),
                                         ("--seed", args.seed), ("--randomize", args.randomize),
                                         ("--residual", args.residual), ("--warm-start", args.warm_start),
                                         ("--set", args.set or None),
                                         ("--out", args.out)) if value is not None]
    if changing:
        raise ValueError(f"--resume continues the saved configuration; drop {', '.join(changing)}")
    config = load_config(run_dir / "config.yaml", validate=False)
    if _stopped_before_first_checkpoint(run_dir):  # nothing to continue: the saved configuration starts again
        for key, value in (("timesteps", args.timesteps), ("n_workers", args.workers),
                           ("checkpoint_freq", args.checkpoint_freq), ("checkpoint_minutes", args.checkpoint_minutes)):
            if value is not None:
                config[key] = value
        validate_config(config)
        planned_timesteps(config)
        return config, run_dir
    if config.get("algo") == "dagger":
        raise ValueError(f"{run_dir} holds a distilled agent (algo dagger): it has no PPO steps to continue; "
                         "train a new run")
    for key, value in (("timesteps", args.timesteps), ("n_workers", args.workers),
                       ("checkpoint_freq", args.checkpoint_freq), ("checkpoint_minutes", args.checkpoint_minutes)):
        if value is not None:
            config[key] = value
    validate_config(config)
    from agents.checkpoints import read_json

    start = _latest_checkpoint(run_dir)
    planned_timesteps(config, int(read_json(start / "policy.json").get("num_timesteps", 0)),
                      unfinished=not card_written(run_dir))
    return config, run_dir


def _new_run(args: argparse.Namespace) -> tuple[dict[str, Any], Path]:
    """The configuration of a new run from the flags, and its (creatable) folder."""
    if not args.out:
        raise ValueError("--out is required (the run folder)")
    out = Path(args.out)
    config = _config_from_args(args)
    if (out / "config.yaml").exists():
        if not _stopped_before_first_checkpoint(out):
            raise ValueError(f"{out} already holds a run; continue it with --resume {out} or choose another --out")
        saved = load_config(out / "config.yaml", validate=False)
        if saved != config:
            raise ValueError(f"{out} holds a run with another configuration that stopped before its first checkpoint; "
                             "choose another --out, or delete the folder to start there afresh")
    planned_timesteps(config)
    check_output_folder(out, "--out")
    return config, out


# what a run writes before its first checkpoint; all of it is the run's own, remade when it starts again
_EARLY_FILES = ("config.yaml", "tb", "eval", "best", "checkpoints", "demonstrations")


def _stopped_before_first_checkpoint(run_dir: Path) -> bool:
    """``run_dir`` holds a run (its ``config.yaml``) that ended, by Ctrl-C or a crash, before it saved any
    model: nothing to continue, so the same command (or ``--resume``) starts it again."""
    from agents.checkpoints import CheckpointNotFoundError

    if not (run_dir / "config.yaml").is_file():
        return False
    try:
        _latest_checkpoint(run_dir)
    except CheckpointNotFoundError:
        return True
    return False


def _clear_early_files(run_dir: Path) -> None:
    import shutil

    for name in _EARLY_FILES:
        path = run_dir / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()


def run_single(args: argparse.Namespace) -> int:
    """One training run (:func:`agents.train.train`) from the arguments, its figures printed; the run folder
    is locked for as long as the run lasts (a second run into it refuses, naming this one)."""
    from wall_inspector.cli import lock_run_folder

    folder = args.resume or args.out
    try:
        if folder:
            check_output_folder(Path(folder), "--resume" if args.resume else "--out")
    except ValueError as exc:
        raise SystemExit(str(exc)) from None
    # a folder in use is refused first; a new folder is created (by its lock) only once every setting is checked
    lock = lock_run_folder(folder, "wall-inspector train") if folder and Path(folder).exists() else None
    try:
        try:
            config, out = _usage(args)
            checks = check_observations(config)  # builds the env once: settings it refuses stop the command here
            if config["randomize"]:  # and once with the randomisation ranges
                from agents.envs import make_env

                make_env(config, monitor=False).close()
        except (ValueError, FileNotFoundError) as exc:
            raise SystemExit(str(exc)) from None
        if folder and lock is None:
            lock = lock_run_folder(folder, "wall-inspector train")
        return _run_single(args, config, out, checks)
    finally:
        if lock is not None:
            lock.release()


def _run_single(args: argparse.Namespace, config: dict[str, Any], out: Path, checks: Any) -> int:
    planned = planned_timesteps(config) if not args.resume else None
    if planned is not None and planned < config["timesteps"]:
        rollout = config["n_envs"] * config["ppo"]["n_steps"]
        print(f"training {planned // rollout} whole PPO rollouts of {rollout} env steps = {planned} of the "
              f"{config['timesteps']} requested", file=sys.stderr)
    restart = _stopped_before_first_checkpoint(out)
    if restart:
        print(f"{out}: the run there stopped before its first checkpoint; starting it again", file=sys.stderr)
        _clear_early_files(out)
    elif args.resume:
        print(f"resuming {out} from its latest checkpoint", file=sys.stderr)
    try:
        result = train(config, out, resume=bool(args.resume) and not restart, progress_bar=not args.no_progress,
                       verbose=0 if args.quiet else 1, command=_command(args, config), checks=checks)
    except TrainingInterrupted as stop:
        print(f"\ninterrupted at {stop.num_timesteps} env steps: model, normalisation statistics and step count saved "
              f"in {stop.checkpoint}; continue with: wall-inspector train --resume {shlex.quote(str(stop.run_dir))} "
              f"--timesteps {config['timesteps']}", file=sys.stderr)
        return 130
    card = result.card
    t, m = card["training"], card["evaluation"]["metrics"]
    print(f"trained {t['timesteps_this_run']} steps in {t['wall_time_s']:.0f} s ({t['steps_per_s']:.0f} env steps/s); "
          f"best checkpoint: return {m['mean_return']:.1f}, completed {m['completed']:.0%}, "
          f"position RMSE {100 * m['position_rmse_m']:.2f} cm, wall-normal RMSE {100 * m['wall_normal_rmse_m']:.2f} cm, "
          f"collisions {m['collisions']}")
    print(f"model card: {out / 'model_card.md'}")
    if args.ship:
        target = ship(out, config["env_id"], config["residual"], config["warm_start"]["controller"],
                      config["teacher"]["controller"] if config["algo"] == "dagger" else None)
        print(f"shipped to {target}")
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from wall_inspector import ray_backend

    _training_arguments(parser)
    ray_backend.add_arguments(parser, "each training run is a Ray Tune trial that resumes from its last checkpoint "
                                      "if its worker dies")
    parser.add_argument("--seeds", default=None, metavar="SEEDS",
                        help="with --ray: one run per seed, e.g. 0-9 or 0,3,7")
    parser.add_argument("--sweep", default=None, metavar="SPACE.yaml",
                        help="with --ray: one run per point of the grid in this YAML file (configuration keys as in "
                             "--set, each with a list of values), e.g. {ppo.learning_rate: [1.0e-4, 3.0e-4]}")
    parser.add_argument("--cpus-per-trial", type=float, default=None,
                        help="with --ray: CPUs Ray reserves for each run, and the most PyTorch threads it takes (default: "
                             "n_workers with --vector subprocess, else the more of torch_threads and rollout_torch_threads "
                             "when set, 1 when they are auto)")
    parser.add_argument("--max-failures", type=int, default=3,
                        help="with --ray: times a run is restarted from its last checkpoint after its worker died "
                             "(default 3)")


def run(args: argparse.Namespace) -> int:
    if args.ray is None:
        for flag, value in (("--seeds", args.seeds), ("--sweep", args.sweep), ("--ray-cpus", args.ray_cpus),
                            ("--cpus-per-trial", args.cpus_per_trial)):
            if value is not None:
                raise SystemExit(f"{flag} needs --ray (several runs as Ray Tune trials)")
        return run_single(args)
    from wall_inspector import train_on_ray

    return train_on_ray.run(args)
