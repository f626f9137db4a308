"""The built tree as a table: what the tick log's header and the monitor page draw.

Why a table of ids: the page and the replay need the tree's shape once (ids, names, types,
children, the limits of each guard and timeout), and then only status changes by name, which the
builder keeps unique. Ids are pre-order positions, so the root is 0 and a parent comes before
its children.
"""

from __future__ import annotations

from typing import Any

import py_trees
from py_trees.behaviour import Behaviour

from trees.decorators import FTGuard, FTSampler, Timeout
from trees.registry import REGISTRY

#: The two nodes the cell adds around a tree's file (not types a file may name).
_ADDED: dict[type, str] = {
    py_trees.composites.Parallel: "parallel",
    FTSampler: "ft_sampler",
}


def node_type(node: Behaviour) -> str:
    """The registry's type of a built node (its exact class: a subclass is another type), from
    what each class declared (trees/node_type.py)."""
    cls = type(node)
    if cls in _ADDED:
        return _ADDED[cls]
    return next((k for k, nt in REGISTRY.items() if nt.built is cls), cls.__name__)


def preorder(root: Behaviour) -> list[Behaviour]:
    out: list[Behaviour] = []

    def walk(node: Behaviour) -> None:
        out.append(node)
        for child in node.children:
            walk(child)

    walk(root)
    return out


def node_table(root: Behaviour) -> list[dict[str, Any]]:
    """``[{"id", "name", "type", "children": [ids], "limits"?}]`` in pre-order."""
    nodes = preorder(root)
    ids = {id(n): i for i, n in enumerate(nodes)}
    table = []
    for i, n in enumerate(nodes):
        row: dict[str, Any] = {
            "id": i,
            "name": n.name,
            "type": node_type(n),
            "children": [ids[id(c)] for c in n.children],
        }
        if isinstance(n, FTGuard):
            row["limits"] = {"force_n": float(n.max_force), "torque_nm": float(n.max_torque)}
        elif isinstance(n, Timeout):
            row["limits"] = {"seconds": float(n.seconds)}
        table.append(row)
    return table


__all__ = ["node_table", "node_type", "preorder"]
