"""The paper's Tables I and II in simulation: scenarios, runner, Markdown, JSON and figures.

Table I (paper Sec. 4.2): ``WallCircle-v0``, d_thr = 0.10 m, k_s in {1, 4, 10} N/m,
command noise on; PID, MPC and SC-MPC at every k_s. The paper reports one
simulated flight per case; we fly :data:`TABLE_I_SEEDS` = 5 seeds per case, which
keeps the whole command at a couple of minutes while a single unlucky noise draw
cannot decide a comparison (the spread across seeds is in the JSON).

Table II (paper Sec. 4.4, a real flight there): ``WallSweep-v0``, k_s = 4.1 N/m,
d_thr = 0.132 m, command noise on, 10 seeds; PID, MPC, SC-MPC.

Every flight runs with ``terminate_on_collision=False``: the vehicle bounces off the
wall, the contact is counted, and the flight covers the whole reference, as the
paper's flights went on after contacts. Every policy flies the same seeds.

Policies are given as a mapping name -> factory. A factory is called once per
scenario as ``factory(env)`` or, if it takes two parameters, ``factory(env,
scenario)`` when it has two positional parameters, so that it can read the
scenario's suction parameters (SC-MPC is told the true k_s and d_thr, as in the
paper's simulation). :func:`paper_policies`
gives PID, MPC and SC-MPC; other policies (e.g. a trained PPO agent from
``agents``) are added by passing more entries, without touching this module.
"""

from __future__ import annotations

import functools
import inspect
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from controllers.evaluation import EvaluationResult, evaluate
from controllers.mpc.cost import MPCWeights
from controllers.mpc.policy import MPC, SCMPC
from controllers.pid import PID

__all__ = [
    "Scenario", "ScenarioResult", "TABLE_I", "TABLE_II", "TABLE_I_SEEDS", "TABLE_II_SEEDS", "PAPER_VALUES",
    "paper_policies", "run_scenarios", "markdown_tables", "acceptance", "markdown_checks", "write_outputs",
]

TABLE_I_SEEDS = tuple(range(5))
TABLE_II_SEEDS = tuple(range(10))


@dataclass(frozen=True)
class Scenario:
    """One row group of a table: a task with its suction parameters and seeds."""

    table: str  # "I" or "II"
    env_id: str
    k_s: float  # N/m
    d_thr: float  # m
    seeds: tuple[int, ...]
    env_kwargs: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return f"Table {self.table}, k_s={self.k_s:g} N/m, d_thr={self.d_thr:g} m"

    def make_kwargs(self) -> dict[str, Any]:
        return {"k_s": self.k_s, "d_thr": self.d_thr, "noise": True, "terminate_on_collision": False,
                **self.env_kwargs}


TABLE_I = tuple(Scenario("I", "WallInspector/WallCircle-v0", k_s, 0.10, TABLE_I_SEEDS) for k_s in (1.0, 4.0, 10.0))
TABLE_II = (Scenario("II", "WallInspector/WallSweep-v0", 4.1, 0.132, TABLE_II_SEEDS),)

# The paper's figures (cm) for the README and the printed comparison.
PAPER_VALUES: dict[str, dict[Any, Any]] = {
    "I": {  # wall-normal (their Y) MAE / RMSE, simulation
        ("PID", 10.0): (4.1, 5.4), ("MPC", 1.0): (0.27, 0.47), ("MPC", 4.0): (0.88, 0.98),
        ("MPC", 10.0): (2.9, 3.0), ("SC-MPC", 10.0): (0.32, 0.39),
    },
    "II": {  # RMSE x / y and MAE x / y, flight
        "PID": {"rmse": (8.1, 9.6), "mae": (4.5, 6.2)},
        "MPC": {"rmse": (5.3, 4.3), "mae": (1.7, 2.1)},
        "SC-MPC": {"rmse": (2.1, 2.0), "mae": (1.2, 1.4)},
    },
}

PolicyFactory = Callable[..., Any]


def _pid(env):
    return PID.from_env(env)


def _mpc(env, *, weights: MPCWeights | None = None):
    return MPC.from_env(env, weights=weights)


