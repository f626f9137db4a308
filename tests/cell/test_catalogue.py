"""Tests of :func:`cell.catalogue.load_catalogue`: the shipped Table 3 parts and every way a
hand-written catalogue can be wrong (each error must name the file and the dotted key)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from cell.catalogue import (
    OPTIONAL,
    REQUIRED,
    Catalogue,
    CatalogueError,
    default_catalogue_path,
    load_catalogue,
)
from drivers.parts import Part

from .conftest import TABLE3_PARTS as TABLE3

# name: (length m, outer m, hole m, hole_shape, rigid, open_ends)
EXPECTED = {
    "bushing": (0.068, 0.034, 0.028, "circle", True, 2),
    "medicine_bottle": (0.083, 0.035, 0.028, "circle", True, 1),
    "plastic_cup": (0.073, 0.048, 0.044, "circle", True, 1),
    "cookie_can": (0.160, 0.066, 0.060, "circle", True, 1),
    "wiring_duct": (0.122, 0.060, 0.057, "rectangle", True, 2),
    "mounting_rail": (0.083, 0.0076, 0.0064, "rectangle", True, 2),
    "water_bottle": (0.161, 0.030, 0.025, "circle", False, 1),
}


def _valid_entry() -> dict[str, Any]:
    return {
        "length_mm": 68,
        "outer_mm": 34,
        "hole_mm": 28,
        "hole_shape": "circle",
        "mass_kg": 0.156,
    }


def _write(tmp_path: Path, data: Any, name: str = "parts.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def _write_foo(tmp_path: Path, **changes: Any) -> Path:
    """A catalogue with one part ``foo``; a change of ``None`` deletes that key."""
    entry = _valid_entry()
    for key, value in changes.items():
        if value is None:
            entry.pop(key, None)
        else:
            entry[key] = value
    return _write(tmp_path, {"parts": {"foo": entry}})


def _error(path: Path) -> str:
    with pytest.raises(ValueError) as info:
        load_catalogue(path)
    assert isinstance(info.value, CatalogueError)
    message = str(info.value)
    assert str(path) in message
    return message


# --- the shipped catalogue -----------------------------------------------------------------


def test_shipped_catalogue_has_the_seven_table3_parts() -> None:
    catalogue = load_catalogue()
    assert isinstance(catalogue, Catalogue)
    assert catalogue.path == default_catalogue_path()
    assert list(catalogue.parts) == list(TABLE3)
    for name, part in catalogue.parts.items():
        assert isinstance(part, Part)
        assert part.name == name


@pytest.mark.parametrize("name", TABLE3)
def test_shipped_dimensions_are_in_metres(name: str) -> None:
    length, outer, hole, shape, rigid, open_ends = EXPECTED[name]
    part = load_catalogue().get(name)
    assert part.length == pytest.approx(length, abs=1e-12)
    assert part.outer == pytest.approx(outer, abs=1e-12)
    assert part.hole == pytest.approx(hole, abs=1e-12)
    assert part.hole_shape == shape
    assert part.rigid is rigid
    assert part.open_ends == open_ends
    assert 0 < part.mass < 1  # kg, not converted like the lengths


def test_shipped_bushing_in_detail() -> None:
    bushing = load_catalogue().get("bushing")
    assert bushing.length == pytest.approx(0.068)
    assert bushing.outer == pytest.approx(0.034)
    assert bushing.hole == pytest.approx(0.028)
    assert bushing.hole_shape == "circle"
    assert bushing.mass == pytest.approx(0.156)
    assert bushing.rigid is True
    # The paper's row is kept for comparison.
    assert bushing.reference["delta_mm"] == pytest.approx(7.2)
    # Eq. 3 with the default 20 mm finger reproduces Table 3's delta.
    assert bushing.delta(0.020) == pytest.approx(0.0072, abs=1e-4)


def test_shipped_special_parts() -> None:
    catalogue = load_catalogue()
    assert catalogue.get("wiring_duct").hole_shape == "rectangle"
    assert catalogue.get("mounting_rail").hole_shape == "rectangle"
    assert catalogue.get("water_bottle").rigid is False
    rigid = [n for n, p in catalogue.parts.items() if p.rigid]
    assert rigid == [n for n in TABLE3 if n != "water_bottle"]


def test_load_by_str_and_path_give_the_same_parts() -> None:
    path = default_catalogue_path()
    assert load_catalogue(str(path)).parts == load_catalogue(path).parts


# --- a valid hand-written catalogue ---------------------------------------------------------


def test_minimal_valid_entry_loads_with_defaults(tmp_path: Path) -> None:
    path = _write_foo(tmp_path)
    catalogue = load_catalogue(path)
    assert catalogue.path == path
    foo = catalogue.get("foo")
    assert (foo.length, foo.outer, foo.hole) == pytest.approx((0.068, 0.034, 0.028))
    assert foo.rigid is True
    assert foo.open_ends == 2
    assert foo.reference == {}


def test_optional_keys_are_read(tmp_path: Path) -> None:
    path = _write_foo(
        tmp_path,
        rigid=False,
        open_ends=1,
        paper={"delta_mm": 1.5},
        description="a test tube",
        hole_shape="rectangle",
        length_mm=12.5,
    )
    foo = load_catalogue(path).get("foo")
    assert foo.rigid is False
    assert foo.open_ends == 1
    assert foo.reference == {"delta_mm": 1.5}
    assert foo.hole_shape == "rectangle"
    assert foo.length == pytest.approx(0.0125)


# --- malformed entries ----------------------------------------------------------------------


@pytest.mark.parametrize("key", REQUIRED)
def test_missing_required_key(tmp_path: Path, key: str) -> None:
    message = _error(_write_foo(tmp_path, **{key: None}))
    assert "parts.foo" in message
    assert key in message
    assert "missing" in message


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("length_mm", 0),
        ("length_mm", -68),
        ("outer_mm", -34),
        ("hole_mm", 0.0),
        ("mass_kg", -0.1),
        ("mass_kg", 0),
    ],
)
def test_non_positive_number(tmp_path: Path, key: str, value: float) -> None:
    message = _error(_write_foo(tmp_path, **{key: value}))
    assert f"parts.foo.{key}" in message
    assert "> 0" in message
    assert repr(value) in message or str(value) in message


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("length_mm", "68"),
        ("length_mm", "sixty-eight"),
        ("outer_mm", [34]),
        ("hole_mm", {"mm": 28}),
        ("mass_kg", True),
        ("length_mm", float("nan")),
        ("outer_mm", float("inf")),
    ],
)
def test_not_a_number(tmp_path: Path, key: str, value: Any) -> None:
    message = _error(_write_foo(tmp_path, **{key: value}))
    assert f"parts.foo.{key}" in message
    assert "expected a number" in message


def test_unknown_key_lists_the_valid_keys(tmp_path: Path) -> None:
    message = _error(_write_foo(tmp_path, colour="red"))
    assert "parts.foo.colour" in message
    assert "unknown key" in message
    for key in REQUIRED + OPTIONAL:
        assert key in message


def test_misspelt_key_is_reported_as_unknown_not_ignored(tmp_path: Path) -> None:
    # A typo of an optional key must not silently fall back to the default.
    message = _error(_write_foo(tmp_path, rigd=False))
    assert "parts.foo.rigd" in message


@pytest.mark.parametrize("shape", ["hexagon", "Circle", "", 3])
def test_bad_hole_shape(tmp_path: Path, shape: Any) -> None:
    message = _error(_write_foo(tmp_path, hole_shape=shape))
    assert "parts.foo.hole_shape" in message
    assert "circle" in message and "rectangle" in message


@pytest.mark.parametrize(("outer", "hole"), [(34, 34), (34, 40)])
def test_hole_not_smaller_than_outer(tmp_path: Path, outer: float, hole: float) -> None:
    message = _error(_write_foo(tmp_path, outer_mm=outer, hole_mm=hole))
    assert "parts.foo.hole_mm" in message
    assert "outer_mm" in message


def test_hole_just_smaller_than_outer_is_fine(tmp_path: Path) -> None:
    foo = load_catalogue(_write_foo(tmp_path, outer_mm=34, hole_mm=33.9)).get("foo")
    assert foo.hole < foo.outer


@pytest.mark.parametrize("value", ["yes", 1, "true"])
def test_rigid_must_be_a_boolean(tmp_path: Path, value: Any) -> None:
    message = _error(_write_foo(tmp_path, rigid=value))
    assert "parts.foo.rigid" in message


@pytest.mark.parametrize("value", [0, 3, True, "two"])
def test_open_ends_must_be_one_or_two(tmp_path: Path, value: Any) -> None:
    message = _error(_write_foo(tmp_path, open_ends=value))
    assert "parts.foo.open_ends" in message


def test_paper_must_be_a_mapping(tmp_path: Path) -> None:
    message = _error(_write_foo(tmp_path, paper="0.9"))
    assert "parts.foo.paper" in message


def test_entry_that_is_not_a_mapping(tmp_path: Path) -> None:
    message = _error(_write(tmp_path, {"parts": {"foo": 68}}))
    assert "parts.foo" in message


def test_error_names_the_bad_part_among_good_ones(tmp_path: Path) -> None:
    bad = _valid_entry()
    bad["hole_mm"] = "28mm"
    path = _write(tmp_path, {"parts": {"good": _valid_entry(), "bad": bad}})
    message = _error(path)
    assert "parts.bad.hole_mm" in message
    assert "parts.good" not in message


# --- malformed files ------------------------------------------------------------------------


def test_invalid_yaml_reports_the_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text(
        "parts:\n  foo:\n    length_mm: 68\n    outer_mm: [34\n    hole_mm: 28\n",
        encoding="utf-8",
    )
    message = _error(path)
    assert "YAML" in message
    assert message.startswith(f"{path}:5:") or message.startswith(f"{path}:4:"), message


def test_invalid_yaml_line_number_points_at_the_problem(tmp_path: Path) -> None:
    path = tmp_path / "tabs.yaml"
    # A tab where indentation is expected, on line 3.
    path.write_text("parts:\n  foo:\n\tlength_mm: 68\n", encoding="utf-8")
    message = _error(path)
    assert message.startswith(f"{path}:3:"), message


@pytest.mark.parametrize(
    "text",
    [
        "",  # empty file
        "# only a comment\n",
        "bushing:\n  length_mm: 68\n",  # forgot the top-level key
        "- parts\n",  # a list, not a mapping
        "just a string\n",
    ],
)
def test_missing_top_level_parts(tmp_path: Path, text: str) -> None:
    path = tmp_path / "noparts.yaml"
    path.write_text(text, encoding="utf-8")
    message = _error(path)
    assert "parts" in message
    assert "missing top-level key" in message


@pytest.mark.parametrize("parts", [{}, [], None, "bushing"])
def test_parts_must_be_a_non_empty_mapping(tmp_path: Path, parts: Any) -> None:
    message = _error(_write(tmp_path, {"parts": parts}))
    assert "parts" in message
    assert "non-empty mapping" in message


def test_part_name_must_be_a_string(tmp_path: Path) -> None:
    path = tmp_path / "intname.yaml"
    path.write_text(
        "parts:\n  42: {length_mm: 68, outer_mm: 34, hole_mm: 28, hole_shape: circle,"
        " mass_kg: 0.1}\n",
        encoding="utf-8",
    )
    message = _error(path)
    assert "42" in message


def test_file_that_does_not_exist(tmp_path: Path) -> None:
    path = tmp_path / "nowhere" / "parts.yaml"
    message = _error(path)
    assert "cannot read" in message


def test_directory_instead_of_a_file(tmp_path: Path) -> None:
    message = _error(tmp_path)
    assert "cannot read" in message


# --- Catalogue.get --------------------------------------------------------------------------


def test_get_unknown_name_lists_known_parts() -> None:
    catalogue = load_catalogue()
    with pytest.raises(ValueError) as info:
        catalogue.get("nosuchpart")
    message = str(info.value)
    assert "nosuchpart" in message
    for name in TABLE3:
        assert name in message


def test_get_unknown_name_in_a_custom_catalogue(tmp_path: Path) -> None:
    catalogue = load_catalogue(_write_foo(tmp_path))
    with pytest.raises(ValueError, match="known parts: foo") as info:
        catalogue.get("bushing")
    assert "'bushing'" in str(info.value)


def test_a_key_error_names_the_catalogue_s_line(tmp_path: Path) -> None:
    path = tmp_path / "parts.yaml"
    path.write_text(
        "parts:\n  foo:\n    length_mm: 68\n    outer_mm: 34\n    hole_mm: 28\n"
        "    hole_shape: circle\n    mass_kg: 0.1\n    open_end: 1\n",
        encoding="utf-8",
    )
    message = _error(path)
    assert message.startswith(f"{path}:8: parts.foo.open_end: unknown key"), message


def test_a_configuration_reports_its_catalogue_s_typo_at_the_catalogue_s_line(
    tmp_path: Path,
) -> None:
    """Not at the line of the configuration that names the catalogue."""
    import subprocess
    import sys

    text = default_catalogue_path().read_text(encoding="utf-8")
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().startswith("outer_mm:"))
    lines[at] = lines[at].replace("outer_mm:", "outer_mn:")
    (tmp_path / "parts.yaml").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (tmp_path / "cell.yaml").write_text("cell:\n  catalogue: parts.yaml\n", encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, "-m", "cell.cli", "tree", "--config", "cell.yaml", "--out", "t"],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in proc.stderr
    assert f"parts.yaml:{at + 1}:" in err[0] and "outer_mn: unknown key" in err[0], err[0]
    assert not (tmp_path / "t").exists()
