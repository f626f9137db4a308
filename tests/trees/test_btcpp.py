"""trees/btcpp.py: the tree as BehaviorTree.CPP v4 XML (what Groot2 opens) and back.

The round trip is checked on the shipped tree both ways it matters: the YAML spec comes back
equal, and the tree the registry builds from it -- guards, timeouts and limits included -- is
the same. The reader is fed what Groot2 writes (the explicit ``<Action ID=...>`` form,
several trees with ``main_tree_to_execute``, ``<SubTree>``) and what the cell must refuse, each
refusal naming the line.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import py_trees
import pytest

from tests.trees.helpers import fresh_ctx
from trees import behaviours as lv
from trees.btcpp import BUILTIN, BtcppError, btcpp_ids, from_xml, to_xml, to_yaml
from trees.registry import NAME, REGISTRY, TreeBuilder
from trees.yaml_lines import load_yaml, parse_yaml

DEFAULTS = {"timeout_s": 30.0, "max_force_n": 80.0, "max_torque_nm": 8.0}
SHIPPED = Path(lv.__file__).resolve().parents[1] / "cell" / "data" / "trees"
TREE = SHIPPED / "bushing_machining.yaml"


def built(spec: object) -> str:
    """The tree the registry builds from ``spec``, as text with every node's class and the
    limits of each guard and timeout (what would differ if a limit were lost)."""
    ctx = fresh_ctx()
    doc = parse_yaml("{}", "t.yaml")
    root = TreeBuilder(ctx, doc, DEFAULTS).build(spec, ())
    rows = []
    for node in root.iterate():
        extra = [
            f"{a}={getattr(node, a)}"
            for a in ("max_force", "max_torque", "seconds", "attempts", "pause", "reason")
            if hasattr(node, a)
        ]
        rows.append(f"{type(node).__name__}:{node.name}:{','.join(extra)}")
    return "\n".join(rows)


def test_every_registered_type_has_one_btcpp_id() -> None:
    assert set(btcpp_ids()) == set(REGISTRY)
    ids = [i for i, _ in btcpp_ids().values()]
    assert all(ids) and len(ids) == len(set(ids))  # each node declares its own, none shared
    for kind, (_, category) in btcpp_ids().items():
        expected = {"composite": {"Control"}, "decorator": {"Decorator"}}.get(
            REGISTRY[kind].kind, {"Action", "Condition"}
        )
        assert category in expected, kind


def test_every_node_declares_the_class_it_builds() -> None:
    """A node's facts sit in its registry entry: its class (a leaf's ``leaf``, else ``cls``)
    is what the tick log's table names it by."""
    from trees.nodes import node_type

    for kind, nt in REGISTRY.items():
        built = nt.leaf if nt.kind == "leaf" else nt.cls
        assert built is not None, kind
        assert node_type(object.__new__(built)) == kind


def test_the_xml_is_btcpp_v4_with_one_tree_and_a_model_of_every_node_type() -> None:
    spec = load_yaml(TREE).data
    root = ET.fromstring(to_xml(spec, DEFAULTS))
    assert root.tag == "root" and root.get("BTCPP_format") == "4"
    trees = root.findall("BehaviorTree")
    assert len(trees) == 1 and trees[0].get("ID") == root.get("main_tree_to_execute")
    model = root.find("TreeNodesModel")
    assert model is not None
    declared = {el.get("ID"): el for el in model}
    used = {el.tag for el in trees[0].iter()} - {"BehaviorTree"}
    assert used - BUILTIN <= set(declared)
    assert set(declared) == {i for i, _ in btcpp_ids().values()} - BUILTIN
    grasp = declared["Grasp"]
    assert grasp.tag == "Action"
    ports = {p.get("name"): p for p in grasp.findall("input_port")}
    assert set(ports) == set(REGISTRY["grasp"].all_params())
    assert ports["max_force_n"].get("type") == "double"
    assert ports["max_force_n"].get("default") == "80"  # the safety section's
    assert declared["Retry"].find("input_port[@name='attempts']").get("type") == "int"
    assert declared["HoldingPart"].tag == "Condition"
    # A node's values are attributes; "name" is the instance's name, never a port.
    tilt = trees[0].find(".//Tilt")
    assert tilt is not None and tilt.get("max_force_n") == "90" and tilt.get("timeout_s") == "40"
    assert all(p.get("name") not in NAME for el in model for p in el)


def test_yaml_to_xml_to_yaml_is_the_same_tree() -> None:
    spec = load_yaml(TREE).data
    back = from_xml(to_xml(spec, DEFAULTS), "tree.xml")
    assert back == spec
    # ... and through the YAML text a cell reads, built by the registry: the same nodes,
    # guards, timeouts and limits.
    again = parse_yaml(to_yaml(back), "tree.yaml").data
    assert again == spec
    assert built(again) == built(spec)


