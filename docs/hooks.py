"""MkDocs hooks of the documentation site (``hooks:`` in mkdocs.yml).

- Files of the repository that the site shows are published into it without a copy: the notebooks
  as tutorials (mkdocs-jupyter renders their committed outputs; nothing is executed) and the shipped
  agents' model cards.
- Pages link to those files by their path in the repository (``../../notebooks/01_wall_suction.ipynb``),
  so a page read on its own in the repository links right; in the site such a link points at the
  published page.
- The command reference is every command's ``--help``, put into the page when the site is built,
  so it cannot fall behind the commands.
"""

from __future__ import annotations

import os
import posixpath
import re
from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent.parent
DOCS = "docs"  # docs_dir, relative to the repository root
COMMANDS_MARKER = "<!-- help of every command -->"
_LINK = re.compile(r"(\]\()([^)\s#]+)((?:#[^)\s]*)?\))")


def published() -> dict[str, str]:
    """Repository path -> path in the site (relative to docs_dir) of every file published into it."""
    files = {f"notebooks/{p.name}": f"tutorials/{p.name}" for p in sorted((ROOT / "notebooks").glob("*.ipynb"))}
    for card in sorted((ROOT / "agents" / "pretrained").glob("*/model_card.md")):
        files[card.relative_to(ROOT).as_posix()] = f"results/model-cards/{card.parent.name}.md"
    return files


@event_priority(-100)  # after mkdocs-jupyter has wrapped the notebooks of docs_dir (there are none)
def on_files(files: Files, config) -> Files:
    from mkdocs_jupyter.plugin import NotebookFile

    for repository_path, site_path in published().items():
        source = str(ROOT / repository_path)
        file = File.generated(config, site_path, abs_src_path=source)
        if site_path.endswith(".ipynb"):  # rendered by mkdocs-jupyter, which reads the notebook from its path
            file = NotebookFile(file, **config)
            file.abs_src_path = source
        files.append(file)
    return files


def _site_link(page_uri: str, target: str, files: dict[str, str]) -> str | None:
    """The link from page ``page_uri`` to the published copy of ``target`` (a path relative to the
    page in the repository), or None when ``target`` is not a published file."""
    if "://" in target or target.startswith(("/", "mailto:")):
        return None
    repository_path = posixpath.normpath(posixpath.join(DOCS, posixpath.dirname(page_uri), target))
    site_path = files.get(repository_path)
    if site_path is None:
        return None
    return posixpath.relpath(site_path, posixpath.dirname(page_uri) or ".")


def command_reference() -> str:
    """Each command's ``--help`` as printed by ``wall-inspector COMMAND --help`` in a 100-column terminal."""
    import importlib

    from wall_inspector.cli import COMMANDS, OneLineParser

    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal's width
    try:
        parts = []
        for name, (module_name, help_text) in COMMANDS.items():
            parser = OneLineParser(prog=f"wall-inspector {name}", description=help_text)
            importlib.import_module(module_name).add_arguments(parser)
            parts.append(f"## `{name}`\n\n{help_text[0].upper()}{help_text[1:]}.\n\n```text\n{parser.format_help().rstrip()}\n```\n")
        return "\n".join(parts)
    finally:
        if columns is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = columns


def on_page_markdown(markdown: str, page, config, files) -> str:
    uri = page.file.src_uri
    if uri.startswith("results/model-cards/"):  # a model card: say where it lives in the repository
        source = next(r for r, s in published().items() if s == uri)
        markdown += f"\n\n*This card is `{source}`, written by `wall-inspector train --ship`.*\n"
    if COMMANDS_MARKER in markdown:
        markdown = markdown.replace(COMMANDS_MARKER, command_reference())
    targets = published()

    def relink(match: re.Match) -> str:
        link = _site_link(uri, match.group(2), targets)
        return match.group(0) if link is None else match.group(1) + link + match.group(3)

    return _LINK.sub(relink, markdown)
