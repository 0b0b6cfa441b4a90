"""Robustness: every method, told only the nominal model, flown in worlds that are not the nominal one.

Every result of the paper tables assumes the simulator's exact world: SC-MPC is told the
true suction. A real wall need not follow the paper's identified ``k_s`` = 4.1 N/m and
``d_thr`` = 0.132 m, and a real vehicle meets pushes, turbulence, a late and noisy state
estimate and lagging rotors. :data:`DEFAULT_GRID` is the paper's Table II sweep
(``WallSweep-v0``, command noise, flights go on after a contact) in these worlds:

=============  ==========================================================================
group          worlds
=============  ==========================================================================
suction        ``k_s`` in {1, 2, 4.1, 8, 12} N/m x ``d_thr`` in {0.10, 0.132, 0.16} m
push           a steady 0.1, 0.3 and 1 N toward the wall and along it
gusts          light and moderate Dryden turbulence (:mod:`wall_env.conditions.wind`)
latency        10, 20 and 30 ms round trip (half on the command, half on the estimate)
sensing        the motion-capture and visual-inertial presets (:mod:`wall_env.conditions.sensing`)
motor lag      10, 30 and 50 ms
realistic      the ``realistic`` profile: motion capture, 20 ms latency, 30 ms lag, light gusts
=============  ==========================================================================

Methods are picklable :class:`Method` objects (a flight may run in another process or on
Ray): each makes a policy for a batched env of one world's seeds. Every method is told
the nominal model only, except :class:`ToldTheTruth`, the reference: SC-MPC told each
world's true suction and push (the other conditions cannot be told to a model).
:func:`fly_cell` flies one (world, method) cell with every seed as a row of one batched
env (:func:`controllers.evaluation.evaluate_batched`); :func:`acceptance` holds the
checks of the adaptive SC-MPC and of PPO against that reference.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from controllers.evaluation import evaluate_batched
from controllers.mpc.policy import MPC, PAPER_SUCTION, SCMPC
from controllers.pid import PID

__all__ = ["World", "Method", "Controller", "ToldTheTruth", "DEFAULT_GRID", "default_methods", "authors_methods",
           "CellResult", "fly_cell", "run_grid", "acceptance", "markdown_report", "method_report", "plot_heatmap", "results_json",
           "ENV_ID", "PAPER_TABLE_II_RMSE_X"]

ENV_ID = "WallInspector/WallSweep-v0"
BASE_KWARGS: dict[str, Any] = {"noise": True, "terminate_on_collision": False}
# the paper's real-flight Table II, wall-normal (x) RMSE in cm, for the ratios beside the realistic profile
PAPER_TABLE_II_RMSE_X = {"PID": 8.1, "MPC": 5.3, "SC-MPC": 2.1}
WALL_NORMAL = (1.0, 0.0, 0.0)  # the sweep's wall: plane x = 0, outward normal +x
ALONG_WALL = (0.0, 1.0, 0.0)


@dataclass(frozen=True)
class World:
    """One cell of the grid: the true world (env keywords on top of the task's) and how to tell it to a model."""

    group: str
    label: str
    k_s: float = PAPER_SUCTION["k_s"]  # N/m
    d_thr: float = PAPER_SUCTION["d_thr"]  # m
    push: tuple[float, float, float] = (0.0, 0.0, 0.0)  # N, world frame
    conditions: Any = None  # wall_env.conditions spec

    def __hash__(self) -> int:  # by name: ``conditions`` may be a dict; labels are unique within a grid
        return hash((self.group, self.label))

    def env_kwargs(self, duration: float | None = None) -> dict[str, Any]:
        kwargs: dict[str, Any] = {**BASE_KWARGS, "k_s": self.k_s, "d_thr": self.d_thr}
        if any(self.push):
            kwargs["effects"] = {"constant_force": {"F": list(self.push)}}
        if self.conditions is not None:
            kwargs["conditions"] = self.conditions
        if duration is not None:
            kwargs["duration"] = duration
        return kwargs

    @property
    def nominal(self) -> bool:
        return (self.k_s == PAPER_SUCTION["k_s"] and self.d_thr == PAPER_SUCTION["d_thr"] and not any(self.push)
                and self.conditions is None)

    @property
    def model_checked(self) -> bool:
        """Cells where the adaptive SC-MPC is checked against the reference: the suction and push worlds."""
        return self.group in ("suction", "push")

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["push"] = list(self.push)
        return data


def _grid() -> tuple[World, ...]:
    worlds = [World("suction", f"k_s {k:g}, d_thr {d:g}", k_s=k, d_thr=d)
              for d in (0.10, 0.132, 0.16) for k in (1.0, 2.0, 4.1, 8.0, 12.0)]
    for force in (0.1, 0.3, 1.0):
        toward = (-force * WALL_NORMAL[0], -force * WALL_NORMAL[1], -force * WALL_NORMAL[2])
        along = (force * ALONG_WALL[0], force * ALONG_WALL[1], force * ALONG_WALL[2])
        worlds.append(World("push", f"{force:g} N toward the wall", push=toward))
        worlds.append(World("push", f"{force:g} N along the wall", push=along))
    worlds += [World("gusts", f"{name} turbulence", conditions={"wind": name}) for name in ("light", "moderate")]
    worlds += [World("latency", f"latency {ms} ms", conditions={"latency": ms / 1000}) for ms in (10, 20, 30)]
    worlds += [World("sensing", name.replace("_", " "), conditions={"sensing": name})
               for name in ("motion_capture", "visual_inertial")]
    worlds += [World("motor lag", f"motor lag {ms} ms", conditions={"motor_time_constant": ms / 1000})
               for ms in (10, 30, 50)]
    worlds.append(World("realistic", "realistic profile", conditions="realistic"))
    return tuple(worlds)


DEFAULT_GRID = _grid()


# ====================================================================== methods
class Method:
    """A method of the grid: ``make(envs, world)`` returns a policy for the batched env of one world."""

    name = "method"

    def make(self, envs: Any, world: World) -> Any:
        raise NotImplementedError


@dataclass(frozen=True)
class Controller(Method):
    """PID, MPC or SC-MPC (told the nominal suction) from a preset; ``adapt`` for the adaptive SC-MPC."""

    kind: str  # "pid", "mpc" or "scmpc"
    label: str
    preset: str = "tuned"
    adapt: bool = False

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.label

    def make(self, envs: Any, world: World) -> Any:
        if self.kind == "pid":
            return PID.from_env(envs, preset=self.preset)
        if self.kind == "mpc":
            return MPC.from_env(envs, preset=self.preset)
        return SCMPC.from_env(envs, preset=self.preset, adapt=self.adapt, k_s=PAPER_SUCTION["k_s"],
                              d_thr=PAPER_SUCTION["d_thr"])


@dataclass(frozen=True)
class ToldTheTruth(Method):
    """The reference: SC-MPC told each world's true suction and push (what a model can be told)."""

    label: str = "SC-MPC told the truth"

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.label

    def make(self, envs: Any, world: World) -> Any:
        from wall_env.effects import make_effect
        from wall_env.model_file import FlightModel

        effects = [make_effect("wall_suction", k_s=world.k_s, d_thr=world.d_thr)]
        if any(world.push):
            effects.append(make_effect("constant_force", F=list(world.push)))
        vehicle = envs.unwrapped.vehicle if hasattr(envs, "unwrapped") else envs.vehicle
        return SCMPC.from_env(envs, model=FlightModel(vehicle, effects))


def default_methods() -> dict[str, Method]:
    """PID, MPC, SC-MPC and the adaptive SC-MPC (tuned presets, told the nominal model), and the reference."""
    methods: list[Method] = [Controller("pid", "PID"), Controller("mpc", "MPC"), Controller("scmpc", "SC-MPC"),
                             Controller("scmpc", "SC-MPC adaptive", adapt=True), ToldTheTruth()]
    return {m.name: m for m in methods}


def authors_methods() -> dict[str, Method]:
    """PID, MPC and SC-MPC with the authors' released settings (the ``paper`` preset)."""
    methods = [Controller(kind, f"{label} (authors')", preset="paper")
               for kind, label in (("pid", "PID"), ("mpc", "MPC"), ("scmpc", "SC-MPC"))]
    return {m.name: m for m in methods}


# ====================================================================== flying
@dataclass
class CellResult:
    """One (world, method) cell: pooled metrics over the seeds and each flight's own."""

    world: World
    method: str
    metrics: dict[str, Any]
    per_episode: list[dict[str, Any]]
    seconds: float = field(default=0.0, compare=False)

    @property
    def rmse_cm(self) -> float:
        return 100.0 * float(self.metrics["wall_normal_rmse"])

    @property
    def contact_flights(self) -> int:
        return int(self.metrics["collision_episodes"])


_KEPT = ("wall_normal_rmse", "wall_normal_mae", "rmse", "collisions", "collision_episodes", "min_wall_clearance",
         "episodes", "terminated_early")


def fly_cell(world: World, method: Method, seeds: Sequence[int], duration: float | None = None) -> CellResult:
    """Fly ``method`` in ``world`` on every seed (rows of one batched env)."""
    start = time.perf_counter()
    result = evaluate_batched(lambda envs: method.make(envs, world), ENV_ID, seeds, world.env_kwargs(duration))
    metrics = {k: v for k, v in result.metrics().items() if k in _KEPT}
    per_episode = [{"seed": e.seed, **{k: v for k, v in e.metrics().items() if k in _KEPT}} for e in result.episodes]
    return CellResult(world, method.name, metrics, per_episode, time.perf_counter() - start)


Job = tuple[World, Method]
Executor = Callable[[Sequence[Job], Sequence[int], float | None, Callable[[], object]], Sequence[CellResult]]
"""``executor(jobs, seeds, duration, on_cell)``: fly every job anywhere, call ``on_cell()`` after each, return the
results in the order of ``jobs``."""


def local_executor(workers: int = 1) -> Executor:
    """Fly the cells in this process (``workers`` 1) or in that many processes."""

    def run(jobs: Sequence[Job], seeds: Sequence[int], duration: float | None,
            on_cell: Callable[[], object]) -> list[CellResult]:
        if workers <= 1:
            out = []
            for world, method in jobs:
                out.append(fly_cell(world, method, seeds, duration))
                on_cell()
            return out
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        # spawned, not forked: the parent may hold threads (PyTorch, Ray) that a fork would copy half-way
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = [pool.submit(fly_cell, world, method, list(seeds), duration) for world, method in jobs]
            results = []
            for future in futures:
                results.append(future.result())
                on_cell()
            return results

    return run


def run_grid(worlds: Sequence[World], methods: Mapping[str, Method], seeds: Sequence[int], *,
             duration: float | None = None, executor: Executor | None = None, progress: bool = True,
             extra: Sequence[Job] = ()) -> list[CellResult]:
    """Every method in every world (and the ``extra`` jobs), in the grid's order; a tqdm bar counts the cells."""
    from tqdm import tqdm

    if not worlds or not methods:
        raise ValueError("the grid needs at least one world and one method")
    jobs: list[Job] = [(world, method) for world in worlds for method in methods.values()] + list(extra)
    run = executor or local_executor(1)
    with tqdm(total=len(jobs), unit="cell", disable=not progress, dynamic_ncols=True) as bar:
        results = list(run(jobs, [int(s) for s in seeds], duration, lambda: bar.update(1)))
    if len(results) != len(jobs):
        raise RuntimeError(f"the executor returned {len(results)} results for {len(jobs)} cells")
    return results


# ====================================================================== checks and reports
def _find(results: Sequence[CellResult], world: World, method: str) -> CellResult | None:
    return next((r for r in results if r.world == world and r.method == method), None)


ADAPTIVE, PPO, REFERENCE, TUNED_MPC = "SC-MPC adaptive", "PPO", "SC-MPC told the truth", "MPC"


def acceptance(results: Sequence[CellResult]) -> list[dict[str, Any]]:
    """The checks: the adaptive SC-MPC on every suction and push cell (RMSE <= 1.5x the reference's + 0.05 cm,
    never above the tuned MPC's, no contact where the reference has none), and on the nominal cell <= 0.1 cm;
    PPO with no contact where the reference has none and <= 0.5 cm on the nominal cell; under the realistic
    profile both with no contact and <= 1.0 cm. A check whose methods were not flown is left out."""
    checks: list[dict[str, Any]] = []
    worlds = list(dict.fromkeys(r.world for r in results))

    def add(check: str, value: Any, passed: bool, world: World | None = None) -> None:
        checks.append({"check": check, "world": None if world is None else world.label, "value": value,
                       "pass": bool(passed)})

    worst_ratio, worst_world = -math.inf, None
    above_mpc, new_contacts = [], []
    for world in worlds:
        adaptive, reference = _find(results, world, ADAPTIVE), _find(results, world, REFERENCE)
        if world.model_checked and adaptive is not None and reference is not None:
            limit = 1.5 * reference.rmse_cm + 0.05
            margin = adaptive.rmse_cm - limit
            if margin > worst_ratio:
                worst_ratio, worst_world = margin, world
            mpc = _find(results, world, TUNED_MPC)
            if mpc is not None and adaptive.rmse_cm > mpc.rmse_cm:
                above_mpc.append(world.label)
            if adaptive.contact_flights and not reference.contact_flights:
                new_contacts.append(world.label)
    if worst_world is not None:
        add("SC-MPC adaptive, every suction and push cell: RMSE - (1.5 x told-the-truth + 0.05 cm) <= 0 "
            "(worst cell, cm)", round(worst_ratio, 4), worst_ratio <= 0, worst_world)
        add("SC-MPC adaptive, every suction and push cell: RMSE never above tuned MPC's (cells above)",
            above_mpc, not above_mpc)
        add("SC-MPC adaptive, every suction and push cell: no contact where told-the-truth has none (cells)",
            new_contacts, not new_contacts)
    nominal = next((w for w in worlds if w.nominal), None)
    if nominal is not None:
        adaptive = _find(results, nominal, ADAPTIVE)
        if adaptive is not None:
            add("SC-MPC adaptive, nominal Table II: RMSE <= 0.1 cm", round(adaptive.rmse_cm, 4),
                adaptive.rmse_cm <= 0.1, nominal)
        ppo = _find(results, nominal, PPO)
        if ppo is not None:
            add("PPO, nominal Table II: RMSE <= 0.5 cm", round(ppo.rmse_cm, 4), ppo.rmse_cm <= 0.5, nominal)
    ppo_contacts = [w.label for w in worlds
                    if (p := _find(results, w, PPO)) is not None and (r := _find(results, w, REFERENCE)) is not None
                    and p.contact_flights and not r.contact_flights]
    if any(_find(results, w, PPO) is not None for w in worlds):
        add("PPO: no contact on any cell where told-the-truth has none (cells with contact)", ppo_contacts,
            not ppo_contacts)
    realistic = next((w for w in worlds if w.group == "realistic"), None)
    if realistic is not None:
        for name in (ADAPTIVE, PPO):
            cell = _find(results, realistic, name)
            if cell is not None:
                add(f"{name}, realistic profile: no contact and RMSE <= 1.0 cm",
                    f"{cell.rmse_cm:.2f} cm, {cell.contact_flights} flight(s) with contact",
                    cell.rmse_cm <= 1.0 and cell.contact_flights == 0, realistic)
    return checks


def _cell_text(cell: CellResult | None) -> str:
    if cell is None:
        return "-"
    text = f"{cell.rmse_cm:.2f}"
    if cell.contact_flights:
        text += f", {cell.contact_flights}/{cell.metrics['episodes']}"
    return text


def markdown_report(results: Sequence[CellResult], seeds: Sequence[int], checks: Sequence[dict[str, Any]],
                    seconds: float | None = None, note: str = "") -> str:
    """The grid as a Markdown table (worlds x methods: wall-normal RMSE in cm, and flights with contact), the
    realistic profile with the authors' settings beside the paper's Table II ratios, and the checks."""
    worlds = list(dict.fromkeys(r.world for r in results))
    realistic_authors = [r for r in results if r.world.group == "realistic" and r.method.endswith("(authors')")]
    methods = [m for m in dict.fromkeys(r.method for r in results) if not m.endswith("(authors')")]
    out = [note] if note else []
    out.append(f"`{ENV_ID}` (the paper's Table II sweep), command noise on, flights go on after a contact, "
               f"{len(seeds)} seeds a cell ({', '.join(map(str, seeds))}); every method is told only the nominal "
               f"model (k_s {PAPER_SUCTION['k_s']} N/m, d_thr {PAPER_SUCTION['d_thr']} m) except the reference, "
               f"SC-MPC told each world's true suction and push. Wall-normal RMSE (cm), then flights with wall contact "
               "when any.\n")
    out.append("| world | " + " | ".join(methods) + " |")
    out.append("|---|" + "---:|" * len(methods))
    for world in worlds:
        out.append(f"| {world.label} | " + " | ".join(_cell_text(_find(results, world, m)) for m in methods) + " |")
    out.append("")
    realistic = next((w for w in worlds if w.group == "realistic"), None)
    if realistic is not None and realistic_authors:
        out.append("**The realistic profile beside the paper's real flight** (Table II, wall-normal RMSE): ratios "
                   "to MPC's, since the profile is not tuned toward the paper's numbers.\n")
        out.append("| method | RMSE (cm) | flights with contact | / MPC's (this row's settings) | paper: / MPC's |")
        out.append("|---|---:|---:|---:|---:|")
        rows = [r for r in results if r.world == realistic]
        for cell in rows:
            authors = cell.method.endswith("(authors')")
            base = cell.method.removesuffix(" (authors')")
            mpc = _find(results, realistic, "MPC (authors')" if authors else "MPC")
            ratio = f"{cell.rmse_cm / mpc.rmse_cm:.2f}" if mpc is not None and mpc.rmse_cm > 0 else "-"
            paper = PAPER_TABLE_II_RMSE_X.get(base)
            paper_ratio = f"{paper / PAPER_TABLE_II_RMSE_X['MPC']:.2f}" if paper and authors else "-"
            out.append(f"| {cell.method} | {cell.rmse_cm:.2f} | {cell.contact_flights}/{cell.metrics['episodes']} | "
                       f"{ratio} | {paper_ratio} |")
        out.append("")
    if checks:
        out.append("Checks, as measured by this run:\n")
        out += [f"- {'pass' if c['pass'] else 'FAIL'}: {c['check']}"
                + (f" [{c['world']}]" if c.get("world") else "") + f" (measured {c['value']})" for c in checks]
        out.append("")
    if seconds is not None:
        out.append(f"The whole grid ({len(results)} cells of {len(seeds)} flights) took {seconds / 60:.1f} min.")
    return "\n".join(out)


def method_report(results: Sequence[CellResult], method: str, seeds: Sequence[int],
                  checks: Sequence[dict[str, Any]] = ()) -> str:
    """One method's row of the grid as a Markdown table beside the reference (SC-MPC told the truth), and the
    checks that name it: what a model card says about how the agent holds when the world is not the nominal one."""
    worlds = [w for w in dict.fromkeys(r.world for r in results) if _find(results, w, method) is not None]
    out = [f"`wall-inspector robustness` on `{ENV_ID}`, {len(seeds)} seeds a cell ({', '.join(map(str, seeds))}), "
           f"told nothing of the world it flies in (the reference, SC-MPC, is told each world's true suction and "
           "push). Wall-normal RMSE (cm), then flights with wall contact when any.\n",
           f"| world | {method} | SC-MPC told the truth |", "|---|---:|---:|"]
    out += [f"| {w.label} | {_cell_text(_find(results, w, method))} | {_cell_text(_find(results, w, REFERENCE))} |"
            for w in worlds]
    mine = [c for c in checks if c["check"].startswith(f"{method},") or c["check"].startswith(f"{method}:")]
    if mine:
        out += ["", *[f"- {'pass' if c['pass'] else 'FAIL'}: {c['check']}" + (f" [{c['world']}]" if c.get("world") else "")
                      + f" (measured {c['value']})" for c in mine]]
    return "\n".join(out) + "\n"


def results_json(results: Sequence[CellResult], seeds: Sequence[int], checks: Sequence[dict[str, Any]],
                 seconds: float | None = None) -> dict[str, Any]:
    return {
        "env_id": ENV_ID, "seeds": [int(s) for s in seeds], "told": dict(PAPER_SUCTION),
        "cells": [{"world": r.world.to_dict(), "method": r.method, "metrics": r.metrics,
                   "per_episode": r.per_episode, "seconds": round(r.seconds, 3)} for r in results],
        "checks": list(checks), "wall_time_s": None if seconds is None else round(seconds, 1),
    }


def plot_heatmap(results: Sequence[CellResult], path: str | Path) -> None:
    """Methods x worlds: wall-normal RMSE on a log colour scale, each cell annotated with its RMSE (cm) and,
    in red, its flights with contact."""
    import numpy as np
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure  # not pyplot: must not switch the caller's backend

    worlds = list(dict.fromkeys(r.world for r in results))
    methods = [m for m in dict.fromkeys(r.method for r in results) if not m.endswith("(authors')")]
    values = np.full((len(methods), len(worlds)), np.nan)
    contacts = np.zeros_like(values)
    for i, method in enumerate(methods):
        for j, world in enumerate(worlds):
            cell = _find(results, world, method)
            if cell is not None:
                values[i, j] = max(cell.rmse_cm, 1e-3)
                contacts[i, j] = cell.contact_flights
    figure = Figure(figsize=(max(8.0, 0.52 * len(worlds) + 2.5), 1.0 + 0.55 * len(methods)))
    ax = figure.add_subplot()
    norm = LogNorm(vmin=max(np.nanmin(values), 0.01), vmax=max(np.nanmax(values), 0.02))
    image = ax.imshow(values, cmap="viridis", norm=norm, aspect="auto")
    flights = max((int(r.metrics["episodes"]) for r in results), default=0)
    for i in range(len(methods)):
        for j in range(len(worlds)):
            if np.isfinite(values[i, j]):
                dark = norm(values[i, j]) > 0.6  # dark text on the bright end of viridis
                text = f"{values[i, j]:.2f}" if values[i, j] < 10 else f"{values[i, j]:.0f}"
                ax.text(j, i - 0.17, text, ha="center", va="center", fontsize=6, color="black" if dark else "white")
                if contacts[i, j]:
                    ax.text(j, i + 0.25, f"{int(contacts[i, j])}/{flights} hit", ha="center", va="center", fontsize=5.5,
                            color="#b00000" if dark else "#ff6060", fontweight="bold")
    ax.set_xticks(range(len(worlds)), [w.label for w in worlds], rotation=70, ha="right", fontsize=7)
    ax.set_yticks(range(len(methods)), methods, fontsize=8)
    colorbar = figure.colorbar(image, ax=ax, fraction=0.025)
    colorbar.set_label("wall-normal RMSE (cm)")
    ax.set_title("Told the nominal model, flown in other worlds: wall-normal RMSE (cm); red: flights that hit the wall",
                 fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=130)


def write_outputs(results: Sequence[CellResult], seeds: Sequence[int], out: str | Path,
                  seconds: float | None = None) -> tuple[str, list[dict[str, Any]]]:
    """``robustness.md``, ``robustness.json`` and ``robustness.png`` in ``out``; returns the Markdown and checks."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    checks = acceptance(results)
    text = markdown_report(results, seeds, checks, seconds)
    (out / "robustness.md").write_text(text + "\n")
    (out / "robustness.json").write_text(json.dumps(results_json(results, seeds, checks, seconds), indent=2) + "\n")
    plot_heatmap(results, out / "robustness.png")
    return text, checks