def test_a_limit_changed_in_the_xml_reaches_the_built_guard() -> None:
    spec = load_yaml(TREE).data
    xml = to_xml(spec, DEFAULTS).replace(
        '<Tilt timeout_s="40" max_force_n="90"', '<Tilt timeout_s="45" max_force_n="70"'
    )
    text = built(from_xml(xml, "tree.xml"))
    assert "FTGuard:tilt ft guard:max_force=70.0" in text
    assert "Timeout:tilt timeout:seconds=45.0" in text


GROOT2 = """<?xml version="1.0" encoding="UTF-8"?>
<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Pick">
    <Sequence name="pick">
      <Action ID="Perceive" timeout_s="20"/>
      <PlanPick/>
      <Action ID="Grasp" name="grasp it" max_force_n="55.5"/>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Main">
    <Retry attempts="2">
      <Fallback>
        <SubTree ID="Pick" _autoremap="false"/>
        <Condition ID="HoldingPart"/>
      </Fallback>
    </Retry>
  </BehaviorTree>
  <TreeNodesModel><Action ID="Perceive"/></TreeNodesModel>
</root>
"""


def test_what_groot2_writes_is_read_subtrees_inlined() -> None:
    spec = from_xml(GROOT2, "g.xml")
    assert spec == {
        "type": "retry",
        "attempts": 2,
        "child": {
            "type": "selector",
            "children": [
                {
                    "type": "sequence",
                    "name": "pick",
                    "children": [
                        {"type": "perceive", "timeout_s": 20},
                        {"type": "plan_pick"},
                        {"type": "grasp", "name": "grasp it", "max_force_n": 55.5},
                    ],
                },
                {"type": "holding_part"},
            ],
        },
    }
    assert "FTGuard:grasp it ft guard:max_force=55.5" in built(spec)


@pytest.mark.parametrize(
    ("change", "line", "needle"),
    [
        (("<PlanPick/>", "<PlanPik/>"), 6, "unknown node 'PlanPik'"),
        (('timeout_s="20"', 'timeout="20"'), 5, "a port 'timeout'"),
        (('timeout_s="20"', 'timeout_s="{t}"'), 5, "blackboard references"),
        (('timeout_s="20"', 'timeout_s="twenty"'), 5, "expected float"),
        (('max_force_n="55.5"', 'max_force_n="900"'), 7, "must lie in [1, 300]"),
        (('attempts="2"', ""), 11, "needs 'attempts'"),
        (('<Retry attempts="2">', '<Retry attempts="2"><PlanPick/>'), 11, "exactly one child"),
        (("<PlanPick/>", '<PlanPick _skipIf="x"/>'), 6, "script pre/post condition"),
        (('<SubTree ID="Pick" _autoremap="false"/>', '<SubTree ID="Main"/>'), 13, "itself"),
        (
            ('<SubTree ID="Pick" _autoremap="false"/>', '<SubTree ID="Pick" x="{y}"/>'),
            13,
            "remapping",
        ),
        (('BTCPP_format="4"', 'BTCPP_format="3"'), 2, "BTCPP_format is '3'"),
        (('main_tree_to_execute="Main"', 'main_tree_to_execute="Nope"'), 2, "'Nope'"),
        (("</Fallback>", "</Fallbak>"), 15, "not well-formed"),
        (("<PlanPick/>", '<PlanPick ahead="maybe"/>'), 6, "expected true or false"),
    ],
)
def test_refusals_name_the_line(change: tuple[str, str], line: int, needle: str) -> None:
    text = GROOT2.replace(*change)
    assert text != GROOT2
    with pytest.raises(BtcppError) as info:
        from_xml(text, "g.xml")
    message = str(info.value)
    assert message.startswith(f"g.xml:{line}:"), message
    assert needle in message, message


def test_the_cli_writes_tree_xml_and_reads_it_back(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from cell.cli import main

    assert main(["tree", "--format", "btcpp", "--out", str(tmp_path)]) == 0
    xml = tmp_path / "tree.xml"
    assert ET.parse(xml).getroot().get("BTCPP_format") == "4"
    back = tmp_path / "back"
    assert main(["tree", "--from-btcpp", str(xml), "--out", str(back)]) == 0
    assert load_yaml(back / "tree.yaml").data == load_yaml(TREE).data
    capsys.readouterr()
    # Without --out the YAML is printed; a broken file is one line and exit 2.
    assert main(["tree", "--from-btcpp", str(xml)]) == 0
    assert parse_yaml(capsys.readouterr().out, "-").data == load_yaml(TREE).data
    bad = tmp_path / "bad.xml"
    bad.write_text(xml.read_text().replace("<PlanPick />", "<Nope />"))
    assert main(["tree", "--from-btcpp", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"cell tree: error: {bad}:") and "'Nope'" in err[0]
    # --format names what a configured tree is written as: with --from-btcpp it is refused,
    # never silently ignored, and nothing is written.
    for fmt in ("btcpp", "picture"):
        assert main(["tree", "--from-btcpp", str(xml), "--format", fmt,
                     "--out", str(tmp_path / "refused")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--format" in err[0] and "--from-btcpp" in err[0]
    assert not (tmp_path / "refused").exists()
    py_trees.blackboard.Blackboard.clear()
