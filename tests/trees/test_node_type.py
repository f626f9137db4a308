"""A node type is one declaration on its class: the builder, the BT.CPP model, `cell tree
--types` and the tick log's type names find it by themselves."""

from __future__ import annotations

from collections.abc import Iterator

import py_trees
import pytest
from py_trees import common
from py_trees.behaviour import Behaviour

from cell.cli import main
from tests.trees.helpers import fresh_ctx
from trees.btcpp import from_xml, to_xml
from trees.context import CellContext
from trees.node_type import REGISTRY, Param, declare, forget
from trees.nodes import node_table
from trees.registry import TreeBuilder, describe_types
from trees.yaml_lines import parse_yaml

DEFAULTS = {"timeout_s": 30.0, "max_force_n": 80.0, "max_torque_nm": 8.0}


@pytest.fixture
def example_node() -> Iterator[type[Behaviour]]:
    """The whole of a new node type: its class and its declaration, in one place."""

    @declare(
        "count_ticks",
        "succeeds on its n-th tick (an example node)",
        "Action",
        {"ticks": Param(int, required=True, low=1, high=100, doc="ticks to run")},
    )
    class CountTicks(Behaviour):
        def __init__(self, name: str, ctx: CellContext, ticks: int) -> None:
            super().__init__(name)
            self.ticks, self.seen = ticks, 0

        def initialise(self) -> None:
            self.seen = 0

        def update(self) -> common.Status:
            self.seen += 1
            self.feedback_message = f"tick {self.seen} of {self.ticks}"
            done = self.seen >= self.ticks
            return common.Status.SUCCESS if done else common.Status.RUNNING

    yield CountTicks
    forget("count_ticks")


def test_a_declared_node_is_built_listed_and_exported(example_node, capsys) -> None:
    assert REGISTRY["count_ticks"].btcpp == ("CountTicks", "Action")
    doc = parse_yaml("type: sequence\nchildren:\n  - {type: count_ticks, ticks: 3}\n", "t.yaml")
    root = TreeBuilder(fresh_ctx(), doc, DEFAULTS).build(doc.data, ())
    leaf = root.children[0]
    assert isinstance(leaf, example_node)
    for _ in range(2):
        root.tick_once()
    assert root.status is py_trees.common.Status.RUNNING
    root.tick_once()
    assert root.status is py_trees.common.Status.SUCCESS
    assert [row["type"] for row in node_table(root)] == ["sequence", "count_ticks"]

    xml = to_xml(doc.data, DEFAULTS)
    assert '<CountTicks ticks="3"' in xml
    assert '<Action ID="CountTicks">' in xml  # the TreeNodesModel entry, with its port
    assert 'name="ticks"' in xml
    assert from_xml(xml, "t.xml") == doc.data

    assert "count_ticks" in describe_types()
    assert main(["tree", "--types"]) == 0
    out = capsys.readouterr().out
    assert "count_ticks" in out and "ticks to run" in out


def test_a_node_type_or_btcpp_id_declared_twice_is_refused(example_node) -> None:
    with pytest.raises(ValueError, match="declared twice"):
        declare("count_ticks", "again", "Action")(type("Other", (Behaviour,), {}))
    with pytest.raises(ValueError, match="BT.CPP ID 'CountTicks'"):
        declare("count_ticks_2", "again", "Action")(type("CountTicks", (Behaviour,), {}))


def test_forgotten_example_leaves_the_registry_as_shipped(example_node) -> None:
    forget("count_ticks")
    assert "count_ticks" not in REGISTRY
