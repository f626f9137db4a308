"""The part catalogue: a YAML data file read once, at the edge, into :class:`Part` objects.

Every error names the file and the key (``parts.<name>.<key>``) and says what is wrong, so an
integrator can fix a catalogue without reading code. Dimensions are millimetres in the file
(the key names say so) and metres in the returned objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from drivers.parts import HOLE_SHAPES, Part
from trees.yaml_lines import UniqueKeyLoader

REQUIRED = ("length_mm", "outer_mm", "hole_mm", "hole_shape", "mass_kg")
OPTIONAL = ("rigid", "open_ends", "paper", "description")


def default_catalogue_path() -> Path:
    """The catalogue shipped with the package (Table 3's seven parts)."""
    return Path(__file__).resolve().parent / "data" / "parts.yaml"


class CatalogueError(ValueError):
    """A malformed catalogue; the message names the file and the key."""


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


def _number(path: Path, key: str, value: object, *, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CatalogueError(f"{path}: {key}: expected a number, got {value!r}")
    if positive and value <= 0:
        raise CatalogueError(f"{path}: {key}: must be > 0, got {value!r}")
    return float(value)


def _parse_part(path: Path, name: str, entry: object) -> Part:
    where = f"parts.{name}"
    if not isinstance(entry, dict):
        raise CatalogueError(f"{path}: {where}: expected a mapping of keys, got {entry!r}")
    missing = [k for k in REQUIRED if k not in entry]
    if missing:
        raise CatalogueError(
            f"{path}: {where}.{missing[0]}: missing (required: {', '.join(REQUIRED)})"
        )
    unknown = [k for k in entry if k not in REQUIRED + OPTIONAL]
    if unknown:
        raise CatalogueError(
            f"{path}: {where}.{unknown[0]}: unknown key; valid keys: "
            f"{', '.join(REQUIRED + OPTIONAL)}"
        )
    length = _number(path, f"{where}.length_mm", entry["length_mm"]) * 1e-3
    outer = _number(path, f"{where}.outer_mm", entry["outer_mm"]) * 1e-3
    hole = _number(path, f"{where}.hole_mm", entry["hole_mm"]) * 1e-3
    mass = _number(path, f"{where}.mass_kg", entry["mass_kg"])
    shape = entry["hole_shape"]
    if shape not in HOLE_SHAPES:
        raise CatalogueError(
            f"{path}: {where}.hole_shape: {shape!r} is not one of {', '.join(HOLE_SHAPES)}"
        )
    if hole >= outer:
        raise CatalogueError(
            f"{path}: {where}.hole_mm: {entry['hole_mm']} must be smaller than outer_mm "
            f"{entry['outer_mm']}"
        )
    rigid = entry.get("rigid", True)
    if not isinstance(rigid, bool):
        raise CatalogueError(f"{path}: {where}.rigid: expected true or false, got {rigid!r}")
    open_ends = entry.get("open_ends", 2)
    if isinstance(open_ends, bool) or open_ends not in (1, 2):
        raise CatalogueError(f"{path}: {where}.open_ends: expected 1 or 2, got {open_ends!r}")
    paper = entry.get("paper", {})
    if not isinstance(paper, dict):
        raise CatalogueError(f"{path}: {where}.paper: expected a mapping, got {paper!r}")
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
        raise CatalogueError(f"{p}: cannot read the part catalogue: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise CatalogueError(f"{p}: not UTF-8 text (byte {exc.start})") from None
    try:
        data = yaml.load(text, Loader=UniqueKeyLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise CatalogueError(f"{p}: not valid YAML{at}: {getattr(exc, 'problem', exc)}") from None
    if not isinstance(data, dict) or "parts" not in data:
        raise CatalogueError(f"{p}: parts: missing top-level key 'parts'")
    entries = data["parts"]
    if not isinstance(entries, dict) or not entries:
        raise CatalogueError(f"{p}: parts: expected a non-empty mapping of part names")
    parts = {}
    for name, entry in entries.items():
        if not isinstance(name, str) or not name:
            raise CatalogueError(f"{p}: parts: part names must be non-empty strings, got {name!r}")
        parts[name] = _parse_part(p, name, entry)
    return Catalogue(path=p, parts=parts)
