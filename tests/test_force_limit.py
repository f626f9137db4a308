"""The highest force limit a motion may be given is defined once: skills.motion.MAX_FORCE_LIMIT,
the FT300's measuring range. Every place that checks a force limit reads it from there, so a
sensor with another range changes one line."""

from __future__ import annotations

import ast
import pathlib

from cell.config import SafetySection
from skills.motion import MAX_FORCE_LIMIT
from skills.params import config_keys
from trees.context import SKILL_SECTIONS
from trees.node_type import MOTION, REGISTRY

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: where a force limit is read, checked or configured
APPLICATION = ("cell", "trees", "skills")


def _literal_sites(value: float, root: pathlib.Path = ROOT) -> list[str]:
    sites = []
    for package in APPLICATION:
        for path in sorted((root / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if (isinstance(node, ast.Constant) and not isinstance(node.value, bool)
                        and isinstance(node.value, (int, float)) and node.value == value):
                    sites.append(f"{path.relative_to(root)}:{node.lineno}")
    return sites


def test_the_force_ceiling_is_written_once() -> None:
    sites = _literal_sites(MAX_FORCE_LIMIT)
    assert len(sites) == 1 and sites[0].startswith("skills/motion.py:"), sites


def test_every_force_limit_check_reads_the_one_ceiling() -> None:
    # the configuration's safety section
    bounds = SafetySection.model_fields["ft_abort_force_n"].metadata
    assert any(getattr(b, "le", None) == MAX_FORCE_LIMIT for b in bounds)
    # a tree node's own limit
    assert MOTION["max_force_n"].high == MAX_FORCE_LIMIT
    for node_type in REGISTRY.values():
        if "max_force_n" in node_type.params:
            assert node_type.params["max_force_n"].high == MAX_FORCE_LIMIT
    # every skill's stricter guard
    guards = [k for cls in SKILL_SECTIONS.values() for k in config_keys(cls)
              if k.part == "max_force"]
    assert guards
    assert all(k.high == MAX_FORCE_LIMIT for k in guards)


def test_the_check_would_see_a_second_copy(tmp_path: pathlib.Path) -> None:
    (tmp_path / "trees").mkdir()
    (tmp_path / "trees" / "limits.py").write_text("LIMIT = 1.0\nHIGH = 300  # N\n")
    assert _literal_sites(MAX_FORCE_LIMIT, tmp_path) == ["trees/limits.py:2"]
