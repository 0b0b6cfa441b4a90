"""The README and the documentation pages as a reader meets them: in the site's order, with their code blocks."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
_FENCE = re.compile(r"^```([\w+-]*)\n(.*?)^```\n", re.S | re.M)
_HEADING = re.compile(r"^#{1,6} (.+)$", re.M)


@dataclass(frozen=True)
class Block:
    page: Path
    heading: str  # the last heading above the block
    language: str  # "" when the fence names none
    code: str
    line: int  # 1-based line of the opening fence

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line} ({self.heading})"


def _nav_entries(nav) -> list[str]:
    entries: list[str] = []
    for item in nav:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        if isinstance(value, list):
            entries += _nav_entries(value)
        else:
            entries.append(value)
    return entries


def nav() -> list[str]:
    """The site's pages (paths relative to docs/), in the order of mkdocs.yml's nav."""
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    return _nav_entries(config["nav"])


def page_source(entry: str) -> Path:
    """The file a nav entry is built from: a page of docs/, or a repository file docs/hooks.py publishes."""
    published = {site: repository for repository, site in _published().items()}
    return ROOT / published[entry] if entry in published else DOCS / entry


def _published() -> dict[str, str]:
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
    assert spec is not None and spec.loader is not None
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    return hooks.published()


def pages() -> list[Path]:
    """README.md, then every Markdown page of the site in nav order (notebooks excluded: the notebook
    tests run those)."""
    return [ROOT / "README.md"] + [page_source(entry) for entry in nav() if entry.endswith(".md")]


def blocks(page: Path) -> list[Block]:
    text = page.read_text()
    prose = _FENCE.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)  # a "# comment" in a block is no heading
    found = []
    for match in _FENCE.finditer(text):
        headings = _HEADING.findall(prose[:match.start()])
        line = text.count("\n", 0, match.start()) + 1
        found.append(Block(page, headings[-1] if headings else "", match.group(1), match.group(2), line))
    return found


def all_blocks() -> list[Block]:
    return [block for page in pages() for block in blocks(page)]


def block_under(heading: str, language: str) -> Block:
    """The first ``language`` block under the heading (of any level) ``heading``, in any page."""
    for block in all_blocks():
        if block.heading == heading and block.language == language:
            return block
    raise AssertionError(f"no {language} block under a heading {heading!r} in the README or the docs")


def block_containing(text: str, language: str) -> Block:
    for block in all_blocks():
        if block.language == language and text in block.code:
            return block
    raise AssertionError(f"no {language} block containing {text!r} in the README or the docs")


def shell_commands(code: str) -> list[str]:
    """The commands of a shell block: continuation lines joined, comments dropped."""
    joined = re.sub(r"\\\n\s*", " ", code)
    commands = []
    for line in joined.splitlines():
        command = re.split(r"\s+#", line, maxsplit=1)[0].strip()
        if command and not command.startswith("#"):
            commands.append(command)
    return commands
