"""``wall-inspector demo``: the paper's wall flight and two real structures, flown by every method, in pictures.

Flies ``WallSweep-v0`` (vertical zig-zags while approaching the wall 0.1 m and back),
``Facade-v0`` (past two window recesses, around a ledge and back over it) and ``Pier-v0``
(a circle around a bridge pier), k_s = 4.1 N/m, d_thr = 0.132 m, the paper's command
noise, once each with the cascaded PID, the nominal MPC, SC-MPC and, where one is shipped,
the PPO agent (``--task`` picks one). Contacts are counted and the flight goes on. Prints
each method's wall-normal RMSE, contacts and closest approach, and writes a picture per
task: ``demo.png`` (the sweep), ``demo_facade.png`` and ``demo_pier.png``, each a rendered
frame of the SC-MPC flight and every method's distance from the structure against time.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

import wall_env  # registers the environments
from wall_env.validation import check_output_folder

ENV_ID = "WallInspector/WallSweep-v0"
SUCTION: dict[str, Any] = {"k_s": 4.1, "d_thr": 0.132}


@dataclass(frozen=True)
class DemoTask:
    """One pictured flight: the task, when the frame is rendered and the picture's file and titles."""

    env_id: str
    frame_time: float  # s
    picture: str
    title: str
    frame_title: str


TASKS = {
    "WallSweep": DemoTask(ENV_ID, 9.0, "demo.png", "the paper's wall sweep (Fig. 10), wall-normal axis",
                          "SC-MPC beside the wall at t = 9 s"),
    "Facade": DemoTask("WallInspector/Facade-v0", 27.0, "demo_facade.png",
                       "Facade-v0: past two windows, around the ledge and back over it",
                       "SC-MPC over the ledge at t = 27 s"),
    "Pier": DemoTask("WallInspector/Pier-v0", 9.0, "demo_pier.png", "Pier-v0: a lap around a bridge pier",
                     "SC-MPC beside the pier at t = 9 s"),
}


def _policies(env_id: str = ENV_ID) -> dict:
    from controllers import MPC, PID, SCMPC

    policies = {
        "PID": PID.from_env,
        "MPC": MPC.from_env,
        "SC-MPC": lambda env: SCMPC.from_env(env, **SUCTION),
    }
    try:
        import agents

        if agents.pretrained_path(env_id).is_dir():
            policies["PPO"] = lambda env: agents.load_policy(env_id, env=env)
    except ImportError:  # agents needs PyTorch; the demo works without it
        pass
    return policies


def fly(make_policy: Any, seed: int, render: bool, task: str = "WallSweep") -> tuple[dict[str, np.ndarray], Any]:
    """One flight of ``task``: per step the time, the centre of mass's x and its reference's, the contact flag,
    the nearest duct's clearance to the structure and the error along the nearest surface's normal at the
    reference (``wall_normal_error``); the rendered frame (if ``render``)."""
    from controllers.evaluation import _wall_normals

    demo = TASKS[task]
    env = gym.make(demo.env_id, **SUCTION, terminate_on_collision=False, render_mode="rgb_array" if render else None)
    policy = make_policy(env)
    obs, _ = env.reset(seed=seed)
    log: dict[str, list] = {"time": [], "x": [], "x_ref": [], "contact": [], "clearance": [], "p": [], "p_ref": []}
    frame, start, done = None, True, False
    while not done:
        action, _ = policy.predict(obs, episode_start=np.array([start]), deterministic=True)
        start = False
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        log["time"].append(info["time"])
        log["x"].append(info["p_world"][0])
        log["x_ref"].append(info["p_ref"][0])
        log["contact"].append(info["collision"])
        log["clearance"].append(info["wall_clearance"])
        log["p"].append(info["p_world"])
        log["p_ref"].append(info["p_ref"])
        if render and abs(info["time"] - demo.frame_time) < 1e-9:
            frame = env.render()
    result = {k: np.asarray(v) for k, v in log.items()}
    base: Any = env.unwrapped
    normals = _wall_normals(base.scene, result["p_ref"])
    result["wall_normal_error"] = np.sum((result.pop("p") - result.pop("p_ref")) * normals, axis=1)
    env.close()
    return result, frame


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--task", choices=(*TASKS, "all"), default="all",
                        help="which flight to picture: WallSweep (demo.png), Facade, Pier or all (default)")
    parser.add_argument("--out", default="out", help="folder for the pictures")


def _picture(task: str, logs: dict[str, dict[str, np.ndarray]], frame: Any, out) -> Any:
    from matplotlib.figure import Figure

    demo = TASKS[task]
    fig = Figure(figsize=(12, 4))
    ax_img, ax_plot = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.5]})
    if frame is not None:
        ax_img.imshow(frame)
    ax_img.set_axis_off()
    ax_img.set_title(demo.frame_title)
    if task == "WallSweep":
        reference = next(iter(logs.values()))
        ax_plot.plot(reference["time"], 100 * reference["x_ref"], "k--", lw=1, label="reference")
        for name, log in logs.items():
            ax_plot.plot(log["time"], 100 * log["x"], lw=1, label=name)
        contact_distance = 100 * (0.1 / np.sqrt(2) + wall_env.VehicleParams().duct_radius)
        ax_plot.axhline(contact_distance, color="0.3", ls=":", lw=1.2, label="ducts touch the wall")
        ax_plot.set_ylabel("centre of mass to wall (cm)")
    else:
        for name, log in logs.items():
            ax_plot.plot(log["time"], 100 * log["clearance"], lw=1, label=name)
        ax_plot.axhline(0.0, color="0.3", ls=":", lw=1.2, label="ducts touch the structure")
        ax_plot.set_ylabel("nearest duct to the structure (cm)")
    ax_plot.set_xlabel("time (s)")
    ax_plot.set_title(demo.title)
    ax_plot.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    path = out / demo.picture
    fig.savefig(path, dpi=90)
    return path


def run(args: argparse.Namespace) -> int:
    try:
        out = check_output_folder(args.out, "--out")  # before the flights, not after them
    except ValueError as exc:
        raise SystemExit(str(exc)) from None
    out.mkdir(parents=True, exist_ok=True)
    for task in (TASKS if args.task == "all" else (args.task,)):
        demo = TASKS[task]
        logs, frame = {}, None
        print(f"{demo.env_id}: k_s = 4.1 N/m, d_thr = 0.132 m, command noise on, seed {args.seed}")
        print(f"  {'method':8s} {'wall-normal RMSE':>17s} {'contact steps':>14s} {'closest duct':>13s}")
        for name, make in _policies(demo.env_id).items():
            log, picture = fly(make, args.seed, render=name == "SC-MPC", task=task)
            frame = picture if picture is not None else frame
            logs[name] = log
            rmse = np.sqrt(np.mean(log["wall_normal_error"] ** 2))
            print(f"  {name:8s} {100 * rmse:14.2f} cm {int(log['contact'].sum()):14d} "
                  f"{100 * log['clearance'].min():10.2f} cm")
        print(f"wrote {_picture(task, logs, frame, out)}")
    return 0
