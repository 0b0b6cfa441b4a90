"""The pages ``wall-inspector readme`` writes: README.md and the documentation pages under ``docs/``.

A block (``<!-- BEGIN name -->`` ... ``<!-- END name -->``) may stand in the README, in any page of
``docs/`` or in several; ``--set name=FILE`` fills it wherever it stands. Some blocks are cut from
another's content, so that a headline in the README or a budget table on its own page always
matches the full table it comes from (:data:`DERIVED`). Block content is written with its links
relative to the repository root (the README's folder); in a page of ``docs/`` they are rewritten
relative to that page, so the same table links right in both.
"""

from __future__ import annotations

import os
import posixpath
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

_BLOCK = re.compile(r"<!-- BEGIN ([\w.-]+) -->\n")
_LINK = re.compile(r"(\]\()([^)\s]+)(\))")


def _cut(marker: str) -> Callable[[str], str]:
    """A cutter: the paragraph whose first line starts with ``marker`` and the table or list after it."""

    def cut(text: str) -> str:
        lines = text.splitlines()
        start = next((i for i, line in enumerate(lines) if line.startswith(marker)), None)
        if start is None:
            raise ValueError(f"has no paragraph starting {marker!r}")
        end = start
        while end < len(lines) and lines[end].strip():  # the paragraph
            end += 1
        while end < len(lines) and not lines[end].strip():
            end += 1
        if end == len(lines) or not lines[end].startswith(("|", "- ")):
            raise ValueError(f"has no table or list after the paragraph starting {marker!r}")
        while end < len(lines) and lines[end].startswith(("|", "- ")):  # the table or list
            end += 1
        return "\n".join(lines[start:end]) + "\n"

    return cut


# block -> (the block it is cut from, the cutter)
DERIVED: dict[str, tuple[str, Callable[[str], str]]] = {
    "compare-headline": ("compare", _cut("**Table II**")),
    "compare-budget": ("compare", _cut("**Optimisation budget**")),
    "compare-paper-sim-budget": ("compare-paper-sim", _cut("**Optimisation budget**")),
    "robustness-headline": ("robustness", _cut("Checks, as measured by this run:")),
}


@dataclass
class Page:
    path: Path
    text: str
    changed: bool = False
    names: set[str] = field(default_factory=set)


def read_pages(readme: Path, read: Callable[[Path, str], str]) -> list[Page]:
    """The README (read with ``read``, which names the file in its error) and every Markdown page under
    ``docs/`` beside it, in that order."""
    paths = [readme]
    docs = readme.parent / "docs"
    if docs.is_dir():
        paths += sorted(docs.rglob("*.md"))
    pages = []
    for path in paths:
        text = read(path, f"--readme {path}" if path == readme else str(path))
        pages.append(Page(path, text, names=set(_BLOCK.findall(text))))
    return pages


def relink(content: str, page: Path, root: Path) -> str:
    """``content``'s relative links, written relative to ``root``, rewritten relative to ``page``'s folder."""
    folder = page.parent.resolve()
    if folder == root.resolve():
        return content

    def rewrite(match: re.Match) -> str:
        target = match.group(2)
        if target.startswith(("#", "/", "mailto:")) or "://" in target:
            return match.group(0)
        path, hash_, anchor = target.partition("#")
        moved = posixpath.normpath(Path(os.path.relpath(root.resolve() / path, folder)).as_posix())
        return match.group(1) + moved + hash_ + anchor + match.group(3)

    return _LINK.sub(rewrite, content)


def with_figure(content: str, name: str, figure: Path | None, page: Path, root: Path) -> str:
    """``content`` with a link to the block's figure (``docs/NAME.png``) at its end, when it has one."""
    if figure is None:
        return content
    link = os.path.relpath(figure.resolve(), page.parent.resolve())
    return content.rstrip() + f"\n\n![{name}: the figure written beside the table]({Path(link).as_posix()})\n"
