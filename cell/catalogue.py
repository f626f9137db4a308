"""The part catalogue: a YAML data file read once, at the edge, into :class:`Part` objects.

Every error names the file, the line and the key (``parts.<name>.<key>``) and says what is
wrong, so an integrator can fix a catalogue without reading code; a configuration that names
the catalogue reports its errors at the catalogue's line, not at its own. Dimensions are
millimetres in the file (the key names say so) and metres in the returned objects.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from drivers.parts import HOLE_SHAPES, Part
from trees.yaml_lines import ConfigError, UniqueKeyLoader, _index_lines

REQUIRED = ("length_mm", "outer_mm", "hole_mm", "hole_shape", "mass_kg")
OPTIONAL = ("rigid", "open_ends", "paper", "description")


def default_catalogue_path() -> Path:
    """The catalogue shipped with the package (Table 3's seven parts)."""
    return Path(__file__).resolve().parent / "data" / "parts.yaml"


class CatalogueError(ValueError):
    """A malformed catalogue: ``file:line: key: reason``, each kept apart (``source``,
    ``line``, ``key``, ``reason``) so a command reports it as the catalogue's own error."""

    def __init__(self, source: str, line: int | None, key: str, reason: str) -> None:
        self.source, self.line, self.key, self.reason = source, line, key, reason
        super().__init__(str(ConfigError(source, line, key, reason)))

    def as_config_error(self) -> ConfigError:
        return ConfigError(self.source, self.line, self.key, self.reason)


@dataclass(frozen=True)
class _File:
    """The catalogue being read and the line of each of its keys."""

    path: Path
    lines: dict[tuple[str | int, ...], int]

    def error(self, key: str, reason: str) -> CatalogueError:
        """``key`` dotted (``parts.bushing.outer_mm``): the line of it or of its nearest parent."""
        parts: tuple[str | int, ...] = tuple(key.split(".")) if key else ()
        while parts and parts not in self.lines:
            parts = parts[:-1]
        return CatalogueError(str(self.path), self.lines.get(parts), key, reason)


@dataclass(frozen=True)
class Catalogue:
    path: Path
    parts: dict[str, Part]

    def get(self, name: str) -> Part:
        try:
            return self.parts[name]
        except KeyError:
            raise ValueError(
                f"unknown part {name!r} in {self.path}; known parts: {', '.join(self.parts)}"
            ) from None


def _number(f: _File, key: str, value: object, *, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise f.error(key, f"expected a number, got {value!r}")
    if positive and value <= 0:
        raise f.error(key, f"must be > 0, got {value!r}")
    return float(value)


def _parse_part(f: _File, name: str, entry: object) -> Part:
    where = f"parts.{name}"
    if not isinstance(entry, dict):
        raise f.error(where, f"expected a mapping of keys, got {entry!r}")
    # An unknown key first: a misspelt key is also a missing one, and its own line is the fix.
    unknown = [k for k in entry if k not in REQUIRED + OPTIONAL]
    if unknown:
        close = difflib.get_close_matches(str(unknown[0]), REQUIRED + OPTIONAL, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise f.error(f"{where}.{unknown[0]}",
                      f"unknown key{hint}; valid keys: {', '.join(REQUIRED + OPTIONAL)}")
    missing = [k for k in REQUIRED if k not in entry]
    if missing:
        raise f.error(f"{where}.{missing[0]}", f"missing (required: {', '.join(REQUIRED)})")
    length = _number(f, f"{where}.length_mm", entry["length_mm"]) * 1e-3
    outer = _number(f, f"{where}.outer_mm", entry["outer_mm"]) * 1e-3
    hole = _number(f, f"{where}.hole_mm", entry["hole_mm"]) * 1e-3
    mass = _number(f, f"{where}.mass_kg", entry["mass_kg"])
    shape = entry["hole_shape"]
    if shape not in HOLE_SHAPES:
        raise f.error(f"{where}.hole_shape", f"{shape!r} is not one of {', '.join(HOLE_SHAPES)}")
    if hole >= outer:
        raise f.error(f"{where}.hole_mm", f"{entry['hole_mm']} must be smaller than outer_mm "
                      f"{entry['outer_mm']}")
    rigid = entry.get("rigid", True)
    if not isinstance(rigid, bool):
        raise f.error(f"{where}.rigid", f"expected true or false, got {rigid!r}")
    open_ends = entry.get("open_ends", 2)
    if isinstance(open_ends, bool) or open_ends not in (1, 2):
        raise f.error(f"{where}.open_ends", f"expected 1 or 2, got {open_ends!r}")
    paper = entry.get("paper", {})
    if not isinstance(paper, dict):
        raise f.error(f"{where}.paper", f"expected a mapping, got {paper!r}")
    return Part(
        name=name,
        length=length,
        outer=outer,
        hole=hole,
        hole_shape=shape,
        mass=mass,
        rigid=rigid,
        open_ends=int(open_ends),
        reference=dict(paper),
    )


def load_catalogue(path: str | Path | None = None) -> Catalogue:
    """Read and validate a catalogue file (the shipped one by default)."""
    p = Path(path) if path is not None else default_catalogue_path()
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise CatalogueError(str(p), None, "", f"cannot read the part catalogue: {exc.strerror}") \
            from None
    except UnicodeDecodeError as exc:
        raise CatalogueError(str(p), None, "", f"not UTF-8 text (byte {exc.start})") from None
    try:
        node = yaml.compose(text, Loader=UniqueKeyLoader)
        data = yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 -- a SafeLoader
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        at = f" (column {mark.column + 1})" if mark is not None else ""
        raise CatalogueError(str(p), line, "", f"not valid YAML{at}: "
                             f"{getattr(exc, 'problem', None) or exc}") from None
    lines: dict[tuple[str | int, ...], int] = {}
    if node is not None:
        _index_lines(node, (), lines)
    f = _File(p, lines)
    if not isinstance(data, dict) or "parts" not in data:
        raise f.error("parts", "missing top-level key 'parts'")
    entries = data["parts"]
    if not isinstance(entries, dict) or not entries:
        raise f.error("parts", "expected a non-empty mapping of part names")
    parts = {}
    for name, entry in entries.items():
        if not isinstance(name, str) or not name:
            raise f.error("parts", f"part names must be non-empty strings, got {name!r}")
        parts[name] = _parse_part(f, name, entry)
    return Catalogue(path=p, parts=parts)
