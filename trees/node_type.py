"""What a tree file may name: each node class declares its type once, the BehaviorTree.CPP way.

A behaviour class is made a node type by :func:`declare` on the class itself: the name a tree
file gives as ``type``, a line of documentation, its parameters (the ports a BT.CPP model lists)
and its BT.CPP ID and category. Everything that lists node types -- the tree builder
(:mod:`trees.registry`), the TreeNodesModel of `cell tree --format btcpp`, `cell tree --types`,
the tick log's class table and docs/configuration.md's node table -- reads :data:`REGISTRY`,
which the declarations fill. Adding a node type is one edit: the class and its declaration.

Why not a table beside the classes: four tables (the builder's, the BT.CPP IDs, the tick log's
classes, the classes' own attributes) had to agree, and a new node had to be added to each.

:data:`REGISTRY` is complete once :mod:`trees.registry` is imported (it imports the modules that
declare the cell's own nodes); read it from there.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

from py_trees.behaviour import Behaviour
from py_trees.composites import Composite
from py_trees.decorators import Decorator

from skills.motion import MAX_FORCE_LIMIT, MAX_TORQUE_LIMIT
from skills.params import config_keys
from trees.context import SKILL_SECTIONS


@dataclass(frozen=True)
class Param:
    """A node parameter (a BT.CPP input port): its type, whether a file must give it, its range."""

    kind: type | tuple[type, ...]
    required: bool = False
    low: float | None = None
    high: float | None = None
    doc: str = ""


#: The guard every motion leaf is built inside (trees.registry.TreeBuilder): its timeout and
#: force-torque limits, per node; unset, the configuration's ``safety`` section's.
MOTION = {
    "timeout_s": Param(
        float, low=0.1, high=3600, doc="timeout (s); default safety.default_timeout_s"
    ),
    "max_force_n": Param(
        float, low=1, high=MAX_FORCE_LIMIT, doc="FT abort force (N); default safety's"
    ),
    "max_torque_nm": Param(
        float, low=0.1, high=MAX_TORQUE_LIMIT, doc="FT abort torque (N*m); default safety's"
    ),
}
#: Every node's own parameter.
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

    @property
    def built(self) -> type[Behaviour]:
        """The class a node of this type is (a leaf's own, a composite's or decorator's)."""
        built = self.leaf if self.leaf is not None else self.cls
        assert built is not None
        return built

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


#: Type name (what a tree file's ``type`` says) -> its declaration, in declaration order.
REGISTRY: dict[str, NodeType] = {}

B = TypeVar("B", bound=type[Behaviour])


def declare(
    type_name: str,
    doc: str,
    category: str,
    params: dict[str, Param] | None = None,
    btcpp_id: str | None = None,
) -> Callable[[B], B]:
    """Make a behaviour class a node type a tree file may name (the module doc): ``type_name``
    in tree files, ``category`` and ``btcpp_id`` (default: the class's name) in BT.CPP's XML.

    A composite builds as ``cls(name=, memory=True, children=)``; a decorator by its
    ``from_spec(name, child, ctx, params, defaults)``; a leaf as ``cls(name, ctx, **params)``,
    and a leaf with ``moves = True`` inside the timeout and force-torque guard of its MOTION
    parameters. The kind follows from the class; a second declaration of a type name or a
    BT.CPP ID is refused (two classes behind one name would be chosen by import order)."""

    def register(cls: B) -> B:
        btcpp = (btcpp_id or cls.__name__, category)
        kind = (
            "composite" if issubclass(cls, Composite)
            else "decorator" if issubclass(cls, Decorator)
            else "leaf"
        )
        if kind == "decorator" and not hasattr(cls, "from_spec"):
            raise TypeError(f"decorator node {type_name!r} ({cls.__name__}) needs from_spec()")
        if type_name in REGISTRY:
            raise ValueError(f"node type {type_name!r} is declared twice")
        taken = {nt.btcpp[0]: name for name, nt in REGISTRY.items()}
        if btcpp[0] in taken:
            raise ValueError(f"BT.CPP ID {btcpp[0]!r} of {type_name!r} is {taken[btcpp[0]]!r}'s")
        REGISTRY[type_name] = NodeType(
            kind,
            doc,
            dict(params or {}),
            cls if kind == "leaf" else None,
            btcpp,
            None if kind == "leaf" else cls,
        )
        return cls

    return register


def forget(type_name: str) -> None:
    """Undeclare a node type (a test's own example node, once the test is done)."""
    REGISTRY.pop(type_name, None)


__all__ = ["MOTION", "NAME", "REGISTRY", "NodeType", "Param", "declare", "forget",
           "section_params"]
