"""Trees from YAML: a registry of behaviour types, each with its checked parameters.

A node is a mapping with ``type`` and that type's parameters; composites take ``children``,
decorators one ``child``. Motion leaves take ``timeout_s``, ``max_force_n`` and
``max_torque_nm``, which the builder turns into a :class:`~trees.decorators.Timeout` inside an
:class:`~trees.decorators.FTGuard` around the leaf: safety is part of the tree, visible in
``cell tree``, and never forgotten by a leaf. An unknown type or parameter, or a missing one, is
an error naming the file, the line, the key and the valid choices.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import py_trees
from py_trees import common
from py_trees.behaviour import Behaviour

from skills.motion import MAX_FORCE_LIMIT
from skills.params import config_keys
from trees.behaviours import (
    AlignBehaviour,
    FeedSlotBehaviour,
    GoHome,
    GraspBehaviour,
    HoldingPart,
    PackInBoxBehaviour,
    Perceive,
    PickFromAboveBehaviour,
    PickFromSlotBehaviour,
    PivotClears,
    PlanPick,
    PutBack,
    RepositionBehaviour,
    SlotHolds,
    SlotMachined,
    TiltBehaviour,
    WaitMachining,
)
from trees.context import SECTION_DOCS, SKILL_SECTIONS, CellContext
from trees.decorators import Cycles, FTGuard, FTSampler, Retry, StopOnFailure, Timeout
from trees.yaml_lines import ConfigError, KeyPath, LinedDocument, load_yaml


@dataclass(frozen=True)
class Param:
    kind: type | tuple[type, ...]
    required: bool = False
    low: float | None = None
    high: float | None = None
    doc: str = ""


MOTION = {
    "timeout_s": Param(
        float, low=0.1, high=3600, doc="timeout (s); default safety.default_timeout_s"
    ),
    "max_force_n": Param(
        float, low=1, high=MAX_FORCE_LIMIT, doc="FT abort force (N); default safety's"
    ),
    "max_torque_nm": Param(float, low=0.1, high=50, doc="FT abort torque (N*m); default safety's"),
}
NAME = {"name": Param(str, doc="shown in `cell tree` and the log")}


@dataclass(frozen=True)
class NodeType:
    kind: str  # "leaf" | "composite" | "decorator"
    doc: str
    params: dict[str, Param] = field(default_factory=dict)
    leaf: type[Behaviour] | None = None
    #: its BehaviorTree.CPP node ID and model category (trees/btcpp.py). The IDs of
    #: BehaviorTree.CPP's own nodes (``Sequence``, ``Fallback``) are not declared in the model;
    #: the others avoid its built-in IDs (its ``Timeout`` counts milliseconds of wall time; ours
    #: counts seconds of the cell's clock, hence ``CellTimeout``).
    btcpp: tuple[str, str] = ("", "")
    #: the class a composite or decorator builds (a leaf's is ``leaf``)
    cls: type[Behaviour] | None = None

    @property
    def section(self) -> str | None:
        """The ``skills:`` section whose keys this leaf takes as per-node overrides."""
        return getattr(self.leaf, "section", None)

    def all_params(self) -> dict[str, Param]:
        """Its own parameters and, for a skill leaf, its section's keys."""
        if self.section is None:
            return dict(self.params)
        return self.params | section_params(self.section)


def section_params(section: str) -> dict[str, Param]:
    """A ``skills:`` section's keys as node parameters (configured units, e.g. degrees)."""
    out: dict[str, Param] = {}
    for k in config_keys(SKILL_SECTIONS[section]):
        unit = k.shown_unit
        out[k.key] = Param(
            float,
            low=k.shown(k.low),
            high=k.shown(k.high),
            doc=f"{k.doc} ({unit}; default {k.shown(k.default):g})",
        )
    return out


