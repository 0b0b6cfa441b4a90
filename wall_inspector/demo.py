"""``wall-inspector demo``: a short flight near a wall that shows the suction at work.

The vehicle starts at rest on the stand-off point of ``WallHover-v0`` and holds hover thrust with
zero body rates (action 0) while the wall's suction, which the open-loop command
does not know about, pulls it in. The command prints what happened and writes a
picture: a rendered frame next to the wall clearance and suction force against time.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np

import wall_env  # noqa: F401  (registers the environments)


def fly(env_id: str, seed: int, seconds: float) -> tuple[dict[str, np.ndarray], np.ndarray]:
    env = gym.make(env_id, render_mode="rgb_array", noise=False, duration=seconds)
    env.reset(seed=seed, options={"perturb_start": False})
    log: dict[str, list] = {"time": [], "clearance": [], "suction": [], "x": []}
    frame = env.render()
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(4))
        log["time"].append(info["time"])
        log["clearance"].append(info["wall_clearance"])
        log["suction"].append(np.linalg.norm(info["suction_force_world"]))
        log["x"].append(info["p_world"][0])
        if info["collision"] or len(log["time"]) % 25 == 0:
            frame = env.render()
        done = terminated or truncated
    env.close()
    return {k: np.asarray(v) for k, v in log.items()}, frame


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default="WallInspector/WallHover-v0", help="environment id")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, default=3.0, help="flight length (s)")
    parser.add_argument("--out", default="out", help="folder for the picture")


def run(args: argparse.Namespace) -> int:
    from matplotlib.figure import Figure

    log, frame = fly(args.env, args.seed, args.seconds)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    hit = np.flatnonzero(log["clearance"] <= 0.0)
    print(f"{args.env}: open-loop hover thrust, zero body rates, {len(log['time'])} steps of 10 ms")
    print(f"  duct clearance to the wall: {100 * log['clearance'][0]:.1f} cm at start, "
          f"{100 * log['clearance'].min():.1f} cm at least")
    print(f"  suction force: {log['suction'][0]:.2f} N at start, {log['suction'].max():.2f} N at most")
    if hit.size:
        print(f"  the suction pulled the vehicle into the wall after {log['time'][hit[0]]:.2f} s")
    else:
        print("  no contact with the wall")

    fig = Figure(figsize=(11, 4))
    ax_img, ax_plot = fig.subplots(1, 2)
    ax_img.imshow(frame)
    ax_img.set_axis_off()
    ax_img.set_title("last frame")
    ax_plot.plot(log["time"], 100 * log["clearance"], label="duct clearance to wall (cm)")
    ax_plot.plot(log["time"], log["suction"], label="suction force (N)")
    ax_plot.axhline(0.0, color="k", lw=0.8)
    ax_plot.set_xlabel("time (s)")
    ax_plot.legend()
    ax_plot.set_title("open-loop hover beside the wall")
    fig.tight_layout()
    path = out / "demo.png"
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")
    return 0
