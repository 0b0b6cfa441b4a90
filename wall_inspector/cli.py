"""``wall-inspector``: one command line for every job of the project.

Each subcommand lives in the module that owns its work and exposes
``add_arguments(parser)`` and ``run(args) -> int``; it is imported only when used,
so ``wall-inspector bench-env`` never loads PyTorch.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("wall_inspector.demo", "fly a short rollout near a wall, print what happened and write a picture"),
    "bench-env": ("wall_env.benchmark", "measure environment steps per second and reset time"),
    "bench-mpc": ("controllers.benchmark", "time SC-MPC solves in closed loop against IPOPT on the same problems"),
    "compare": ("wall_inspector.compare", "reproduce the paper's Tables I and II with PID, MPC and SC-MPC (tables, JSON, plots)"),
    "tune": ("wall_inspector.tune", "tune a controller's gains or weights on a task within a budget (Optuna), write a preset"),
    "train": ("agents.train", "train a PPO agent on a wall task (checkpoints, TensorBoard, model card)"),
    "notebooks": ("wall_inspector.notebooks", "run the notebooks top to bottom (and save their outputs)"),
    "readme": ("wall_inspector.readme", "copy result tables written by other commands into README.md"),
    "fly": ("discovery.fly", "record a flight log (CSV + JSON) from the simulator with measurement noise"),
    "bench-discover": ("discovery.benchmark", "time model discovery on a 60 s, 100 Hz flight log"),
    "discover": ("discovery.cli", "find, name and fit what the nominal model misses in flight logs; write a model file"),
}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wall-inspector",
        description="Quadrotor flight near walls: environments, controllers, agents and model discovery.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        parser = _parser()
        if argv and argv[0] not in ("-h", "--help"):
            parser.error(f"unknown command {argv[0]!r}; choose from {', '.join(COMMANDS)}")
        parser.print_help()
        return 0
    name = argv[0]
    module_name, help_text = COMMANDS[name]
    module = importlib.import_module(module_name)
    parser = argparse.ArgumentParser(prog=f"wall-inspector {name}", description=help_text)
    module.add_arguments(parser)
    args = parser.parse_args(argv[1:])
    return int(module.run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
