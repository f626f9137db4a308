"""``--set KEY.PATH=VALUE``: change one key of the configuration from the command line.

Why: a run that differs from the file by one value (a seed, a force limit, a fault rate) should
not need an edited copy of the file. The value is read as YAML (``3`` is a number, ``[0.5,
0.44]`` a list, ``true`` a boolean, ``abc`` text), put into the document at its dotted path
before validation, and then validated exactly like the file -- so a bad value is refused the
same way, with ``--set KEY=VALUE`` in place of ``file:line`` in the message. The dotted path
follows the file's sections (``workflow.cycles``, ``skills.grasp.speed_m_s``,
``cell.layout.bin_center``); a number indexes a list (``tree.children.2.type``).

Relative paths inside the configuration (the tree file, the catalogue) stay relative to the
configuration file, whether they come from the file or from ``--set``.
"""

from __future__ import annotations

import argparse
import copy
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import yaml

from cell.errors import UserError
from trees.yaml_lines import ConfigError, KeyPath, LinedDocument, dotted


@dataclass
class Override:
    """One ``--set``: where, what, and the text the user typed (for messages)."""

    path: KeyPath
    value: Any
    text: str


def parse_set(text: str) -> Override:
    """``"workflow.cycles=3"`` -> ``Override(("workflow", "cycles"), 3, ...)``."""
    key, eq, raw = text.partition("=")
    key = key.strip()
    if not eq or not key:
        raise UserError(f"--set {text}: expected KEY.PATH=VALUE, e.g. --set workflow.cycles=3")
    parts: list[str | int] = []
    for part in key.split("."):
        if not part:
            raise UserError(f"--set {text}: empty name in the key {key!r}")
        parts.append(int(part) if part.isdigit() else part)
    if isinstance(parts[0], int):
        raise UserError(f"--set {text}: a key starts with a section name, e.g. workflow")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise UserError(f"--set {text}: the value is not valid YAML: {problem}") from None
    return Override(tuple(parts), value, text)


@dataclass
class OverriddenDocument(LinedDocument):
    """A configuration document with values set from the command line: an error about one of
    them names the ``--set`` instead of a line of the file."""

    overrides: list[Override] = field(default_factory=list)

    def error(self, path: Sequence[str | int], reason: str) -> ConfigError:
        p = tuple(path)
        for o in reversed(self.overrides):
            n = min(len(p), len(o.path))
            if n and p[:n] == o.path[:n] and (len(p) >= len(o.path) or p not in self.lines):
                return ConfigError(f"--set {o.text}", None, dotted(p), reason)
        return super().error(path, reason)


def _put(data: dict[str, Any], o: Override) -> None:
    node: Any = data
    for i, part in enumerate(o.path[:-1]):
        where = dotted(o.path[: i + 1])
        if isinstance(node, dict):
            if part not in node or node[part] is None:
                node[part] = {}
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int):
            if part >= len(node):
                raise UserError(
                    f"--set {o.text}: {where}: no item {part} (the list has {len(node)})"
                )
            node = node[part]
        else:
            raise UserError(f"--set {o.text}: {dotted(o.path[:i])} holds {node!r}, not a section")
        if not isinstance(node, dict | list):
            raise UserError(f"--set {o.text}: {where} holds {node!r}, not a section")
    last = o.path[-1]
    if isinstance(node, list):
        if not isinstance(last, int) or last >= len(node):
            raise UserError(f"--set {o.text}: {dotted(o.path)}: no such item of the list")
        node[last] = o.value
    else:
        node[last] = o.value


def apply_sets(doc: LinedDocument, sets: Sequence[str]) -> LinedDocument:
    """``doc`` with every ``--set`` applied, in order (a later one wins)."""
    if not sets:
        return doc
    overrides = [parse_set(s) for s in sets]
    data = copy.deepcopy(doc.data) if doc.data is not None else {}
    if not isinstance(data, dict):
        return doc  # validation refuses the file itself, naming it
    for o in overrides:
        _put(data, o)
    return OverriddenDocument(doc.source, data, dict(doc.lines), overrides)


def add_set_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY.PATH=VALUE",
        help="change one configuration key, validated like the file (repeatable), e.g. "
        "--set workflow.cycles=3 --set safety.ft_abort_force_n=60",
    )


__all__ = ["OverriddenDocument", "Override", "add_set_argument", "apply_sets", "parse_set"]
