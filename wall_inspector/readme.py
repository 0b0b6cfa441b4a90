"""``wall-inspector readme``: put result tables that commands wrote into README.md and the docs.

Result commands write Markdown files (``bench-env --markdown``, ``bench-mpc
--markdown``, ``compare --out``); this command copies them between markers in the
README and the pages of ``docs/`` (:mod:`wall_inspector.readme_pages`: where blocks
stand, the headlines cut from them), and ``--agents`` tabulates the model cards that
``train --ship`` wrote, so no figure in the README or the documentation is typed by hand::

    <!-- BEGIN bench-env -->
    ...replaced...
    <!-- END bench-env -->
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
from pathlib import Path

from wall_inspector.readme_pages import Page, relink, with_figure


def replace_block(text: str, name: str, content: str) -> str:
    pattern = re.compile(rf"(<!-- BEGIN {re.escape(name)} -->\n)(.*?)(<!-- END {re.escape(name)} -->)", re.S)
    if not pattern.search(text):
        raise ValueError(f"README has no block '<!-- BEGIN {name} -->' ... '<!-- END {name} -->'")
    return pattern.sub(lambda m: m.group(1) + content.rstrip() + "\n" + m.group(3), text)


_BASE_NAMES = {"scmpc": "SC-MPC", "pid": "PID"}


def _envs(training: dict) -> str:
    """How a card's envs ran: ``"256 batched"`` or ``"32 in 2 processes"``."""
    n = training.get("n_envs")
    if n is None:
        return "-"
    if training.get("vector") == "batched":
        return f"{n} batched"
    workers = training.get("n_workers", 0)
    return f"{n} in {workers} processes" if workers else f"{n} in 1 process"


def agents_table(pretrained: Path) -> str:
    """One row per shipped agent, from its ``model_card.json`` (timesteps: the env steps the agent's
    training spent, a controller's demonstrations or a teacher's labels included)."""
    from agents.checkpoints import training_env_steps

    lines = [
        "| agent | timesteps | training wall time | env steps/s | envs | episodes completed | "
        "position RMSE | wall-normal RMSE | contact steps |",
        "|---|---:|---:|---:|---|---:|---:|---:|---:|",
    ]
    seeds = set()
    for card_path in sorted(pretrained.glob("*/model_card.json")):
        card = json.loads(card_path.read_text())
        t, m = card["training"], card["evaluation"]["metrics"]
        seeds.add(len(card["evaluation"]["seeds"]))
        name = f"`{card['env_id'].split('/')[-1]}`"
        if card.get("residual"):
            name += f", residual on {_BASE_NAMES.get(card['residual'], card['residual'])}"
        warm = (t.get("warm_start") or {}).get("controller")
        if warm:
            name += f", warm-started from {_BASE_NAMES.get(warm, warm)} demonstrations"
        teacher = (t.get("teacher") or {}).get("controller")
        if teacher:  # a row of its own: it learned from the controller, not alone
            name += f", distilled from {_BASE_NAMES.get(teacher, teacher)} (DAgger)"
        rate = f"{t['steps_per_s']:,.0f}" if t["total_timesteps"] else "-"
        envs = f"{card['config']['teacher']['envs']} batched" if teacher and "config" in card else _envs(t)
        lines.append(
            f"| [{name}]({card_path.parent.as_posix()}/model_card.md) | {training_env_steps(t):,} | "
            f"{t['total_wall_time_s'] / 60:.1f} min | {rate} | {envs} | {100 * m['completed']:.0f} % | "
            f"{100 * m['position_rmse_m']:.2f} cm | {100 * m['wall_normal_rmse_m']:.2f} cm | {m['collisions']} |")
    lines += ["", f"From each agent's model card: trained by `wall-inspector train ... --ship` on this 2-core machine "
              f"(the card holds the exact command and, in its threads row, the load other jobs put on the machine; "
              f"timesteps include a controller's demonstrations or a teacher's labelled steps; env steps/s include "
              f"the evaluations during training), "
              f"evaluated on the task's nominal settings with command noise "
              f"over {'/'.join(str(n) for n in sorted(seeds))} seeds by the evaluation function of the comparison tables."]
    return "\n".join(lines) + "\n"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--readme", default="README.md",
                        help="the README to update; the pages of the docs/ folder beside it are updated too (default README.md)")
    parser.add_argument("--set", dest="blocks", action="append", default=[], metavar="NAME=FILE",
                        help="replace block NAME, wherever it stands, with the Markdown in FILE (repeatable); the blocks "
                             "cut from it follow, and a picture beside FILE with its name and .png goes into docs/NAME.png")
    parser.add_argument("--agents", action="store_true",
                        help="replace block 'agents' with a table of the shipped agents' model cards")


def _read(path: Path, argument: str) -> str:
    try:
        return path.read_text()
    except OSError as exc:
        raise SystemExit(f"{argument}: cannot read {path} ({exc.strerror or exc})") from None


def _fill(pages: list[Page], root: Path, name: str, content: str, source: str, figure: Path | None = None) -> list[str]:
    """Put ``content`` into block ``name`` of every page that holds it; the lines to print."""
    done = []
    for page in pages:
        if name in page.names:
            text = with_figure(relink(content, page.path, root), name, figure, page.path, root)
            page.text = replace_block(page.text, name, text)
            page.changed = True
            done.append(f"{page.path}: block {name!r} <- {source}")
    return done


def run(args: argparse.Namespace) -> int:
    from wall_inspector.readme_pages import DERIVED, read_pages

    path = Path(args.readme)
    root = path.parent
    # every input is read and every block found before any page is written
    pages = read_pages(path, _read)
    held = set().union(*(page.names for page in pages))
    report: list[str] = []
    figures: list[tuple[Path, Path]] = []
    for item in args.blocks:
        name, sep, file = item.partition("=")
        if not sep:
            raise SystemExit(f"--set takes NAME=FILE, got {item!r}")
        content = _read(Path(file), f"--set {item}")
        if name not in held:
            raise SystemExit(f"--set {item}: README has no block '<!-- BEGIN {name} -->' ... '<!-- END {name} -->', "
                             f"nor has any page under {root / 'docs'}")
        picture = Path(file).with_suffix(".png")
        figure = root / "docs" / f"{name}.png" if picture.is_file() and picture != Path(file) else None
        if figure is not None:
            figures.append((picture, figure))
        report += _fill(pages, root, name, content, file, figure)
        for derived, (source, cut) in DERIVED.items():
            if source == name and derived in held:
                try:
                    part = cut(content)
                except ValueError as exc:
                    raise SystemExit(f"--set {item}: {file} {exc} (block {derived!r} is cut from it)") from None
                report += _fill(pages, root, derived, part, f"{file} (cut)")
    if args.agents:
        from agents.policy import PRETRAINED_DIR

        if "agents" not in held:
            raise SystemExit(f"--agents: README has no block '<!-- BEGIN agents -->', nor has any page under {root / 'docs'}")
        pretrained = PRETRAINED_DIR.relative_to(Path.cwd()) if PRETRAINED_DIR.is_relative_to(Path.cwd()) else PRETRAINED_DIR
        report += _fill(pages, root, "agents", agents_table(pretrained), f"{PRETRAINED_DIR}/*/model_card.json")
    for picture, figure in figures:
        figure.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(picture, figure)
        report.append(f"{figure} <- {picture}")
    for page in pages:
        if page.changed:
            page.path.write_text(page.text)
    for line in report:
        print(line)
    return 0
