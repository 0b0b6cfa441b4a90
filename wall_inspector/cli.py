"""``wall-inspector``: one command line for every job of the project.

Each subcommand lives in a module of this package that exposes ``add_arguments(parser)``
and ``run(args) -> int`` and calls the plain functions of the library packages (wall_env,
controllers, agents, discovery), which parse, print and exit nothing; it is imported only
when used, so ``wall-inspector bench-env`` never loads PyTorch.

Usage errors look the same for every command: one line on stderr,
``wall-inspector COMMAND: error: MESSAGE``, and exit status 2. They come from argparse
(an unknown flag, a value of the wrong type) or from a command's own checks, which a
command signals by raising ``SystemExit("message")`` before it starts its work. Ctrl-C
ends a command with status 130 and no traceback (``train`` saves its state first).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

if TYPE_CHECKING:
    from wall_env.run_lock import RunLock

USAGE_ERROR = 2  # exit status of every usage error (argparse's convention)
INTERRUPTED = 130  # exit status after Ctrl-C (128 + SIGINT)

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("wall_inspector.demo", "fly a short rollout near a wall, print what happened and write a picture"),
    "bench-env": ("wall_inspector.bench_env", "measure environment steps per second and reset time"),
    "bench-mpc": ("wall_inspector.bench_mpc", "time SC-MPC solves in closed loop against IPOPT on the same problems"),
    "compare": ("wall_inspector.compare", "reproduce the paper's Tables I and II with PID, MPC and SC-MPC (tables, JSON, plots)"),
    "robustness": ("wall_inspector.robustness", "fly every method, told only the nominal model, over a grid of true worlds "
                                                "(suction, pushes, gusts, latency, sensing, motor lag)"),
    "bench-ray": ("wall_inspector.bench_ray", "measure compare --ray: speed-up with 2 CPUs over 1, Ray's overhead per flight"),
    "tune": ("wall_inspector.tune", "tune a controller's gains or weights on a task within a budget (Optuna), write a preset"),
    "train": ("wall_inspector.train", "train a PPO agent on a wall task (checkpoints, TensorBoard, model card; --ray: many runs)"),
    "bench-train": ("wall_inspector.bench_train", "time training to the target over several seeds, and its speed beside a busy core"),
    "bench-throughput": ("wall_inspector.bench_throughput", "training env steps per second for several vector-env layouts"),
    "notebooks": ("wall_inspector.notebooks", "run the notebooks top to bottom (and save their outputs)"),
    "readme": ("wall_inspector.readme", "copy result tables written by other commands into README.md"),
    "import-log": ("wall_inspector.import_log", "convert a PX4 ULog or a ROS 2 bag into the project's flight log (CSV + JSON)"),
    "fly": ("wall_inspector.fly", "record a flight log (CSV + JSON) from the simulator with measurement noise"),
    "bench-discover": ("wall_inspector.bench_discover", "time discovery on a 60 s, 100 Hz log; --acceptance: its "
                                                        "accuracy on hidden-effect logs"),
    "discover": ("wall_inspector.discover", "find, name and fit what the nominal model misses in flight logs; write a model file"),
    "export": ("wall_inspector.export", "write a PPO agent as ONNX, or MPC / SC-MPC as C, to fly without this package"),
    "bench-export": ("wall_inspector.bench_export", "time the exported C controller's step (C timing loop) and the ONNX "
                                                    "policy's step on the Table II flight, beside Python's predict"),
}


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (no usage block) and exit status 2."""

    def error(self, message: str) -> NoReturn:
        usage_error(self.prog, f"{message} (see {self.prog} --help)")


def print_usage_error(prog: str, message: str) -> int:
    """Print ``PROG: error: MESSAGE`` as one line on stderr; return the exit status, 2."""
    text = " ".join(str(message).split())  # one line, whatever the message held
    print(f"{prog}: error: {text}", file=sys.stderr)
    return USAGE_ERROR


def usage_error(prog: str, message: str) -> NoReturn:
    """:func:`print_usage_error`, then exit with status 2."""
    raise SystemExit(print_usage_error(prog, message))


def lock_run_folder(folder: str | Path, command: str) -> RunLock:
    """:class:`~wall_env.run_lock.RunLock` of ``folder`` acquired now; a busy folder is a usage error:
    ``SystemExit`` with the one-line message naming the run that holds it."""
    from wall_env.run_lock import RunFolderBusy, RunLock

    try:
        return RunLock(folder, command).acquire()
    except RunFolderBusy as exc:
        raise SystemExit(str(exc)) from None


def _parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
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
            return print_usage_error(parser.prog, f"unknown command {argv[0]!r}; choose from {', '.join(COMMANDS)}")
        parser.print_help()
        return 0
    name = argv[0]
    module_name, help_text = COMMANDS[name]
    prog = f"wall-inspector {name}"
    from wall_env import interrupts

    interrupts.install()  # a Ctrl-C that native code swallows is still seen by the long loops
    try:
        module = importlib.import_module(module_name)  # Ctrl-C while importing is a Ctrl-C too
        parser = OneLineParser(prog=prog, description=help_text)
        module.add_arguments(parser)
        args = parser.parse_args(argv[1:])
        return int(module.run(args) or 0)
    except SystemExit as exit_:
        if isinstance(exit_.code, str):  # a command's own usage check: raise SystemExit("message")
            return print_usage_error(prog, exit_.code)
        if exit_.code == USAGE_ERROR:  # the parser's, already printed as one line
            return USAGE_ERROR
        raise
    except (KeyboardInterrupt, Exception) as exc:
        if not interrupts.is_interrupt(exc):  # a real error; one raised after Ctrl-C is the interrupt's
            raise
        print(f"{prog}: interrupted", file=sys.stderr)
        return INTERRUPTED
    finally:
        interrupts.requested.clear()


if __name__ == "__main__":
    sys.exit(main())
