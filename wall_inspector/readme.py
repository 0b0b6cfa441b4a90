"""``wall-inspector readme``: put result tables that commands wrote into README.md.

Result commands write Markdown files (``bench-env --markdown``, ``bench-mpc
--markdown``, ``compare --out``); this command copies them between markers in the
README, and ``--agents`` tabulates the model cards that ``train --ship`` wrote, so no
figure in the README is typed by hand::

    <!-- BEGIN bench-env -->
    ...replaced...
    <!-- END bench-env -->
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path


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
    parser.add_argument("--readme", default="README.md", help="the README to update (default README.md)")
    parser.add_argument("--set", dest="blocks", action="append", default=[], metavar="NAME=FILE",
                        help="replace block NAME with the Markdown in FILE (repeatable)")
    parser.add_argument("--agents", action="store_true",
                        help="replace block 'agents' with a table of the shipped agents' model cards")


def _read(path: Path, argument: str) -> str:
    try:
        return path.read_text()
    except OSError as exc:
        raise SystemExit(f"{argument}: cannot read {path} ({exc.strerror or exc})") from None


def run(args: argparse.Namespace) -> int:
    path = Path(args.readme)
    text = _read(path, f"--readme {path}")  # every input is read and every block found before the README is written
    for item in args.blocks:
        name, sep, file = item.partition("=")
        if not sep:
            raise SystemExit(f"--set takes NAME=FILE, got {item!r}")
        try:
            text = replace_block(text, name, _read(Path(file), f"--set {item}"))
        except ValueError as exc:
            raise SystemExit(f"--set {item}: {exc}") from None
        print(f"{path}: block {name!r} <- {file}")
    if args.agents:
        from agents.policy import PRETRAINED_DIR

        text = replace_block(text, "agents", agents_table(PRETRAINED_DIR.relative_to(Path.cwd())
                                                          if PRETRAINED_DIR.is_relative_to(Path.cwd()) else PRETRAINED_DIR))
        print(f"{path}: block 'agents' <- {PRETRAINED_DIR}/*/model_card.json")
    path.write_text(text)
    return 0
