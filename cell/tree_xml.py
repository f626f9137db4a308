"""`cell tree --format btcpp` and `cell tree --from-btcpp`: the configured tree to and from
BehaviorTree.CPP v4 XML (Groot2's format). The conversion itself is :mod:`trees.btcpp`; this
module finds the configured tree and its defaults and reports errors as every command does."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from cell.errors import UserError
from cell.output import report_config_error
from skills.params import config_keys
from trees.btcpp import BtcppError, read_xml, to_yaml, write_xml
from trees.context import SKILL_SECTIONS
from trees.yaml_lines import ConfigError


def section_defaults(config: Any) -> dict[str, dict[str, float]]:
    """Each ``skills:`` section's values as a leaf gets them when it overrides nothing: the
    configured value, else the skill's default (configured units, as the node keys)."""
    out: dict[str, dict[str, float]] = {}
    for name, cls in SKILL_SECTIONS.items():
        given = getattr(config.skills, name).model_dump(exclude_unset=True)
        out[name] = {k.key: given.get(k.key, k.shown(k.default)) for k in config_keys(cls)}
    return out


def write_btcpp(prep: Any, out: Path) -> int:
    from cell.assemble import DATA_DIR
    from trees.registry import resolve_tree_spec

    spec, tree_doc, _ = resolve_tree_spec(prep.config.tree, prep.doc, DATA_DIR)
    s = prep.config.safety
    defaults = {
        "timeout_s": s.default_timeout_s,
        "max_force_n": s.ft_abort_force_n,
        "max_torque_nm": s.ft_abort_torque_nm,
    }
    try:
        path = write_xml(
            out / "tree.xml",
            spec,
            defaults=defaults,
            section_defaults=section_defaults(prep.config),
            source=Path(tree_doc.source).name,
        )
    except OSError as exc:
        raise UserError(f"--out {out}: cannot write tree.xml: {exc.strerror}") from None
    print(f"wrote {path} (BehaviorTree.CPP v4; open it in Groot2)")
    return 0


def from_btcpp(path: Path, out: Path | None) -> int:
    try:
        spec = read_xml(path)
    except (BtcppError, ConfigError) as exc:
        return report_config_error(exc, "tree")
    text = to_yaml(spec, source=path.name)
    if out is None:
        sys.stdout.write(text)
        return 0
    target = out / "tree.yaml"
    try:
        out.mkdir(parents=True, exist_ok=True)
        target.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise UserError(f"--out {out}: cannot write tree.yaml: {exc.strerror}") from None
    print(f"wrote {target} (use it as `tree: {{file: {target}}}`)")
    return 0


__all__ = ["from_btcpp", "section_defaults", "write_btcpp"]