def _scmpc(env, scenario: Scenario, *, weights: MPCWeights | None = None):
    return SCMPC.from_env(env, k_s=scenario.k_s, d_thr=scenario.d_thr, weights=weights)


def paper_policies(mpc_weights: MPCWeights | None = None) -> dict[str, PolicyFactory]:
    """PID, MPC and SC-MPC (told the scenario's true suction parameters).

    ``mpc_weights`` replaces the authors' sigmas in both MPCs (for sensitivity
    studies; the paper's tables use the default ``None``).
    """
    if mpc_weights is None:
        return {"PID": _pid, "MPC": _mpc, "SC-MPC": _scmpc}
    return {"PID": _pid, "MPC": functools.partial(_mpc, weights=mpc_weights),
            "SC-MPC": functools.partial(_scmpc, weights=mpc_weights)}


def _call_factory(factory: PolicyFactory, env, scenario: Scenario):
    parameters = [p for p in inspect.signature(factory).parameters.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return factory(env, scenario) if len(parameters) >= 2 else factory(env)


@dataclass
class ScenarioResult:
    scenario: Scenario
    policy: str
    evaluation: EvaluationResult

    def metrics(self) -> dict[str, Any]:
        return self.evaluation.metrics()


def run_scenarios(scenarios: Sequence[Scenario], policies: Mapping[str, PolicyFactory],
                  progress: bool = True) -> list[ScenarioResult]:
    """Fly every policy on every scenario's seeds; a tqdm bar counts the flights."""
    from tqdm import tqdm

    if not policies:
        raise ValueError("policies must name at least one policy")
    total = sum(len(s.seeds) for s in scenarios) * len(policies)
    results = []
    with tqdm(total=total, unit="flight", disable=not progress, dynamic_ncols=True) as bar:
        for scenario in scenarios:
            for name, factory in policies.items():
                bar.set_description(f"{name} on {scenario.env_id.split('/')[-1]} k_s={scenario.k_s:g}")

                def make_policy(env, factory=factory, scenario=scenario):
                    return _call_factory(factory, env, scenario)

                evaluation = evaluate(make_policy, scenario.env_id, scenario.seeds, scenario.make_kwargs(),
                                      on_episode=lambda _: bar.update(1))
                evaluation.policy = name
                results.append(ScenarioResult(scenario, name, evaluation))
    return results


# ====================================================================== tables
def _cm(value: float) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{100 * value:.2f}"


def _collisions(m: dict[str, Any]) -> str:
    return f"{m['collisions']} ({m['collision_episodes']}/{m['episodes']})"


def markdown_tables(results: Sequence[ScenarioResult], note: str = "") -> str:
    """Markdown of Table I and/or Table II with the paper's figures beside ours (``note`` goes first)."""
    out = [note + "\n"] if note else []
    table_i = [r for r in results if r.scenario.table == "I"]
    table_ii = [r for r in results if r.scenario.table == "II"]
    if table_i:
        seeds = len(table_i[0].scenario.seeds)
        out.append(f"**Table I** (simulation): `WallCircle-v0`, d_thr = 0.10 m, command noise on, {seeds} seeds "
                   "per row; wall-normal error (the paper's Y), cm. Collisions: contact steps "
                   "(flights with contact / flights).\n")
        out.append("| Method | k_s (N/m) | MAE (cm) | RMSE (cm) | paper MAE / RMSE (cm) | collisions | "
                   "min clearance (cm) |")
        out.append("|---|---|---|---|---|---|---|")
        for r in table_i:
            m = r.metrics()
            paper = PAPER_VALUES["I"].get((r.policy, r.scenario.k_s))
            paper_text = f"{paper[0]:g} / {paper[1]:g}" if paper else "-"
            out.append(f"| {r.policy} | {r.scenario.k_s:g} | {_cm(m['wall_normal_mae'])} | "
                       f"{_cm(m['wall_normal_rmse'])} | {paper_text} | {_collisions(m)} | "
                       f"{_cm(m['min_wall_clearance'])} |")
        out.append("")
    if table_ii:
        seeds = len(table_ii[0].scenario.seeds)
        out.append(f"**Table II**: `WallSweep-v0`, k_s = 4.1 N/m, d_thr = 0.132 m, command noise on, {seeds} "
                   "seeds; x is the wall normal, cm. Paper: real flight.\n")
        out.append("| Method | RMSE x | RMSE y | RMSE z | MAE x | MAE y | MAE z | paper RMSE x / y | "
                   "paper MAE x / y | collisions | min clearance |")
        out.append("|---|---|---|---|---|---|---|---|---|---|---|")
        for r in table_ii:
            m = r.metrics()
            paper = PAPER_VALUES["II"].get(r.policy)
            rmse_p = f"{paper['rmse'][0]:g} / {paper['rmse'][1]:g}" if paper else "-"
            mae_p = f"{paper['mae'][0]:g} / {paper['mae'][1]:g}" if paper else "-"
            out.append(f"| {r.policy} | " + " | ".join(_cm(v) for v in m["rmse"]) + " | "
                       + " | ".join(_cm(v) for v in m["mae"]) + f" | {rmse_p} | {mae_p} | {_collisions(m)} | "
                       f"{_cm(m['min_wall_clearance'])} |")
        out.append("")
    return "\n".join(out)


def acceptance(results: Sequence[ScenarioResult]) -> list[dict[str, Any]]:
    """The acceptance figures: each check with its measured value and verdict."""
    def find(table: str, policy: str, k_s: float | None = None) -> dict[str, Any] | None:
        for r in results:
            if r.scenario.table == table and r.policy == policy and (k_s is None or r.scenario.k_s == k_s):
                return r.metrics()
        return None

    checks = []
    sc, mpc, pid = find("II", "SC-MPC"), find("II", "MPC"), find("II", "PID")
    if sc is not None:
        checks.append({"check": "Table II: SC-MPC has no collision", "value": sc["collisions"],
                       "pass": sc["collisions"] == 0})
    if sc is not None and mpc is not None:
        ratio = sc["wall_normal_rmse"] / mpc["wall_normal_rmse"]
        checks.append({"check": "Table II: SC-MPC / MPC wall-normal RMSE <= 0.5", "value": ratio, "pass": ratio <= 0.5})
    if sc is not None and pid is not None:
        ratio = sc["wall_normal_rmse"] / pid["wall_normal_rmse"]
        checks.append({"check": "Table II: SC-MPC / PID wall-normal RMSE <= 0.3", "value": ratio, "pass": ratio <= 0.3})
    if mpc is not None and pid is not None:
        checks.append({"check": "Table II: MPC wall-normal RMSE <= PID's", "value": mpc["wall_normal_rmse"] /
                       pid["wall_normal_rmse"], "pass": mpc["wall_normal_rmse"] <= pid["wall_normal_rmse"]})
    sc10, mpc10 = find("I", "SC-MPC", 10.0), find("I", "MPC", 10.0)
    if sc10 is not None and mpc10 is not None:
        ratio = sc10["wall_normal_rmse"] / mpc10["wall_normal_rmse"]
        checks.append({"check": "Table I, k_s=10: SC-MPC / MPC wall-normal RMSE <= 0.3", "value": ratio,
                       "pass": ratio <= 0.3})
    return checks


# ====================================================================== files and figures
def _scenario_dict(s: Scenario) -> dict[str, Any]:
    data = asdict(s)
    data["seeds"] = list(s.seeds)
    return data


def results_json(results: Sequence[ScenarioResult]) -> dict[str, Any]:
    return {
        "runs": [{"scenario": _scenario_dict(r.scenario), "policy": r.policy, "metrics": r.metrics(),
                  "per_episode": r.evaluation.per_episode()} for r in results],
        "acceptance": acceptance(results),
    }


def _plot_table_i(results: Sequence[ScenarioResult], path: Path, seed_index: int = 0) -> None:
    """Paper Fig. 6: position in the wall plane and wall-normal error against time, per k_s."""
    from matplotlib.figure import Figure  # not pyplot: must not switch the caller's backend

    scenarios = sorted({r.scenario.k_s for r in results})
    fig = Figure(figsize=(4.5 * len(scenarios), 7))
    axes = fig.subplots(2, len(scenarios), squeeze=False)
    for col, k_s in enumerate(scenarios):
        runs = [r for r in results if r.scenario.k_s == k_s]
        ax_traj, ax_err = axes[0, col], axes[1, col]
        reference_drawn = False
        for r in runs:
            e = r.evaluation.episodes[seed_index]
            if not reference_drawn:
                ax_traj.plot(e.p_ref[:, 1], e.p_ref[:, 2], "k--", lw=1, label="reference")
                reference_drawn = True
            ax_traj.plot(e.p_world[:, 1], e.p_world[:, 2], lw=1, label=r.policy)
            ax_err.plot(e.time, 100 * e.wall_normal_error, lw=1, label=r.policy)
        ax_traj.set_title(f"k_s = {k_s:g} N/m, d_thr = 0.10 m (seed {runs[0].evaluation.seeds[seed_index]})")
        ax_traj.set_xlabel("y (m, along the wall)")
        ax_traj.set_ylabel("z (m)")
        ax_traj.set_aspect("equal", adjustable="datalim")
        ax_err.axhline(0.0, color="k", lw=0.6)
        ax_err.set_xlabel("time (s)")
        ax_err.set_ylabel("wall-normal error (cm, + away from wall)")
        ax_traj.legend(fontsize=8)
        ax_err.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _plot_table_ii(results: Sequence[ScenarioResult], path: Path, seed_index: int = 0) -> None:
    """Paper Fig. 10: x, y, z against time for each method, with the reference."""
    from matplotlib.figure import Figure  # not pyplot: must not switch the caller's backend

    fig = Figure(figsize=(9, 8))
    axes = fig.subplots(3, 1, sharex=True)
    for axis, ax in enumerate(axes):
        reference_drawn = False
        for r in results:
            e = r.evaluation.episodes[seed_index]
            if not reference_drawn:
                ax.plot(e.time, e.p_ref[:, axis], "k--", lw=1, label="reference")
                reference_drawn = True
            ax.plot(e.time, e.p_world[:, axis], lw=1, label=r.policy)
        ax.set_ylabel(f"{'xyz'[axis]} (m)")
    axes[0].set_title(f"WallSweep-v0, k_s = 4.1 N/m, d_thr = 0.132 m (seed {results[0].evaluation.seeds[seed_index]});"
                      " wall at x = 0")
    axes[0].legend(fontsize=8, ncol=4)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def markdown_checks(checks: Sequence[dict[str, Any]]) -> str:
    """The acceptance checks as a Markdown list: verdict, check, measured value."""
    lines = ["Acceptance checks, as measured by this run:", ""]
    lines += [f"- {'pass' if c['pass'] else '**FAIL**'}: {c['check']} (measured {c['value']:.3g})" for c in checks]
    return "\n".join(lines) + "\n"


def write_outputs(results: Sequence[ScenarioResult], out_dir: str | Path, note: str = "",
                  extra_checks: Sequence[dict[str, Any]] = ()) -> dict[str, Path]:
    """Write ``tables.md``, ``results.json`` and the figures to ``out_dir``; return their paths.

    ``note`` heads the Markdown and is stored in the JSON (e.g. non-default MPC weights);
    ``extra_checks`` (same form as :func:`acceptance`'s) follow the paper's checks in both.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"markdown": out / "tables.md", "json": out / "results.json"}
    checks = acceptance(results) + list(extra_checks)
    paths["markdown"].write_text(markdown_tables(results, note) + "\n" + markdown_checks(checks))
    paths["json"].write_text(json.dumps({"note": note, **results_json(results), "acceptance": checks},
                                        indent=2, default=float))
    table_i = [r for r in results if r.scenario.table == "I"]
    table_ii = [r for r in results if r.scenario.table == "II"]
    if table_i:
        paths["table_i_figure"] = out / "table_i_circle.png"
        _plot_table_i(table_i, paths["table_i_figure"])
    if table_ii:
        paths["table_ii_figure"] = out / "table_ii_sweep.png"
        _plot_table_ii(table_ii, paths["table_ii_figure"])
    return paths
