"""``wall-inspector readme``: put result tables that commands wrote into README.md.

Result commands write Markdown files (``bench-env --markdown``, ``compare --out``);
this command copies them between markers in the README, so no figure in the README
is typed by hand::

    <!-- BEGIN bench-env -->
    ...replaced...
    <!-- END bench-env -->
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path


def replace_block(text: str, name: str, content: str) -> str:
    pattern = re.compile(rf"(<!-- BEGIN {re.escape(name)} -->\n)(.*?)(<!-- END {re.escape(name)} -->)", re.S)
    if not pattern.search(text):
        raise ValueError(f"README has no block '<!-- BEGIN {name} -->' ... '<!-- END {name} -->'")
    return pattern.sub(lambda m: m.group(1) + content.rstrip() + "\n" + m.group(3), text)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--readme", default="README.md", help="the README to update (default README.md)")
    parser.add_argument("--set", dest="blocks", action="append", default=[], metavar="NAME=FILE",
                        help="replace block NAME with the Markdown in FILE (repeatable)")


def run(args: argparse.Namespace) -> int:
    path = Path(args.readme)
    text = path.read_text()
    for item in args.blocks:
        name, sep, file = item.partition("=")
        if not sep:
            raise SystemExit(f"--set takes NAME=FILE, got {item!r}")
        text = replace_block(text, name, Path(file).read_text())
        print(f"{path}: block {name!r} <- {file}")
    path.write_text(text)
    return 0
