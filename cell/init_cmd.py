"""`cell init DIR`: an editable configuration, behaviour tree and part catalogue to start from.

Why: a new cell starts as a copy of a working one. The three files written here are the shipped
example's (the bushing-machining cell that `cell sim` runs), wired to each other by relative
paths -- the configuration names ``tree.yaml`` and ``parts.yaml`` beside it -- so the folder runs
as it is (``cell sim --config DIR/cell.yaml``) and every change is the user's own. Existing files
are never overwritten without ``--force``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cell.errors import UserError

DATA = Path(__file__).resolve().parent / "data"

CONFIG_NAME, TREE_NAME, CATALOGUE_NAME = "cell.yaml", "tree.yaml", "parts.yaml"

HEADER = """\
# A cell configuration written by `cell init`: the shipped bushing-machining example, with its
# behaviour tree ({tree}) and part catalogue ({catalogue}) beside it. Edit any of the three.
#
#   cell sim --config {config} --cycles 1     # run it in the twin
#   cell tree --config {config}               # print and draw its tree
#   cell sim --config {config} --set workflow.cycles=3   # change one key for one run
#
# Paths in this file (tree, catalogue) are relative to this file; the outputs (log:) are
# relative to the folder you run `cell` from. Numbers are SI; each key's name carries its unit;
# docs/configuration.md documents every key and `cell schema` prints its JSON Schema.
"""


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "init",
        help="write an example configuration, tree and catalogue to start from",
        description="Writes DIR/cell.yaml (the configuration), DIR/tree.yaml (the behaviour "
        "tree) and DIR/parts.yaml (the part catalogue): the shipped bushing-machining cell, "
        "which runs as it is. Refuses to overwrite unless --force.",
    )
    p.add_argument("dir", type=Path, metavar="DIR", help="folder to write the three files into")
    p.add_argument("--force", action="store_true", help="overwrite files that exist")
    p.set_defaults(func=cmd_init)


def _config_text(config: Path) -> str:
    """The shipped example with the tree and the catalogue pointed at the copies."""
    lines = (DATA / "bushing_cell.yaml").read_text(encoding="utf-8").splitlines()
    body = [ln for ln in lines if not ln.startswith("#")]
    out: list[str] = []
    for ln in body:
        if ln.startswith("  backend:"):
            out.append(ln)
            out.append(f"  catalogue: {CATALOGUE_NAME}     # part catalogue, beside this file")
            continue
        if ln.strip() == "file: trees/bushing_machining.yaml":
            out.append(f"  file: {TREE_NAME}          # behaviour tree, beside this file")
            continue
        out.append(ln)
    text = "\n".join(out) + "\n"
    if f"catalogue: {CATALOGUE_NAME}" not in text or f"file: {TREE_NAME}" not in text:
        raise AssertionError("the shipped example changed shape; update cell/init_cmd.py")
    head = HEADER.format(config=config, tree=TREE_NAME, catalogue=CATALOGUE_NAME)
    return head + text


def cmd_init(args: argparse.Namespace) -> int:
    folder: Path = args.dir
    targets = {
        folder / CONFIG_NAME: _config_text(folder / CONFIG_NAME),
        folder / TREE_NAME: (DATA / "trees" / "bushing_machining.yaml").read_text("utf-8"),
        folder / CATALOGUE_NAME: (DATA / "parts.yaml").read_text("utf-8"),
    }
    existing = [str(p) for p in targets if p.exists()]
    if existing and not args.force:
        raise UserError(f"{', '.join(existing)}: exists; pass --force to overwrite")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for path, text in targets.items():
            path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise UserError(f"{folder}: cannot write: {exc.strerror}") from None
    for path in targets:
        print(f"wrote {path}")
    print(f"next: cell sim --config {folder / CONFIG_NAME} --cycles 1")
    return 0


__all__ = ["add_parser", "cmd_init"]
