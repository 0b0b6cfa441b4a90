"""Pictures of the proof: the residual against the regressor that localises it, before and after, and
open-loop predictions against measurements.

:func:`plot_all` writes, into a folder:

``residual_vs_regressor.png``
    one row per discovered effect (or, if none, the regressor that best localises the
    residual): the held-out force residual along the effect's direction against that
    effect's localising regressor, before (nominal model) and after (discovered model),
    with bin means.
``residual_time.png``
    the held-out force residual magnitude against time, before and after.
``prediction.png``
    logged against predicted displacement over the prediction horizon, per world axis,
    for the nominal and the discovered model.
``unexplained_shape.png``, ``unexplained_where.png``
    when a residual is left that the model does not explain: its shape against the state it
    depends on, or the residual against time and its mean over the position map.
``residual_on_surface.png``
    with walls or bodies in the scene: the held-out residual toward the surface on a map of
    the surface, position along it against height (:mod:`discovery.surface_map`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["plot_all"]


def _binned(x: np.ndarray, y: np.ndarray, bins: int = 15) -> tuple[np.ndarray, np.ndarray]:
    finite = np.isfinite(x)
    x, y = x[finite], y[finite]
    if x.size < bins:
        return x, y
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    index = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    centres = np.array([x[index == b].mean() for b in range(len(edges) - 1) if np.any(index == b)])
    means = np.array([y[index == b].mean() for b in range(len(edges) - 1) if np.any(index == b)])
    return centres, means


def _thin(n: int, limit: int = 4000) -> np.ndarray:
    return np.arange(0, n, max(1, n // limit))


def _margins(fig, *, left: float = 0.9, right: float = 0.25, bottom: float = 0.6, top: float = 0.45,
             hspace: float = 0.0, wspace: float = 0.0, rows: int = 1, columns: int = 1) -> None:
    """Fixed margins and gaps in inches, instead of ``tight_layout``.

    ``tight_layout`` measures every tick label to place the axes and so draws each figure
    twice; it took a third of ``discover``'s plotting time. The figures here have fixed
    sizes and labels, so fixed margins fit them.
    """
    width, height = fig.get_size_inches()
    axis_h = (height - bottom - top - hspace * (rows - 1)) / rows
    axis_w = (width - left - right - wspace * (columns - 1)) / columns
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height, top=1 - top / height,
                        hspace=hspace / axis_h, wspace=wspace / axis_w)


def plot_all(found, out_dir: str | Path) -> list[Path]:
    """Write the figures of a fitted :class:`~discovery.workflow.Discovery` into ``out_dir``."""
    # Figure objects, not pyplot: writing files must not switch the caller's backend (notebooks)
    from matplotlib.figure import Figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    regs = {r.name: r for r in found.regressors_}
    before, after = found.residual_before_, found.residual_after_
    keep = _thin(len(before))

    # ---------------------------------------------------------------- residual vs regressor
    rows = []
    for effect in found.effects_:
        where = found.where_[effect.name]
        name = where.get("regressor")
        if name in (None, "everywhere"):
            name = "time"
        direction = np.asarray(where.get("direction_world") or (0.0, 0.0, 1.0))
        rows.append((effect.name, regs.get(name, regs["time"]), direction))
    if not rows:
        name = found.where_before_.get("regressor")
        name = name if name in regs else "time"
        direction = np.asarray(found.where_before_.get("direction_world") or (0.0, 0.0, 1.0))
        rows.append(("no effect named", regs[name], direction))
    fig = Figure(figsize=(11, 3.6 * len(rows)))
    axes = fig.subplots(len(rows), 2, squeeze=False, sharey="row")
    for (label, reg, direction), (ax_b, ax_a) in zip(rows, axes):
        x = reg.values
        for ax, residual, title, colour in ((ax_b, before, "nominal model", "tab:red"),
                                            (ax_a, after, "discovered model", "tab:blue")):
            y = residual @ direction
            ax.plot(x[keep], y[keep], ".", ms=2, alpha=0.3, color=colour)
            cx, cy = _binned(x, y)
            ax.plot(cx, cy, "-o", color="k", ms=3, lw=1.2, label="bin means")
            ax.axhline(0.0, color="grey", lw=0.8)
            ax.set_xlabel(f"{reg.name} ({reg.unit})")
            ax.set_title(f"{label}: held-out residual, {title}")
            ax.legend(loc="best", fontsize=8)
        ax_b.set_ylabel(f"force residual along [{', '.join(f'{c:.2f}' for c in direction)}] (N)")
    _margins(fig, top=0.4, hspace=0.95, wspace=0.2, rows=len(rows), columns=2)
    path = out / "residual_vs_regressor.png"
    fig.savefig(path, dpi=90)
    written.append(path)

    # ---------------------------------------------------------------- residual vs time
    fig = Figure(figsize=(11, 3.5))
    ax = fig.subplots()
    t = found.data_.times
    ax.plot(t[keep], np.linalg.norm(before, axis=1)[keep], ".", ms=2, color="tab:red", alpha=0.5,
            label=f"nominal ({found.gap_before_['force_rms_N']:.3f} N RMS)")
    ax.plot(t[keep], np.linalg.norm(after, axis=1)[keep], ".", ms=2, color="tab:blue", alpha=0.5,
            label=f"discovered ({found.gap_after_['force_rms_N']:.3f} N RMS)")
    ax.set_xlabel("time in log (s)")
    ax.set_ylabel("|force residual| (N)")
    ax.set_title("held-out force residual (paper Eq. 28)")
    ax.legend(loc="upper right")
    _margins(fig, top=0.4)
    path = out / "residual_time.png"
    fig.savefig(path, dpi=90)
    written.append(path)

    # ---------------------------------------------------------------- predicted vs measured
    fig = Figure(figsize=(12, 4))
    axes = fig.subplots(1, 3)
    start_b, pred_b, meas_b = found.prediction_before_
    _, pred_a, _ = found.prediction_after_
    for axis, ax in enumerate(axes):
        if len(meas_b) == 0:
            break
        measured = meas_b[:, axis] - start_b[:, axis]
        ax.plot(measured, pred_b[:, axis] - start_b[:, axis], ".", ms=3, color="tab:red", alpha=0.5, label="nominal")
        ax.plot(measured, pred_a[:, axis] - start_b[:, axis], ".", ms=3, color="tab:blue", alpha=0.5,
                label="discovered")
        low, high = float(np.min(measured)), float(np.max(measured))
        ax.plot([low, high], [low, high], "k-", lw=0.8)
        ax.set_xlabel(f"logged displacement {'xyz'[axis]} (m)")
        ax.set_ylabel(f"predicted displacement {'xyz'[axis]} (m)")
        ax.legend(loc="upper left", fontsize=8)
    before_cm, after_cm = 100 * found.gap_before_["prediction_rms_m"], 100 * found.gap_after_["prediction_rms_m"]
    fig.suptitle(f"open-loop predictions over {found.horizon_s:g} s replaying the logged thrust (held-out): "
                 f"{before_cm:.2f} cm -> {after_cm:.2f} cm RMS")
    _margins(fig, left=0.8, top=0.5, wspace=0.85, columns=3)
    path = out / "prediction.png"
    fig.savefig(path, dpi=90)
    written.append(path)
    # ---------------------------------------------------------------- shape of an unexplained residual
    shape = (found.unexplained_ or {}).get("shape")
    if shape:
        reg = regs[shape["regressor"]]
        direction = np.asarray(shape["direction_world"], dtype=float)
        fig = Figure(figsize=(6.5, 4.0))
        ax = fig.add_subplot()
        sample = _thin(len(after))
        ax.plot(reg.values[sample], (after @ direction)[sample], ".", ms=2, alpha=0.3, color="0.5",
                label="held-out residual along its mean direction")
        ax.plot(shape["knots"], shape["force_N_at_knots"], "o-", color="C3",
                label=f"piecewise-linear shape ({100 * shape['explained_fraction']:.0f} % explained)")
        ax.set_xlabel(f"{shape['regressor']} ({shape['unit']})")
        ax.set_ylabel("force (N)")
        ax.set_title("unexplained residual: no effect of the library fits it")
        ax.legend(fontsize=8)
        _margins(fig, left=0.8, top=0.4)
        path = out / "unexplained_shape.png"
        fig.savefig(path, dpi=110)
        written.append(path)
    from discovery.surface_map import plot_surface_map

    # ---------------------------------------------------------------- where an unexplained residual lives
    left = found.unexplained_ or {}
    if left.get("lives_in") in ("time (periodic)", "time (slow)", "position"):
        direction = np.asarray(left.get("direction_world") or (0.0, 0.0, 1.0), dtype=float)
        along = after @ direction
        fig = Figure(figsize=(11, 3.8))
        ax_t, ax_m = fig.subplots(1, 2)
        sample = _thin(len(after))
        ax_t.plot(found.data_.times[sample], along[sample], ".", ms=2, color="0.4")
        ax_t.set_xlabel("time in log (s)")
        ax_t.set_ylabel(f"held-out residual along {np.round(direction, 2).tolist()} (N)")
        time = left.get("time") or {}
        ax_t.set_title(f"in time: peak {time.get('peak_hz')} Hz, {time.get('peak_amplitude_N')} N amplitude")
        cells = left.get("position_cells") or []
        if cells:
            u_edges = sorted({c["along_m"][0] for c in cells} | {c["along_m"][1] for c in cells})
            h_edges = sorted({c["height_m"][0] for c in cells} | {c["height_m"][1] for c in cells})
            values = np.full((len(h_edges) - 1, len(u_edges) - 1), np.nan)
            for cell in cells:
                i, j = u_edges.index(cell["along_m"][0]), h_edges.index(cell["height_m"][0])
                values[j, i] = float(np.asarray(cell["force_N"]) @ direction)
            limit = float(np.nanmax(np.abs(values))) or 1.0
            mesh = ax_m.pcolormesh(u_edges, h_edges, values, cmap="coolwarm", vmin=-limit, vmax=limit)
            fig.colorbar(mesh, ax=ax_m, label="N")
            ax_m.set_xlabel(f"{left['position'].get('along')} (m)")
            ax_m.set_ylabel("height (m)")
            ax_m.set_title("mean over the position map, along that direction")
        _margins(fig, left=0.8, top=0.45, wspace=0.8, columns=2)
        path = out / "unexplained_where.png"
        fig.savefig(path, dpi=90)
        written.append(path)

    surface = plot_surface_map(found, out)
    if surface is not None:
        written.append(surface)
    return written
