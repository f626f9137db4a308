"""The arrows point down only: cell -> trees -> skills -> drivers; sim implements drivers'
interfaces beside the real drivers. Read from the source (every import, also the ones inside
functions), so a shortcut added anywhere fails here before it becomes a habit."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: package -> the packages of this project it may import
ALLOWED = {
    "drivers": {"drivers"},
    "sim": {"drivers", "sim"},
    "skills": {"drivers", "skills"},
    "trees": {"drivers", "skills", "trees"},
}
PROJECT = {"cell", "trees", "skills", "drivers", "sim"}


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name.split(".")[0]) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module.split(".")[0]))
    return [(line, top) for line, top in out if top in PROJECT]


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_a_layer_imports_only_the_layers_below_it(package: str) -> None:
    wrong = [
        f"{path.relative_to(ROOT)}:{line}: imports {top}"
        for path in sorted((ROOT / package).rglob("*.py"))
        for line, top in _imports(path)
        if top not in ALLOWED[package]
    ]
    assert not wrong, "\n".join(wrong)


def test_the_scan_sees_an_upward_import(tmp_path: Path) -> None:
    bad = tmp_path / "x.py"
    bad.write_text("def f():\n    from cell.config import schema\n")
    assert _imports(bad) == [(2, "cell")]
