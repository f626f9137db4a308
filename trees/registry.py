"""Trees from YAML: built from the node types the classes declare (trees/node_type.py), each
node's parameters checked against its type's.

A node is a mapping with ``type`` and that type's parameters; composites take ``children``,
decorators one ``child``. Motion leaves take ``timeout_s``, ``max_force_n`` and
``max_torque_nm``, which the builder turns into a :class:`~trees.decorators.Timeout` inside an
:class:`~trees.decorators.FTGuard` around the leaf: safety is part of the tree, visible in
``cell tree``, and never forgotten by a leaf. An unknown type or parameter, or a missing one, is
an error naming the file, the line, the key and the valid choices.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import py_trees
from py_trees import common
from py_trees.behaviour import Behaviour

# The modules that declare the cell's own node types (each class carries its declaration).
import trees.behaviours  # noqa: F401
import trees.decorators  # noqa: F401
from trees.context import SECTION_DOCS, SKILL_SECTIONS, CellContext
from trees.decorators import FTGuard, FTSampler, Timeout
from trees.node_type import (
    MOTION,
    NAME,
    REGISTRY,
    NodeType,
    Param,
    declare,
    section_params,
)
from trees.yaml_lines import ConfigError, KeyPath, LinedDocument, load_yaml

declare("sequence", "children in order; fails at the first failure", "Control")(
    py_trees.composites.Sequence
)
declare(
    "selector", "children in order until one succeeds (fallback)", "Control", btcpp_id="Fallback"
)(py_trees.composites.Selector)


def _in_order() -> None:
    """Composites, then decorators, then leaves, each in declaration order: how `cell tree
    --types`, the BT.CPP model and the docs list them."""
    rank = {"composite": 0, "decorator": 1, "leaf": 2}
    ordered = sorted(REGISTRY.items(), key=lambda kv: rank[kv[1].kind])
    REGISTRY.clear()
    REGISTRY.update(ordered)


_in_order()


def _check_value(doc: LinedDocument, path: KeyPath, key: str, value: Any, p: Param) -> Any:
    kinds = p.kind if isinstance(p.kind, tuple) else (p.kind,)
    ok = isinstance(value, kinds) and (bool in kinds or not isinstance(value, bool))
    if float in kinds and isinstance(value, int) and not isinstance(value, bool):
        ok, value = True, float(value)
    if not ok:
        what = " or ".join(k.__name__ for k in kinds)
        numeric = float in kinds or int in kinds
        hint = (
            "; numbers are SI and the unit is in the key's name"
            if isinstance(value, str) and numeric else ""
        )
        raise doc.error((*path, key), f"expected {what}, got {value!r}{hint}")
    if p.low is not None and value < p.low or p.high is not None and value > p.high:
        raise doc.error((*path, key), f"must lie in [{p.low:g}, {p.high:g}], got {value!r}")
    return value


class TreeBuilder:
    """Builds behaviours from node specs, checking each against the registry."""

    def __init__(self, ctx: CellContext, doc: LinedDocument, defaults: dict[str, float]) -> None:
        self.ctx, self.doc, self.defaults = ctx, doc, defaults
        self.names: dict[str, int] = {}

    def _name(self, wanted: str) -> str:
        # py_trees blackboard clients and the log need unique, readable names.
        n = self.names.get(wanted, 0)
        self.names[wanted] = n + 1
        return wanted if n == 0 else f"{wanted} #{n + 1}"

    def build(self, spec: Any, path: KeyPath) -> Behaviour:
        doc = self.doc
        if not isinstance(spec, dict):
            raise doc.error(path, f"a node must be a mapping with a 'type', got {spec!r}")
        if "type" not in spec:
            raise doc.error(path, f"missing 'type'; valid types: {', '.join(REGISTRY)}")
        kind = spec["type"]
        if not isinstance(kind, str) or kind not in REGISTRY:
            raise doc.error(
                (*path, "type"),
                f"unknown behaviour type {kind!r}; valid types: {', '.join(REGISTRY)}",
            )
        nt = REGISTRY[kind]
        allowed = dict(NAME) | nt.all_params()
        structural = {"composite": ("children",), "decorator": ("child",), "leaf": ()}[nt.kind]
        params: dict[str, Any] = {}
        for key, value in spec.items():
            if key == "type" or key in structural:
                continue
            if key not in allowed:
                valid = ", ".join([*allowed, *structural]) or "(none)"
                raise doc.error((*path, key), f"unknown parameter of '{kind}'; valid: {valid}")
            params[key] = _check_value(doc, path, key, value, allowed[key])
        for key, p in allowed.items():
            if p.required and key not in params:
                raise doc.error(path, f"'{kind}' needs '{key}' ({p.doc or p.kind.__name__})")
        name = self._name(str(params.pop("name", kind.replace("_", " "))))
        if nt.kind == "composite":
            children = spec.get("children")
            if not isinstance(children, list) or not children:
                raise doc.error((*path, "children"), f"'{kind}' needs a non-empty list 'children'")
            kids = [self.build(c, (*path, "children", i)) for i, c in enumerate(children)]
            return nt.built(name=name, memory=True, children=kids)  # type: ignore[call-arg]
        if nt.kind == "decorator":
            if "child" not in spec:
                raise doc.error(path, f"'{kind}' needs a 'child' node")
            child = self.build(spec["child"], (*path, "child"))
            return nt.built.from_spec(  # type: ignore[attr-defined,no-any-return]
                name, child, self.ctx, params, self.defaults
            )
        assert nt.leaf is not None
        motion = {k: params.pop(k) for k in list(params) if k in MOTION}
        if not getattr(nt.leaf, "moves", False):
            return nt.leaf(name, self.ctx, **params)
        # One source for the limits: the node's (or the safety section's) force and torque are
        # both the FT guard around the leaf and the guard of every motion of its skill.
        force = motion.get("max_force_n", self.defaults["max_force_n"])
        torque = motion.get("max_torque_nm", self.defaults["max_torque_nm"])
        node: Behaviour = nt.leaf(name, self.ctx, max_force_n=force, max_torque_nm=torque, **params)
        timeout = motion.get("timeout_s", self.defaults["timeout_s"])
        node = Timeout(self._name(f"{name} timeout"), node, self.ctx, timeout)
        return FTGuard(self._name(f"{name} ft guard"), node, self.ctx, force, torque)


def resolve_tree_spec(
    tree: dict[str, Any], config_doc: LinedDocument, builtin_dir: Path
) -> tuple[Any, LinedDocument, KeyPath]:
    """The node spec to build, the document it came from, and its path there.

    ``{file: PATH}`` reads PATH relative to the configuration's directory, or, failing that,
    the trees shipped with the package.
    """
    if set(tree) == {"file"}:
        ref = tree["file"]
        if not isinstance(ref, str):
            raise config_doc.error(("tree", "file"), f"expected a path, got {ref!r}")
        base = Path(config_doc.source).resolve().parent
        candidates = [base / ref, builtin_dir / ref]
        for path in candidates:
            if path.is_file():
                doc = load_yaml(path)
                return doc.data, doc, ()
        raise config_doc.error(
            ("tree", "file"), f"no such tree file {ref!r} (looked in {base} and {builtin_dir})"
        )
    if "file" in tree:
        raise config_doc.error(("tree", "file"), "give either 'file' alone or a node spec")
    return tree, config_doc, ("tree",)


def build_root(
    spec: Any,
    doc: LinedDocument,
    path: KeyPath,
    ctx: CellContext,
    defaults: dict[str, float],
) -> Behaviour:
    """The whole tree: the configured nodes beside the force-torque sampler."""
    py_trees.blackboard.Blackboard.clear()
    builder = TreeBuilder(ctx, doc, defaults)
    sampler = FTSampler("ft sampler", ctx)
    body = builder.build(spec, path)
    return py_trees.composites.Parallel(
        name="cell",
        policy=common.ParallelPolicy.SuccessOnSelected(children=[body]),
        children=[sampler, body],
    )


def describe_types() -> str:
    """The registry and the skill sections as text, for `cell tree --types`: every parameter
    with its range and, for a skill's, its unit and default."""
    lines = []
    for name, nt in REGISTRY.items():
        extra = ", ".join(nt.params) if nt.params else "-"
        section = f"; and the keys of skills.{nt.section}" if nt.section else ""
        lines.append(f"{name:16s} {nt.kind:10s} {nt.doc}  [params: {extra}{section}]")
        for key, p in nt.params.items():
            lines.append(f"    {key:30s} {_range(p)}  {p.doc}")
    lines.append("")
    lines.append(
        "skills: sections (cell YAML `skills.<section>.<key>`; a leaf of that skill may "
        "override any key):"
    )
    for section in SKILL_SECTIONS:
        lines.append(f"  {section}: {SECTION_DOCS[section]}")
        for key, p in section_params(section).items():
            lines.append(f"    {key:30s} {_range(p)}  {p.doc}")
    return "\n".join(lines)


def _range(p: Param) -> str:
    if p.low is None and p.high is None:
        return f"{'':17s}"
    return f"[{p.low:g}, {p.high:g}]".ljust(17)


__all__ = [
    "MOTION",
    "NAME",
    "REGISTRY",
    "NodeType",
    "Param",
    "section_params",
    "ConfigError",
    "TreeBuilder",
    "build_root",
    "describe_types",
    "resolve_tree_spec",
]
