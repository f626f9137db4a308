"""What ``cell --help`` and ``cell COMMAND --help`` show: the commands grouped by what they are
for, every default written one way (``(default: X)``), an example and the exit codes.

Why one module: the commands are defined in several modules (and new ones arrive); the help's
form is a property of the whole command line, so it is applied here once, after every command
has been added (:func:`finish_parser`), rather than repeated in each ``add_parser``.
"""

from __future__ import annotations

import argparse
import re
from typing import Any

#: The top-level help's groups, in order; a command not listed goes under "tools".
GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("run the cell", ("sim", "run", "tree", "replay", "soak", "init", "schema")),
    ("study the pivot", ("plan", "analyze", "check-tilt", "pivot", "compare", "sweep")),
    ("hardware", ("check-hardware", "calibrate", "emulate")),
    ("tools", ("perceive", "train-perception")),
)

#: An example for each command (shown under its --help).
EXAMPLES: dict[str, tuple[str, ...]] = {
    "sim": (
        "cell sim --cycles 1                       # the shipped example, one cycle",
        "cell sim --config my/cell.yaml --set workflow.cycles=3 --json out/sim.json",
        "cell sim --config my/cell.yaml --resume    # continue after Ctrl-C or a crash",
    ),
    "run": ("cell check-hardware --config hw.yaml && cell run --config hw.yaml --cycles 1",),
    "tree": ("cell tree --config my/cell.yaml --out out/tree", "cell tree --types"),
    "replay": ("cell replay out/cell_ticks.jsonl", "cell replay out/cell_ticks.jsonl --all"),
    "soak": ("cell soak --cycles 100 --faults default --seed 1 --json out/soak.json",),
    "init": ("cell init mycell && cell sim --config mycell/cell.yaml --cycles 1",),
    "schema": ("cell schema --json out/cell.schema.json",),
    "plan": ("cell plan --part bushing", "cell plan --all --json out/plans.json"),
    "analyze": ("cell analyze --part bushing --la 0.3 0.5 0.7 0.9 --out out",),
    "check-tilt": ("cell check-tilt --part bushing --la 0.9 --alpha 0.3142",),
    "pivot": ("cell pivot --part bushing --trials 10 --seed 0 --json out/pivot.json",),
    "compare": ("cell compare --part bushing --trials 10 --seed 2200 --json out/compare.json",),
    "sweep": ("cell sweep --part bushing cookie_can --trials 10 --workers 2 --out out/sweep",),
    "check-hardware": ("cell check-hardware --config hw.yaml --json out/hw.json",),
    "calibrate": ("cell calibrate --layout my/layout.yaml --views 8 --seed 0",),
    "emulate": (
        "cell emulate --report out/emulator.json &   # prints 'ready' once every device listens",
        "cell check-hardware --config $(cell emulate --print-config)",
    ),
    "perceive": ("cell perceive --scenes 50 --seed 0 --json out/perceive.json",),
    "train-perception": ("cell train-perception --scenes 300 --epochs 24 --out out/unet.onnx",),
}

#: Exit codes, for every command (each may add its own meaning of 1).
EXIT_1: dict[str, str] = {
    "sim": "the cell stopped or ran out of time",
    "run": "the cell stopped or ran out of time",
    "soak": "an exception escaped the tree or a part was lost track of",
    "check-tilt": "the Tilt leaves force balance",
    "check-hardware": "a device check failed",
    "pivot": "",
    "compare": "",
}
SIGNALS = ("sim", "run", "soak")


def epilog(command: str) -> str:
    lines = []
    examples = EXAMPLES.get(command)
    if examples:
        lines += ["example:" if len(examples) == 1 else "examples:"]
        lines += [f"  {e}" for e in examples]
        lines.append("")
    codes = ["0 done"]
    if EXIT_1.get(command):
        codes.append(f"1 {EXIT_1[command]}")
    codes.append("2 bad input or an output that cannot be written (one line; nothing started)")
    if command in SIGNALS:
        codes.append("130/143 Ctrl-C/SIGTERM (arm stopped, log flushed, state saved)")
    lines.append("exit status:")
    lines += [f"  {c}" for c in codes]
    return "\n".join(lines)


_OLD_DEFAULT = re.compile(r"\s*\(([^()]*)\)\s*$")


class CellHelpFormatter(argparse.HelpFormatter):
    """Every default as ``(default: X)`` at the end of its option's help; a help that already
    says its default (in its own words) is left as it is. The epilog keeps its lines."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = re.sub(r"\(default (?!:)", "(default: ", action.help or "")
        default = action.default
        if (
            default is None
            or default is False
            or default is argparse.SUPPRESS
            or default == []
            or not action.option_strings
            or "default" in text
        ):
            return text
        shown = " ".join(map(str, default)) if isinstance(default, list | tuple) else str(default)
        match = _OLD_DEFAULT.search(text)
        if match and shown.endswith("/" + match.group(1)):  # a shipped file, named shortly
            return f"{text[: match.start()]} (default: {match.group(1)})"
        if match and (match.group(1) == shown or _same_number(match.group(1), default)):
            text = text[: match.start()]  # the old "(0.4)" form: said once, the new way
        return f"{text} (default: {shown})" if text else f"default: {shown}"

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if "\n" in text:  # the epilog: examples and exit codes, line by line
            return "\n".join(indent + line for line in text.splitlines())
        return super()._fill_text(text, width, indent)


def _same_number(text: str, default: Any) -> bool:
    try:
        return float(text) == float(default)
    except (TypeError, ValueError):
        return False


def _top_epilog(sub: argparse._SubParsersAction) -> str:
    helps = {a.dest: a.help or "" for a in sub._choices_actions}
    listed: set[str] = set()
    lines = ["start here: `cell sim` runs the shipped example cell in the twin", ""]
    groups = [(title, [c for c in names if c in helps]) for title, names in GROUPS]
    others = [c for c in helps if not any(c in names for _, names in GROUPS)]
    if others:
        groups = [*groups[:-1], (groups[-1][0], groups[-1][1] + others)]
    width = max(len(c) for c in helps) + 2
    for title, names in groups:
        if not names:
            continue
        lines.append(f"{title}:")
        for name in names:
            lines.append(f"  {name:<{width}}{helps[name]}")
            listed.add(name)
        lines.append("")
    lines.append("`cell COMMAND --help` shows a command's options, an example and its exit codes.")
    lines.append("exit status: 0 done; 1 the work failed (see each command); 2 bad input")
    return "\n".join(lines)


def finish_parser(parser: argparse.ArgumentParser, sub: argparse._SubParsersAction) -> None:
    """Apply the help's form to ``parser`` and every command in ``sub``."""
    from pathlib import Path

    from cell.preflight import OUTPUTS

    for name, p in sub.choices.items():
        p.formatter_class = CellHelpFormatter
        folders = {dest for dest, kind in OUTPUTS.get(name, ()) if kind == "dir"}
        for action in p._actions:
            if action.type is Path and action.metavar is None and action.option_strings:
                action.metavar = "DIR" if action.dest in folders else "FILE"
        if p.epilog is None:
            p.epilog = epilog(name)
    parser.formatter_class = CellHelpFormatter
    parser.epilog = _top_epilog(sub)
    sub.help = "one of the commands below"
    sub._choices_actions.clear()  # listed by group in the epilog instead of flat


__all__ = ["CellHelpFormatter", "EXAMPLES", "GROUPS", "epilog", "finish_parser"]