REGISTRY: dict[str, NodeType] = {
    "sequence": NodeType(
        "composite",
        "children in order; fails at the first failure",
        btcpp=("Sequence", "Control"),
        cls=py_trees.composites.Sequence,
    ),
    "selector": NodeType(
        "composite",
        "children in order until one succeeds (fallback)",
        btcpp=("Fallback", "Control"),
        cls=py_trees.composites.Selector,
    ),
    "retry": NodeType(
        "decorator",
        "runs the child again after a failure",
        {
            "attempts": Param(int, required=True, low=1, high=100, doc="runs in all"),
            "pause_s": Param(
                float, low=0.0, high=60.0, doc="wait before each new attempt (s); default 0"
            ),
        },
        btcpp=("Retry", "Decorator"),
        cls=Retry,
    ),
    "timeout": NodeType(
        "decorator",
        "fails the child after a time (s, the cell's clock)",
        {"seconds": Param(float, required=True, low=0.01, high=86400)},
        btcpp=("CellTimeout", "Decorator"),
        cls=Timeout,
    ),
    "ft_guard": NodeType(
        "decorator",
        "fails the child within one tick of a wrench over the limits; stops the arm",
        {
            "max_force_n": Param(float, low=1, high=MAX_FORCE_LIMIT),
            "max_torque_nm": Param(float, low=0.1, high=50),
        },
        btcpp=("FTGuard", "Decorator"),
        cls=FTGuard,
    ),
    "cycles": NodeType(
        "decorator",
        "repeats the child until workflow.cycles or the bin is empty",
        btcpp=("Cycles", "Decorator"),
        cls=Cycles,
    ),
    "stop_on_failure": NodeType(
        "decorator",
        "a failure below needs a person: stops the cell with this reason",
        {"reason": Param(str, required=True)},
        btcpp=("StopOnFailure", "Decorator"),
        cls=StopOnFailure,
    ),
    "perceive": NodeType(
        "leaf",
        "wrist camera over the bin, find the parts",
        dict(MOTION),
        Perceive,
        btcpp=("Perceive", "Action"),
    ),
    "plan_pick": NodeType(
        "leaf", "choose the part and its pivot frame", {}, PlanPick, btcpp=("PlanPick", "Action")
    ),
    "pivot_clears": NodeType(
        "leaf",
        "condition: the chosen part's pivot clears the walls and neighbours where it lies",
        {},
        PivotClears,
        btcpp=("PivotClears", "Condition"),
    ),
    "reposition": NodeType(
        "leaf",
        "drag the chosen part to where a pivot clears (counted apart as repositioned)",
        dict(MOTION),
        RepositionBehaviour,
        btcpp=("Reposition", "Action"),
    ),
    "grasp": NodeType(
        "leaf",
        "the pivot's Grasp (Sec. III-C)",
        dict(MOTION),
        GraspBehaviour,
        btcpp=("Grasp", "Action"),
    ),
    "tilt": NodeType(
        "leaf",
        "the pivot's Tilt about P_c",
        dict(MOTION),
        TiltBehaviour,
        btcpp=("Tilt", "Action"),
    ),
    "align": NodeType(
        "leaf",
        "in-hand Align: turn about the rim into the hole grasp, no release (Sec. III-C)",
        dict(MOTION),
        AlignBehaviour,
        btcpp=("Align", "Action"),
    ),
    "pick_from_above": NodeType(
        "leaf",
        "recovery after a failed align: let go, look, pick from above (counted apart)",
        dict(MOTION),
        PickFromAboveBehaviour,
        btcpp=("PickFromAbove", "Action"),
    ),
    "put_back": NodeType(
        "leaf",
        "recovery: open, rise, home; then fails so a retry above tries again",
        dict(MOTION),
        PutBack,
        btcpp=("PutBack", "Action"),
    ),
    "feed_slot": NodeType(
        "leaf",
        "part into the machine slot, release, drag away",
        dict(MOTION),
        FeedSlotBehaviour,
        btcpp=("FeedSlot", "Action"),
    ),
    "slot_holds_part": NodeType(
        "leaf",
        "condition: the slot holds a part (fed or machined)",
        {},
        SlotHolds,
        btcpp=("SlotHoldsPart", "Condition"),
    ),
    "holding_part": NodeType(
        "leaf",
        "condition: the gripper holds something and reports no fault (gates a retry)",
        {},
        HoldingPart,
        btcpp=("HoldingPart", "Condition"),
    ),
    "slot_machined": NodeType(
        "leaf",
        "condition: the part in the slot is machined",
        {},
        SlotMachined,
        btcpp=("SlotMachined", "Condition"),
    ),
    "wait_machining": NodeType(
        "leaf",
        "start the machine, wait until done",
        {},
        WaitMachining,
        btcpp=("WaitMachining", "Action"),
    ),
    "pick_from_slot": NodeType(
        "leaf",
        "the same hole grasp on the part in the slot",
        dict(MOTION),
        PickFromSlotBehaviour,
        btcpp=("PickFromSlot", "Action"),
    ),
    "pack_in_box": NodeType(
        "leaf",
        "push -z, +x, +y until contact, release",
        dict(MOTION),
        PackInBoxBehaviour,
        btcpp=("PackInBox", "Action"),
    ),
    "go_home": NodeType(
        "leaf", "arm to its home pose", dict(MOTION), GoHome, btcpp=("GoHome", "Action")
    ),
}
COMPOSITES = {k: nt.cls for k, nt in REGISTRY.items() if nt.kind == "composite"}


def _check_value(doc: LinedDocument, path: KeyPath, key: str, value: Any, p: Param) -> Any:
    kinds = p.kind if isinstance(p.kind, tuple) else (p.kind,)
    ok = isinstance(value, kinds) and not isinstance(value, bool)
    if float in kinds and isinstance(value, int) and not isinstance(value, bool):
        ok, value = True, float(value)
    if not ok:
        what = " or ".join(k.__name__ for k in kinds)
        hint = (
            "; numbers are SI and the unit is in the key's name" if isinstance(value, str) else ""
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
            return COMPOSITES[kind](name=name, memory=True, children=kids)
        if nt.kind == "decorator":
            if "child" not in spec:
                raise doc.error(path, f"'{kind}' needs a 'child' node")
            child = self.build(spec["child"], (*path, "child"))
            return self._decorator(kind, name, child, params)
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

    def _decorator(
        self, kind: str, name: str, child: Behaviour, params: dict[str, Any]
    ) -> Behaviour:
        ctx = self.ctx
        if kind == "retry":
            return Retry(name, child, ctx, params["attempts"], params.get("pause_s", 0.0))
        if kind == "timeout":
            return Timeout(name, child, ctx, params["seconds"])
        if kind == "ft_guard":
            return FTGuard(
                name,
                child,
                ctx,
                params.get("max_force_n", self.defaults["max_force_n"]),
                params.get("max_torque_nm", self.defaults["max_torque_nm"]),
            )
        if kind == "cycles":
            return Cycles(name, child, ctx)
        if kind == "stop_on_failure":
            return StopOnFailure(name, child, ctx, params["reason"])
        raise AssertionError(kind)


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
    "REGISTRY",
    "ConfigError",
    "TreeBuilder",
    "build_root",
    "describe_types",
    "resolve_tree_spec",
]
