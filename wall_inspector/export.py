"""``wall-inspector export``: a PPO agent to ONNX, or MPC / SC-MPC to C, to fly without this package.

``wall-inspector export ppo [--agent SOURCE] --out DIR`` writes ``DIR/policy.onnx``
(:func:`agents.export.export_onnx`: the observation normalisation folded in, observation in,
action out, checked against the Python agent before it is written). ``SOURCE`` is a
checkpoint folder (a run folder, its ``best/``, a shipped one) or a task name; default the
shipped agent of ``--env``.

``wall-inspector export scmpc|mpc [--env TASK] [--k-s K --d-thr D | --model FILE] [--preset P] --out DIR``
builds the controller as ``SCMPC.from_env`` / ``MPC.from_env`` would for that task's env and
writes it as C into ``DIR`` (:func:`controllers.export.export_controller`), then builds it
with its Makefile (``--no-build`` only writes the files). The README's "Flying an exported
controller" section shows how a companion computer calls each.
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

from wall_env.validation import check_output_folder

METHODS = ("ppo", "scmpc", "mpc")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("method", choices=METHODS, help="ppo: a trained agent to ONNX; scmpc, mpc: the controller to C")
    parser.add_argument("--out", required=True, help="folder to write into (created if missing)")
    parser.add_argument("--env", default="WallSweep-v0",
                        help="task whose env the controller is built for, or whose shipped agent is exported "
                             "(default WallSweep-v0)")
    parser.add_argument("--agent", default=None, metavar="SOURCE",
                        help="ppo: checkpoint folder or task name (default: the shipped agent of --env)")
    parser.add_argument("--k-s", type=float, default=None, help="scmpc: suction scale k_s (N/m; default 4.1)")
    parser.add_argument("--d-thr", type=float, default=None, help="scmpc: suction threshold d_thr (m; default 0.132)")
    parser.add_argument("--model", default=None, metavar="FILE",
                        help="scmpc: a model file (wall-inspector discover) instead of --k-s/--d-thr")
    parser.add_argument("--preset", default="tuned",
                        help="mpc, scmpc: weights and horizon: tuned (default), paper, paper-sim or a preset file")
    parser.add_argument("--no-build", action="store_true", help="mpc, scmpc: write the C files, do not run make")


def _apply(flags: list[str]) -> str:
    return "only applies" if len(flags) == 1 else "only apply"


def _check(args: argparse.Namespace) -> Path:
    """Every usage check before any work; ``SystemExit("message")`` (one line, exit 2) on the first failure."""
    from wall_env.tasks import task_env_id

    try:
        out = check_output_folder(args.out, "--out")
        args.env = task_env_id(args.env)
    except ValueError as exc:
        raise SystemExit(str(exc)) from None
    controller_flags = {"--k-s": args.k_s, "--d-thr": args.d_thr, "--model": args.model}
    if args.method == "ppo":
        given = [flag for flag, value in {**controller_flags, "--no-build": args.no_build or None}.items()
                 if value is not None]
        if given:
            raise SystemExit(f"{', '.join(given)} {_apply(given)} to scmpc or mpc, not to ppo")
        return out
    if args.agent is not None:
        raise SystemExit(f"--agent only applies to ppo, not to {args.method}")
    if args.method == "mpc":
        given = [flag for flag, value in controller_flags.items() if value is not None]
        if given:
            raise SystemExit(f"{', '.join(given)} {_apply(given)} to scmpc (mpc predicts with the nominal model)")
    if args.model is not None and not Path(args.model).is_file():
        raise SystemExit(f"--model {args.model}: no such file")
    return out


def _agent_source(args: argparse.Namespace) -> str:
    import agents

    source = args.agent if args.agent is not None else args.env
    if Path(source).exists():
        return source
    try:
        folder = agents.pretrained_path(source)
    except ValueError:
        raise SystemExit(f"--agent {source}: no such folder, and not a task name") from None
    if not folder.is_dir():
        raise SystemExit(f"--agent {source}: no shipped agent for this task ({folder} does not exist)")
    return str(folder)


def _export_ppo(args: argparse.Namespace, out: Path) -> int:
    from agents.checkpoints import CheckpointError
    from agents.export import ONNX_FILE, TOLERANCE, OnnxPolicy, export_onnx

    source = _agent_source(args)
    try:
        path = export_onnx(source, out / ONNX_FILE)
    except (ValueError, CheckpointError, FileNotFoundError, ImportError) as exc:  # each names the file or package
        raise SystemExit(str(exc)) from None
    policy = OnnxPolicy(path)
    print(f"wrote {path}: the PPO agent of {source} ({policy.metadata.get('env_id')}), normalisation folded in; "
          f"network input ({policy.input_size} floats) in, action (4 floats in [-1, 1]) out; its actions match "
          f"the Python agent's within {TOLERANCE:g}")
    if policy.memory is not None:
        print(f"the agent remembers: its input is the history of the env's {policy.observation_size}-float observations "
              f"({policy.metadata.get('history')}), which the vehicle keeps as agents.history.ObservationHistory does "
              "(OnnxPolicy.predict keeps it from the observations)")
    return 0


def _export_controller(args: argparse.Namespace, out: Path) -> int:
    import gymnasium as gym

    import wall_env  # noqa: F401  (registers the environments)
    from controllers import MPC, SCMPC
    from controllers.export import build, export_controller

    env = gym.make(args.env)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a compiler-less machine falls back; export says so below
            if args.method == "scmpc":
                policy: MPC = SCMPC.from_env(env, k_s=args.k_s, d_thr=args.d_thr, model=args.model, preset=args.preset)
            else:
                policy = MPC.from_env(env, preset=args.preset)
    except (ValueError, OSError) as exc:  # the preset, the suction values, the model file
        raise SystemExit(str(exc)) from None
    finally:
        env.close()
    description = export_controller(policy, out)
    settings = json.loads(description.read_text())["settings"]
    print(f"wrote {out}: {policy.name} for {args.env} as C (horizon {settings['horizon']} x {settings['dt']:.4g} s, "
          f"one wi_step per {settings['control_dt']:g} s); the interface is in wi_controller.h, every parameter by "
          f"name in {description.name}")
    if args.no_build:
        print(f"build it with: make -C {out}")
        return 0
    try:
        library = build(out)
    except (FileNotFoundError, RuntimeError) as exc:
        print(f"not built: {exc}")
        return 1
    print(f"built {library.name}, libwi_controller.a and wi_bench with make (flags in {out / 'Makefile'})")
    return 0


def run(args: argparse.Namespace) -> int:
    out = _check(args)
    if args.method == "ppo":
        return _export_ppo(args, out)
    return _export_controller(args, out)
