"""Where a result came from: the git commit of the code that made it, and what was changed on top.

Shipped agents (their model cards) and tuned presets (their provenance) record the commit they were
made from; :func:`git_state` is the one place that asks git.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

__all__ = ["git_state", "git_commit", "REPOSITORY"]

REPOSITORY = Path(__file__).resolve().parent.parent  # the checkout this package runs from (if it is one)


def git_state(paths: tuple[str, ...] = (), exclude: tuple[str, ...] = ()) -> dict[str, Any] | None:
    """``{"commit": sha, "uncommitted": [files]}``: the checked-out commit and the tracked files under ``paths``
    (all, if empty; minus ``exclude``) that differ from it; ``None`` outside a git checkout."""
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPOSITORY, capture_output=True, text=True, timeout=10)
        if commit.returncode != 0:
            return None
        pathspec = [*paths, *[f":!{p}" for p in exclude]]
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", *pathspec],
                                cwd=REPOSITORY, capture_output=True, text=True, timeout=10)
        if status.returncode != 0:
            return None
        files = sorted(line[3:] for line in status.stdout.splitlines() if line.strip())
        return {"commit": commit.stdout.strip(), "uncommitted": files}
    except (OSError, subprocess.SubprocessError):
        return None


def git_commit() -> str:
    """The checked-out commit, short, with ``+uncommitted`` if tracked files changed (``unknown`` outside git)."""
    state = git_state()
    if state is None:
        return "unknown"
    return state["commit"][:7] + ("+uncommitted" if state["uncommitted"] else "")
