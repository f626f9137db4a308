"""YAML with line numbers: every error about a configuration names the file, the line and the key.

PyYAML's plain loaders forget where a value came from. We compose the node graph once and keep a
map from each key path (``("workflow", "cycles")``, ``("tree", "children", 2, "type")``) to the
line it sits on, so a validation error found later -- by pydantic or by the tree builder -- can
still point at the line an integrator has to fix.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

KeyPath = tuple[str | int, ...]


class ConfigError(Exception):
    """A configuration the cell refuses: ``file:line: key: reason`` (exit status 2)."""

    def __init__(self, source: str, line: int | None, key: str, reason: str) -> None:
        self.source, self.line, self.key, self.reason = source, line, key, reason
        where = f"{source}:{line}" if line is not None else source
        super().__init__(f"{where}: {key}: {reason}" if key else f"{where}: {reason}")


@dataclass
class LinedDocument:
    """A loaded YAML document and the line (1-based) of every key path in it."""

    source: str
    data: Any
    lines: dict[KeyPath, int] = field(default_factory=dict)

    def line_of(self, path: Sequence[str | int]) -> int | None:
        """The line of ``path`` or of its nearest ancestor that has one."""
        p = tuple(path)
        while p:
            if p in self.lines:
                return self.lines[p]
            p = p[:-1]
        return self.lines.get((), None)

    def error(self, path: Sequence[str | int], reason: str) -> ConfigError:
        return ConfigError(self.source, self.line_of(path), dotted(path), reason)


def dotted(path: Sequence[str | int]) -> str:
    """``("tree", "children", 2, "type")`` -> ``tree.children[2].type``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


class UniqueKeyLoader(yaml.SafeLoader):
    """Safe YAML that refuses repeated keys (a silently dropped setting is a hidden bug)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set[object] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def _index_lines(node: yaml.Node, path: KeyPath, lines: dict[KeyPath, int]) -> None:
    lines.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for key_node, value_node in node.value:
            key = key_node.value
            lines[(*path, key)] = key_node.start_mark.line + 1
            _index_lines(value_node, (*path, key), lines)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _index_lines(item, (*path, i), lines)


def load_yaml(path: str | Path) -> LinedDocument:
    """Read ``path``; a missing file or broken YAML is a :class:`ConfigError` with its line."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(str(p), None, "", f"cannot read: {exc.strerror}") from None
    return parse_yaml(text, str(p))


def parse_yaml(text: str, source: str) -> LinedDocument:
    try:
        node = yaml.compose(text, Loader=UniqueKeyLoader)
        data = yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 -- a SafeLoader
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        raise ConfigError(source, line, "", f"not valid YAML: {exc.problem or exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(source, None, "", f"not valid YAML: {exc}") from None
    lines: dict[KeyPath, int] = {}
    if node is not None:
        _index_lines(node, (), lines)
    return LinedDocument(source, data, lines)
