"""The learning curve of a training run, drawn for its model card.

``model_card.json`` keeps the evaluation callback's history as ``training.eval_curve``: rows of
``[env steps, mean evaluation return, mean episode length (steps)]``, one per evaluation during
training (deterministic actions, the run's evaluation episodes). :func:`plot_learning_curve` draws
the return against the env steps, the episode length on a second axis (an agent that learns to
survive before it learns to track shows it there first), and marks the checkpoint that was shipped.
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["LEARNING_CURVE_PNG", "plot_learning_curve", "shipped_timesteps", "card_curve"]

LEARNING_CURVE_PNG = "learning_curve.png"


def shipped_timesteps(checkpoint: str | None) -> int | None:
    """The env steps of the shipped checkpoint from the card's ``checkpoint`` text (``"best/ at N timesteps ..."``)."""
    match = re.search(r"at (\d+) timesteps", checkpoint or "")
    return int(match.group(1)) if match else None


def plot_learning_curve(curve: Sequence[Sequence[float]], path: str | Path, *, title: str = "",
                        shipped_at: int | None = None, note: str = "") -> Path:
    """Draw ``curve`` (rows of env steps, mean return, mean episode length in steps) into ``path`` (PNG)."""
    from matplotlib.figure import Figure  # not pyplot: must not switch the caller's backend

    rows = [tuple(float(v) for v in row[:3]) for row in curve]
    if len(rows) < 2:
        raise ValueError(f"a learning curve needs at least two evaluations, got {len(rows)}")
    # a resumed run continues from its last checkpoint: where the steps go back, a new line starts
    segments: list[list[tuple[float, ...]]] = [[rows[0]]]
    for row in rows[1:]:
        if row[0] <= segments[-1][-1][0]:
            segments.append([])
        segments[-1].append(row)
    figure = Figure(figsize=(6.4, 3.4))
    ax = figure.add_subplot()
    lengths = ax.twinx()
    for i, part in enumerate(segments):
        steps = [r[0] / 1e6 for r in part]
        ax.plot(steps, [r[1] for r in part], color="#1f77b4", marker="o", markersize=3,
                label="mean evaluation return" if i == 0 else None)
        lengths.plot(steps, [r[2] for r in part], color="#7f7f7f", linestyle="--", linewidth=1.0,
                     label="mean episode length (steps)" if i == 0 else None)
    ax.set_xlabel("env steps (millions)")
    ax.set_ylabel("mean evaluation return", color="#1f77b4")
    ax.grid(alpha=0.3)
    if len(segments) > 1:
        note = (note + "; " if note else "") + "a new line where a resumed run went on from an earlier checkpoint"
    lengths.set_ylabel("mean episode length (steps)", color="#7f7f7f")
    lengths.set_ylim(bottom=0)
    if shipped_at is not None:
        ax.axvline(shipped_at / 1e6, color="#2ca02c", linewidth=1.2, label="shipped checkpoint")
    handles = ax.get_legend_handles_labels()[0] + lengths.get_legend_handles_labels()[0]
    ax.legend(handles=handles, fontsize=7, loc="lower right")
    ax.set_title(title, fontsize=9)
    lines = textwrap.wrap(note, 120) if note else []
    if lines:
        figure.text(0.01, 0.01, "\n".join(lines), fontsize=6.5, color="#555555", va="bottom")
    figure.tight_layout(rect=(0, 0.045 * len(lines), 1, 1))
    path = Path(path)
    figure.savefig(path, dpi=120)
    return path


def card_curve(card: dict[str, Any]) -> list[list[float]] | None:
    """The card's evaluation history, if it has one worth drawing (two or more evaluations)."""
    curve = (card.get("training") or {}).get("eval_curve")
    return curve if isinstance(curve, list) and len(curve) >= 2 else None
