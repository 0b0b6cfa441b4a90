"""``wall-inspector demo``: the paper's wall flight, flown by every method, in one picture.

Flies ``WallSweep-v0`` (vertical zig-zags while approaching the wall 0.1 m and back,
k_s = 4.1 N/m, d_thr = 0.132 m, the paper's command noise) once with the cascaded PID,
the nominal MPC, SC-MPC and, if shipped, the PPO agent; contacts with the wall are
counted and the flight goes on. Prints each method's wall-normal RMSE, contacts and
closest approach, and writes ``demo.png``: a rendered frame of the SC-MPC flight and
every method's distance from the wall against time.
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym
import numpy as np

import wall_env  # registers the environments
from wall_env.validation import check_output_folder

ENV_ID = "WallInspector/WallSweep-v0"
SUCTION: dict[str, Any] = {"k_s": 4.1, "d_thr": 0.132}


def _policies() -> dict:
    from controllers import MPC, PID, SCMPC

    policies = {
        "PID": PID.from_env,
        "MPC": MPC.from_env,
        "SC-MPC": lambda env: SCMPC.from_env(env, **SUCTION),
    }
    try:
        import agents

        if agents.pretrained_path(ENV_ID).is_dir():
            policies["PPO"] = lambda env: agents.load_policy(ENV_ID, env=env)
    except ImportError:  # agents needs PyTorch; the demo works without it
        pass
    return policies


def fly(make_policy: Any, seed: int, render: bool) -> tuple[dict[str, np.ndarray], Any]:
    env = gym.make(ENV_ID, **SUCTION, terminate_on_collision=False, render_mode="rgb_array" if render else None)
    policy = make_policy(env)
    obs, _ = env.reset(seed=seed)
    log: dict[str, list] = {"time": [], "x": [], "x_ref": [], "contact": [], "clearance": []}
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
        if render and abs(info["time"] - 9.0) < 1e-9:  # closest to the wall at t = 9 s
            frame = env.render()
    env.close()
    return {k: np.asarray(v) for k, v in log.items()}, frame


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="out", help="folder for demo.png")


def run(args: argparse.Namespace) -> int:
    from matplotlib.figure import Figure

    try:
        out = check_output_folder(args.out, "--out")  # before the flights, not after them
    except ValueError as exc:
        raise SystemExit(str(exc)) from None
    logs, frame = {}, None
    print(f"{ENV_ID}: k_s = 4.1 N/m, d_thr = 0.132 m, command noise on, seed {args.seed}")
    print(f"  {'method':8s} {'wall-normal RMSE':>17s} {'contact steps':>14s} {'closest duct':>13s}")
    for name, make in _policies().items():
        log, picture = fly(make, args.seed, render=name == "SC-MPC")
        frame = picture if picture is not None else frame
        logs[name] = log
        rmse = np.sqrt(np.mean((log["x"] - log["x_ref"]) ** 2))
        print(f"  {name:8s} {100 * rmse:14.2f} cm {int(log['contact'].sum()):14d} {100 * log['clearance'].min():10.2f} cm")

    out.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(12, 4))
    ax_img, ax_plot = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.5]})
    ax_img.imshow(frame)
    ax_img.set_axis_off()
    ax_img.set_title("SC-MPC beside the wall at t = 9 s")
    reference = next(iter(logs.values()))
    ax_plot.plot(reference["time"], 100 * reference["x_ref"], "k--", lw=1, label="reference")
    for name, log in logs.items():
        ax_plot.plot(log["time"], 100 * log["x"], lw=1, label=name)
    contact_distance = 100 * (0.1 / np.sqrt(2) + wall_env.VehicleParams().duct_radius)
    ax_plot.axhline(contact_distance, color="0.3", ls=":", lw=1.2, label="ducts touch the wall")
    ax_plot.set_xlabel("time (s)")
    ax_plot.set_ylabel("centre of mass to wall (cm)")
    ax_plot.set_title("the paper's wall sweep (Fig. 10), wall-normal axis")
    ax_plot.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    path = out / "demo.png"
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")
    return 0
