"""What ``wall-inspector tune`` searches: the parameters of each method, their ranges, and how a trial becomes a preset.

Every range is searched on a log scale (gains and standard deviations are scale
parameters). Lateral axes (x, y) share one value, as the vehicle is symmetric.

PID (6 parameters): position gain ``kp`` (xy, z) in [1, 80] 1/s^2, velocity gain
``kv`` (xy, z) in [0.5, 30] 1/s, attitude gain ``k_attitude`` (roll/pitch, yaw) in
[1, 60] and [0.5, 20] 1/s.

MPC and SC-MPC (7 sigmas and the horizon): position (xy, z) in [0.01, 0.5] m,
terminal position in [0.005, 0.5] m, roll/pitch rotation in [0.05, 5] rad,
velocity in [0.05, 30] m/s, control rate of the thrust in [0.02, 2] N and of the
roll/pitch rates in [0.01, 1] rad/s. The yaw rotation (0.03 rad), yaw-rate rate
(0.01 rad/s), dynamics (1e-4) and control-limit (0.01) sigmas stay the authors'
(the yaw does not move the vehicle, and the dynamics and limit sigmas make soft
constraints that should stay stiff). The horizon: ``dt`` in [0.01, 0.03] s with
N = 20 steps (0.2 to 0.6 s) by default; with ``horizon_steps`` given, N is a
choice among them too (each N compiles its own solver once).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["SearchSpace", "PID_RANGES", "MPC_RANGES"]

PID_RANGES = {
    "kp_xy": (1.0, 80.0), "kp_z": (1.0, 80.0),
    "kv_xy": (0.5, 30.0), "kv_z": (0.5, 30.0),
    "k_attitude_xy": (1.0, 60.0), "k_attitude_z": (0.5, 20.0),
}
MPC_RANGES = {
    "position_xy": (0.01, 0.5), "position_z": (0.01, 0.5), "terminal_position": (0.005, 0.5),
    "rotation_xy": (0.05, 5.0), "velocity": (0.05, 30.0),
    "control_rate_thrust": (0.02, 2.0), "control_rate_xy": (0.01, 1.0),
}
DT_RANGE = (0.01, 0.03)  # s


@dataclass(frozen=True)
class SearchSpace:
    """The search space of one method (``"pid"``, ``"mpc"`` or ``"scmpc"``).

    ``base``: the preset section the trial's values are written into (the authors'
    settings: what is not searched keeps its value there). ``tune_dt``: search the
    MPC step ``dt``; ``horizon_steps``: the horizon lengths N to choose from
    (``()`` keeps the base N).
    """

    method: str
    base: dict[str, Any]
    tune_dt: bool = True
    horizon_steps: Sequence[int] = ()

    def __post_init__(self) -> None:
        if self.method not in ("pid", "mpc", "scmpc"):
            raise ValueError(f"method must be 'pid', 'mpc' or 'scmpc', got {self.method!r}")
        for n in self.horizon_steps:
            if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= 200:
                raise ValueError(f"horizon_steps must be integers in [2, 200], got {list(self.horizon_steps)}")

    def suggest(self, trial) -> dict[str, Any]:
        """The preset section for an Optuna ``trial`` (it asks the trial for every searched value)."""
        ranges = PID_RANGES if self.method == "pid" else MPC_RANGES
        values = {name: trial.suggest_float(name, low, high, log=True) for name, (low, high) in ranges.items()}
        if self.method != "pid":
            if self.tune_dt:
                values["dt"] = trial.suggest_float("dt", *DT_RANGE, log=True)
            if self.horizon_steps:
                values["horizon"] = trial.suggest_categorical("horizon", list(self.horizon_steps))
        return self.settings(values)

    def settings(self, values: dict[str, Any]) -> dict[str, Any]:
        """The preset section for searched ``values`` (names as in the ranges)."""
        out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in self.base.items()}
        if self.method == "pid":
            out["kp"] = [values["kp_xy"], values["kp_xy"], values["kp_z"]]
            out["kv"] = [values["kv_xy"], values["kv_xy"], values["kv_z"]]
            out["k_attitude"] = [values["k_attitude_xy"], values["k_attitude_xy"], values["k_attitude_z"]]
            return out
        weights = dict(out.get("weights", {}))
        yaw = list(weights.get("rotation", [0.3, 0.3, 0.03]))[2]
        rate = list(weights.get("control_rate", [0.2, 0.1, 0.1, 0.01]))
        weights["position"] = [values["position_xy"], values["position_xy"], values["position_z"]]
        weights["terminal_position"] = [values["terminal_position"]] * 3
        weights["rotation"] = [values["rotation_xy"], values["rotation_xy"], yaw]
        weights["velocity"] = [values["velocity"]] * 3
        weights["control_rate"] = [values["control_rate_thrust"], values["control_rate_xy"], values["control_rate_xy"],
                                   rate[3]]
        out["weights"] = weights
        for key in ("dt", "horizon"):
            if key in values:
                out[key] = values[key]
        return out

    def values_of(self, section: dict[str, Any]) -> dict[str, Any]:
        """The searched values that give a preset ``section`` (to start a study from a known preset)."""
        if self.method == "pid":
            kp, kv, ka = section["kp"], section["kv"], section["k_attitude"]
            values = {"kp_xy": kp[0], "kp_z": kp[2], "kv_xy": kv[0], "kv_z": kv[2], "k_attitude_xy": ka[0],
                      "k_attitude_z": ka[2]}
        else:
            w = section["weights"]
            values = {"position_xy": w["position"][0], "position_z": w["position"][2],
                      "terminal_position": w["terminal_position"][0], "rotation_xy": w["rotation"][0],
                      "velocity": w["velocity"][0], "control_rate_thrust": w["control_rate"][0],
                      "control_rate_xy": w["control_rate"][1]}
            if self.tune_dt:
                values["dt"] = section.get("dt", 0.01)
            if self.horizon_steps:
                values["horizon"] = section.get("horizon", 20)
        ranges = {**PID_RANGES, **MPC_RANGES, "dt": DT_RANGE}
        return {k: (min(max(float(v), ranges[k][0]), ranges[k][1]) if k in ranges else v) for k, v in values.items()}
