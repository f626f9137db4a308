"""The arrows point down only: lab -> cell -> trees -> skills -> drivers; sim implements drivers'
interfaces beside the real drivers (the cell chooses it). The lab's commands join `cell` as
plugins, so the cell never imports the lab. Read from the source (every import, also the ones inside
functions), so a shortcut added anywhere fails here before it becomes a habit.

Within drivers, the skills and the trees see only the device interfaces and the neutral modules
(``drivers/*.py``), never a real driver's package (``drivers/<name>/``: the UR5, the 2F-85, the
FT300, the RealSense): a skill that imported one would plan for that device alone. The cell
builds what a skill needs of a real device (the arm's reach) and hands it in."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: package -> the packages of this project it may import
ALLOWED = {
    "cell": {"cell", "trees", "skills", "drivers", "sim"},
    "drivers": {"drivers"},
    "sim": {"drivers", "sim"},
    "skills": {"drivers", "skills"},
    "trees": {"drivers", "skills", "trees"},
}
PROJECT = {"lab", "cell", "trees", "skills", "drivers", "sim"}
#: packages that may use the device interfaces and neutral modules of drivers only
NO_REAL_DRIVER = ("skills", "trees")
#: the real drivers: every package under drivers/ (its neutral modules are plain files)
REAL_DRIVERS = sorted(
    p.name for p in (ROOT / "drivers").iterdir() if (p / "__init__.py").is_file()
)


def _modules(path: Path) -> list[tuple[int, str]]:
    """Every project module ``path`` imports, dotted (``from drivers import ur5`` counts as
    ``drivers.ur5``: the name may be a subpackage)."""
    tree = ast.parse(path.read_text(), str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return [(line, name) for line, name in out if name.split(".")[0] in PROJECT]


def _imports(path: Path) -> list[tuple[int, str]]:
    return sorted({(line, name.split(".")[0]) for line, name in _modules(path)})


def _real_drivers(path: Path) -> list[tuple[int, str]]:
    """The real drivers' packages ``path`` imports: ``(line, driver)``."""
    out = []
    for line, name in _modules(path):
        parts = name.split(".")
        if parts[0] == "drivers" and len(parts) > 1 and parts[1] in REAL_DRIVERS:
            out.append((line, parts[1]))
    return sorted(set(out))


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_a_layer_imports_only_the_layers_below_it(package: str) -> None:
    wrong = [
        f"{path.relative_to(ROOT)}:{line}: imports {top}"
        for path in sorted((ROOT / package).rglob("*.py"))
        for line, top in _imports(path)
        if top not in ALLOWED[package]
    ]
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("package", NO_REAL_DRIVER)
def test_skills_and_trees_import_no_real_driver(package: str) -> None:
    wrong = [
        f"{path.relative_to(ROOT)}:{line}: imports drivers.{driver}"
        for path in sorted((ROOT / package).rglob("*.py"))
        for line, driver in _real_drivers(path)
    ]
    assert not wrong, "\n".join(wrong)


def test_the_scan_sees_an_upward_import(tmp_path: Path) -> None:
    bad = tmp_path / "x.py"
    bad.write_text("def f():\n    from cell.config import schema\n")
    assert _imports(bad) == [(2, "cell")]


def test_the_real_drivers_are_the_device_packages() -> None:
    assert {"ur5", "robotiq_gripper", "ft300", "realsense"} <= set(REAL_DRIVERS)
    assert not {"devices", "parts", "layout", "events", "tag_board"} & set(REAL_DRIVERS)


@pytest.mark.parametrize(
    "line",
    [
        "from drivers.ur5.kinematics import solve_ik",
        "import drivers.robotiq_gripper.gripper",
        "from drivers.ft300 import stream",
        "from drivers import realsense",
        "def f():\n    import drivers.ur5 as arm",
    ],
)
def test_the_scan_sees_a_real_driver_imported(tmp_path: Path, line: str) -> None:
    bad = tmp_path / "x.py"
    bad.write_text(f"from drivers.parts import Part\n{line}\n")
    found = _real_drivers(bad)
    assert len(found) == 1 and found[0][1] in REAL_DRIVERS, found
