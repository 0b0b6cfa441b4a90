"""The arguments of ``wall-inspector train``: declared on a parser, turned into a training configuration
(:mod:`agents.config`), and written back as the command that repeats a run. One place for both
:mod:`wall_inspector.train` and its Ray trials (:mod:`wall_inspector.train_on_ray`)."""

from __future__ import annotations

import argparse
import shlex
from typing import Any

from agents.config import apply_overrides, default_config, load_config, task_env_id

__all__ = ["_training_arguments", "_config_from_args", "_command"]


def _training_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", help="task, e.g. WallInspector/WallSweep-v0 (or WallSweep-v0, wall_sweep)")
    parser.add_argument("--algo", choices=["ppo", "dagger"],
                        help="ppo: PPO learns the task from its reward alone (default); dagger: a controller (teacher.controller, "
                             "SC-MPC) is distilled into the network, DAgger-style (settings: teacher.* in the config)")
    parser.add_argument("--timesteps", type=int, help="total env steps (default: the task's config)")
    parser.add_argument("--n-envs", type=int, help="environments in the vector env (default: config, 32)")
    parser.add_argument("--workers", type=int, help="worker processes running them with --vector subprocess "
                                                    "(default: config, 2)")
    parser.add_argument("--vector", choices=["batched", "subprocess"],
                        help="batched: all envs in one batched env in this process (default); subprocess: single envs "
                             "in --workers processes")
    parser.add_argument("--seed", type=int, help="random seed (default: config, 0)")
    parser.add_argument("--out", help="run folder for checkpoints, logs and the model card")
    parser.add_argument("--config", help="YAML configuration instead of agents/configs/<task>.yaml")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a configuration entry, e.g. --set ppo.n_steps=128 (repeatable)")
    parser.add_argument("--randomize", action=argparse.BooleanOptionalAction, default=None,
                        help="draw the config's randomize_ranges per episode: the world (k_s, d_thr, stand-off, mass, ...) "
                             "or, for the sweep, facade and pier, the start time along the path (a curriculum; on in "
                             "their configs)")
    parser.add_argument("--residual", choices=["none", "pid", "scmpc"],
                        help="learn a correction on top of this base controller (default: config, none)")
    parser.add_argument("--warm-start", choices=["none", "pid", "scmpc"],
                        help="before PPO, clone this controller's demonstrations into the policy (behaviour cloning; "
                             "settings: warm_start.* in the config; default: config, none)")
    parser.add_argument("--eval-freq", type=int, help="env steps between evaluations (default: config)")
    parser.add_argument("--eval-episodes", type=int, help="episodes per evaluation (default: config)")
    parser.add_argument("--checkpoint-freq", type=int, help="env steps between checkpoints, 0 = none (default: config)")
    parser.add_argument("--checkpoint-minutes", type=float,
                        help="wall-clock minutes between checkpoints as well, 0 = none (default: config, 10)")
    parser.add_argument("--resume", metavar="DIR", help="continue the run in DIR from its latest checkpoint")
    parser.add_argument("--ship", action="store_true",
                        help="copy the best checkpoint and its model card into agents/pretrained/<task>/")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--quiet", action="store_true", help="no PPO log table on the terminal")




# ---------------------------------------------------------------------- configuration from flags
def _config_from_args(args: argparse.Namespace) -> dict[str, Any]:
    if args.config:
        config = load_config(args.config, validate=False)
        if args.env:
            config["env_id"] = task_env_id(args.env)
        if not config.get("env_id"):
            raise ValueError("--env is needed when the configuration file names no env_id")
    else:
        if not args.env:
            raise ValueError("--env is required (e.g. --env WallInspector/WallSweep-v0)")
        config = default_config(args.env)
    flags = {
        "timesteps": args.timesteps, "n_envs": args.n_envs, "n_workers": args.workers, "seed": args.seed,
        "vector": args.vector, "algo": args.algo,
        "randomize": args.randomize, "checkpoint_freq": args.checkpoint_freq,
        "checkpoint_minutes": args.checkpoint_minutes,
        "residual": None if args.residual == "none" else args.residual,
    }
    for key, value in flags.items():
        if value is not None or (key == "residual" and args.residual == "none"):
            config[key] = value
    if args.warm_start is not None:
        config["warm_start"]["controller"] = None if args.warm_start == "none" else args.warm_start
    if args.eval_freq is not None:
        config["eval"]["freq"] = args.eval_freq
    if args.eval_episodes is not None:
        config["eval"]["episodes"] = args.eval_episodes
    if args.workers is None and isinstance(config["n_envs"], int) and 0 < config["n_envs"] < config["n_workers"]:
        config["n_workers"] = config["n_envs"]
    return apply_overrides(config, args.set)



def _command(args: argparse.Namespace, config: dict[str, Any]) -> str:
    """The command that repeats this run, every setting that matters spelled out."""
    if args.resume:
        parts = ["wall-inspector", "train", "--resume", args.resume, "--timesteps", str(config["timesteps"])]
    else:
        parts = ["wall-inspector", "train", "--env", config["env_id"], "--algo", config["algo"],
                 "--timesteps", str(config["timesteps"]),
                 "--n-envs", str(config["n_envs"]), "--vector", config["vector"], "--workers", str(config["n_workers"]),
                 "--seed", str(config["seed"]), "--out", str(args.out)]
        if args.config:
            parts += ["--config", args.config]
        parts.append("--randomize" if config["randomize"] else "--no-randomize")  # explicit: some tasks default to on
        if config["residual"]:
            parts += ["--residual", config["residual"]]
        if config["warm_start"]["controller"]:
            parts += ["--warm-start", config["warm_start"]["controller"]]
        if args.eval_freq is not None:
            parts += ["--eval-freq", str(args.eval_freq)]
        if args.eval_episodes is not None:
            parts += ["--eval-episodes", str(args.eval_episodes)]
        if args.checkpoint_freq is not None:
            parts += ["--checkpoint-freq", str(args.checkpoint_freq)]
        if args.checkpoint_minutes is not None:
            parts += ["--checkpoint-minutes", str(args.checkpoint_minutes)]
        for item in args.set:
            parts += ["--set", item]
        if args.ship:
            parts.append("--ship")
    return shlex.join(parts)
