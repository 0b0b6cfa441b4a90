"""``wall-inspector notebooks``: run the notebooks top to bottom, optionally saving their outputs.

The test suite runs every notebook with ``WALL_INSPECTOR_FAST=1`` (short flights, few
points) on a copy, so committed notebooks are never modified by tests; ``--save``
writes the outputs back into the notebooks (how the committed outputs are made).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

NOTEBOOK_DIR = Path(__file__).resolve().parent.parent / "notebooks"


def execute(path: str | Path, fast: bool = True, timeout: int = 600):
    """Execute a notebook in its own folder and return the executed notebook object."""
    import nbformat
    from nbclient import NotebookClient

    path = Path(path)
    notebook = nbformat.read(path, as_version=4)
    previous = os.environ.get("WALL_INSPECTOR_FAST")
    os.environ["WALL_INSPECTOR_FAST"] = "1" if fast else "0"
    os.environ.setdefault("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    try:
        NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                       resources={"metadata": {"path": str(path.parent)}}).execute()
    finally:
        if previous is None:
            os.environ.pop("WALL_INSPECTOR_FAST", None)
        else:
            os.environ["WALL_INSPECTOR_FAST"] = previous
    return notebook


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("paths", nargs="*", help="notebooks (default: every notebook in notebooks/)")
    parser.add_argument("--fast", action="store_true", help="WALL_INSPECTOR_FAST=1: short flights, few points")
    parser.add_argument("--save", action="store_true", help="write the outputs back into the notebooks")
    parser.add_argument("--timeout", type=int, default=900, help="seconds per cell (default 900)")


def run(args: argparse.Namespace) -> int:
    try:
        import nbclient  # noqa: F401
        import nbformat
    except ImportError as exc:
        raise SystemExit(f"the notebooks command needs the 'notebooks' extra ({exc.name} is missing): "
                         "pip install 'wall-inspector[notebooks]' (make test and make demo install it)") from None

    paths = [Path(p) for p in args.paths] or sorted(NOTEBOOK_DIR.glob("*.ipynb"))
    for path in paths:  # all of them checked before the first one runs
        if not path.is_file() or path.suffix != ".ipynb":
            raise SystemExit(f"{path}: not a notebook file (.ipynb)")
    for path in paths:
        start = time.perf_counter()
        notebook = execute(path, fast=args.fast, timeout=args.timeout)
        print(f"{path}: ran in {time.perf_counter() - start:.0f} s")
        if args.save:
            nbformat.write(notebook, path)
            print(f"  saved outputs into {path}")
    return 0
