"""How stiff and how damped a controller holds its position: the response to a steady side push at hover.

Near a wall the suction grows as the vehicle approaches it: with two rotors inside
``d_thr`` its pull rises at ``2 k_s`` N per metre (8.2 N/m for the paper's
k_s = 4.1 N/m). A closed loop whose lateral stiffness is below that gradient has no
stable position near the wall: the vehicle is drawn onto it. This module measures the
stiffness and damping of any policy so that the gains and weights can be judged
against that figure.

:func:`side_push_response` flies ``WallHover-v0`` with the wall out of reach (the
reference 2 m from it, so no suction), no command noise and an unperturbed start,
with a constant horizontal force ``F`` (default 0.1 N along the wall normal, world
x) from the first step, through the simulator's ``constant_force`` effect. From the
wall-normal position ``x(t)``:

- steady deflection ``x_ss``: the mean of the last ``settle_window`` seconds;
- stiffness per unit mass ``k = F / (m x_ss)`` in N/m per kg (= 1/s^2; for a PID
  with no integral this is its position gain ``Kp``);
- overshoot ``(max x - x_ss) / x_ss`` and the damping ratio of the second-order
  system with that overshoot, ``zeta = -ln(OS) / sqrt(pi^2 + ln(OS)^2)``; with no
  measurable overshoot (below 0.1 %) ``zeta`` is reported as 1 (critically damped
  or slower);
- ``still_moving``: the peak-to-peak of ``x`` over the settle window relative to
  ``x_ss`` (a loop still ringing at the end has a large value and an unreliable
  ``x_ss``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym
import numpy as np

import wall_env  # noqa: F401  (registers the environments)

__all__ = ["PushResponse", "side_push_response"]

_FAR_STANDOFF = 2.0  # m: the near rotors 1.93 m from the wall, far beyond any d_thr


@dataclass(frozen=True)
class PushResponse:
    """Result of :func:`side_push_response` (SI units)."""

    force: float  # N
    mass: float  # kg
    steady_deflection: float  # m, along the push
    stiffness_per_kg: float  # N/m per kg
    overshoot: float  # fraction of the steady deflection
    damping_ratio: float
    still_moving: float  # peak-to-peak over the settle window / steady deflection
    time: np.ndarray  # s
    deflection: np.ndarray  # m

    def summary(self) -> dict[str, float]:
        data = asdict(self)
        data.pop("time")
        data.pop("deflection")
        return data


def damping_from_overshoot(overshoot: float) -> float:
    """Damping ratio of a second-order step response with fractional ``overshoot`` (1 if none)."""
    if overshoot < 1e-3:
        return 1.0
    log_os = math.log(overshoot)
    return -log_os / math.sqrt(math.pi**2 + log_os**2)


def side_push_response(make_policy: Callable[[gym.Env], Any], force: float = 0.1, duration: float = 10.0,
                       settle_window: float = 2.0) -> PushResponse:
    """Push a hovering vehicle flown by ``make_policy(env)`` with ``force`` N along world x; see the module doc."""
    if not 0.0 < abs(force) <= 5.0:
        raise ValueError(f"force must be in (0, 5] N in magnitude, got {force}")
    if not 2 * settle_window < duration <= 600.0:
        raise ValueError(f"duration must be in (2 settle_window, 600] s, got {duration}")
    env = gym.make("WallInspector/WallHover-v0", standoff=_FAR_STANDOFF, duration=duration, noise=False,
                   effects={"constant_force": {"F": [force, 0.0, 0.0]}}, terminate_on_collision=False)
    try:
        policy = make_policy(env)
        obs, info = env.reset(seed=0, options={"perturb_start": False})
        x_ref = float(info["p_ref"][0])
        times, xs = [], []
        start, done = True, False
        while not done:
            action, _ = policy.predict(obs, episode_start=np.array([start]), deterministic=True)
            start = False
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            times.append(info["time"])
            xs.append(info["p_world"][0] - x_ref)
        unwrapped: Any = env.unwrapped
        mass = unwrapped.vehicle.mass
    finally:
        env.close()
    t, x = np.asarray(times), np.asarray(xs) * math.copysign(1.0, force)
    window = t >= t[-1] - settle_window
    x_ss = float(np.mean(x[window]))
    overshoot = max(0.0, (float(np.max(x)) - x_ss) / x_ss) if x_ss > 0 else math.inf
    return PushResponse(
        force=abs(force), mass=mass, steady_deflection=x_ss,
        stiffness_per_kg=abs(force) / (mass * x_ss) if x_ss > 0 else 0.0,
        overshoot=overshoot,
        damping_ratio=damping_from_overshoot(overshoot) if math.isfinite(overshoot) else 0.0,
        still_moving=float(np.ptp(x[window]) / x_ss) if x_ss > 0 else math.inf,
        time=t, deflection=x,
    )
