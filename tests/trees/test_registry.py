"""trees/registry.py on its own: the YAML node specs it accepts, what it builds from them, and the
errors it gives (file, line, key, the valid choices).

tests/cell/test_config.py checks a few of these errors through the whole configuration
(``prepare``); here the builder is driven directly, so each rule is checked where it lives: every
motion leaf is built as leaf -> Timeout -> FTGuard with the node's limits or the safety defaults,
condition and planning leaves are not wrapped, decorators get their parameters, and the shipped
tree's limits are the ones its YAML states.
"""

from __future__ import annotations

from pathlib import Path

import py_trees
import pytest
from py_trees.behaviour import Behaviour
from py_trees.common import Status

from tests.trees.helpers import fresh_ctx
from trees import behaviours as lv
from trees.decorators import Cycles, FTGuard, FTSampler, Retry, StopOnFailure, Timeout
from trees.registry import (
    MOTION,
    REGISTRY,
    TreeBuilder,
    build_root,
    describe_types,
    resolve_tree_spec,
)
from trees.yaml_lines import ConfigError, load_yaml, parse_yaml

DEFAULTS = {"timeout_s": 30.0, "max_force_n": 80.0, "max_torque_nm": 8.0}
SHIPPED = Path(lv.__file__).resolve().parents[1] / "cell" / "data" / "trees"


@pytest.fixture
def ctx():
    return fresh_ctx()


def build(text: str, ctx, defaults: dict[str, float] | None = None) -> Behaviour:  # type: ignore[no-untyped-def]
    doc = parse_yaml(text, "tree.yaml")
    return TreeBuilder(ctx, doc, defaults or DEFAULTS).build(doc.data, ())


def error(text: str, ctx) -> ConfigError:  # type: ignore[no-untyped-def]
    with pytest.raises(ConfigError) as info:
        build(text, ctx)
    return info.value


def unwrap(node: Behaviour) -> tuple[FTGuard, Timeout, Behaviour]:
    assert isinstance(node, FTGuard), type(node)
    timeout = node.decorated
    assert isinstance(timeout, Timeout), type(timeout)
    return node, timeout, timeout.decorated


# ------------------------------------------------------------------------- motion leaves
MOTION_LEAVES = sorted(
    name for name, nt in REGISTRY.items()
    if nt.kind == "leaf" and getattr(nt.leaf, "moves", False)
)


def test_every_motion_leaf_takes_the_motion_limits() -> None:
    assert set(MOTION_LEAVES) >= {"grasp", "tilt", "align", "put_back", "go_home", "pack_in_box"}
    for name in MOTION_LEAVES:
        assert set(MOTION) <= set(REGISTRY[name].params), name


@pytest.mark.parametrize("kind", MOTION_LEAVES)
def test_a_motion_leaf_is_wrapped_in_a_timeout_inside_an_ft_guard_with_the_nodes_limits(
    ctx, kind
) -> None:
    node = build(f"{{type: {kind}, timeout_s: 12, max_force_n: 55, max_torque_nm: 4.5}}", ctx)
    guard, timeout, leaf = unwrap(node)
    assert isinstance(leaf, REGISTRY[kind].leaf)
    assert (guard.max_force, guard.max_torque, timeout.seconds) == (55.0, 4.5, 12.0)
    assert leaf.name == kind.replace("_", " ")


@pytest.mark.parametrize("kind", MOTION_LEAVES)
def test_a_motion_leaf_without_limits_gets_the_safety_defaults(ctx, kind) -> None:
    defaults = {"timeout_s": 7.0, "max_force_n": 42.0, "max_torque_nm": 3.0}
    guard, timeout, _ = unwrap(build(f"{{type: {kind}}}", ctx, defaults))
    assert (guard.max_force, guard.max_torque, timeout.seconds) == (42.0, 3.0, 7.0)


def test_each_limit_falls_back_on_its_own_default(ctx) -> None:
    guard, timeout, _ = unwrap(build("{type: tilt, max_force_n: 90}", ctx))
    assert (guard.max_force, guard.max_torque, timeout.seconds) == (90.0, 8.0, 30.0)


@pytest.mark.parametrize(
    "kind", ["plan_pick", "slot_holds_part", "holding_part", "slot_machined", "wait_machining"]
)
def test_leaves_that_do_not_move_are_not_wrapped(ctx, kind) -> None:
    node = build(f"{{type: {kind}}}", ctx)
    assert isinstance(node, REGISTRY[kind].leaf)
    assert not isinstance(node, FTGuard | Timeout)


def test_the_shipped_tree_has_the_limits_its_yaml_states(ctx) -> None:
    doc = load_yaml(SHIPPED / "bushing_machining.yaml")
    root = TreeBuilder(ctx, doc, DEFAULTS).build(doc.data, ())
    guards = {
        n.decorated.decorated.name: (n.max_force, n.max_torque, n.decorated.seconds)
        for n in root.iterate()
        if isinstance(n, FTGuard)
    }
    assert guards["perceive"] == (80.0, 8.0, 20.0)
    assert guards["grasp"] == (60.0, 8.0, 20.0)
    assert guards["tilt"] == (90.0, 8.0, 40.0)
    assert guards["align"] == (60.0, 8.0, 40.0)
    assert guards["put back"] == (250.0, 30.0, 20.0)  # opens under load after an abort
    assert guards["via home"] == (80.0, 8.0, 20.0)
    assert guards["pack in box"] == (60.0, 8.0, 40.0)
    assert guards["leave box"] == (60.0, 8.0, 20.0)  # a packing stopped past its let go
    assert guards["leave slot"] == (60.0, 8.0, 20.0)  # a feed stopped past its let go
    assert guards["lift from slot"] == (60.0, 8.0, 20.0)  # a pick stopped past its pinch
    assert guards["reposition"] == (60.0, 8.0, 30.0)
    assert guards["look again"] == (80.0, 8.0, 20.0)
    assert guards["look ahead"] == (80.0, 8.0, 20.0)  # while the machine runs
    assert guards["home to look"] == guards["back over slot"] == (80.0, 8.0, 20.0)
    # every motion leaf in the shipped tree is guarded, and nothing else is
    moving = [n for n in root.iterate() if getattr(type(n), "moves", False)]
    assert guards["pick standing"] == (60.0, 8.0, 40.0)
    assert len(moving) == len(guards) == 20
    assert isinstance(root, Cycles)


# ----------------------------------------------------------------- decorators, composites
def test_decorators_get_their_parameters_and_the_child(ctx) -> None:
    text = """\
type: stop_on_failure
reason: part lost
child:
  type: retry
  attempts: 4
  pause_s: 1.5
  child:
    type: timeout
    seconds: 2
    child:
      type: ft_guard
      max_force_n: 33
      child: {type: plan_pick}
"""
    stop = build(text, ctx)
    assert isinstance(stop, StopOnFailure) and stop.reason == "part lost"
    retry = stop.decorated
    assert isinstance(retry, Retry) and (retry.attempts, retry.pause_s) == (4, 1.5)
    timeout = retry.decorated
    assert isinstance(timeout, Timeout) and timeout.seconds == 2.0
    guard = timeout.decorated
    assert isinstance(guard, FTGuard)
    assert (guard.max_force, guard.max_torque) == (33.0, 8.0)  # torque: the default
    assert isinstance(guard.decorated, lv.PlanPick)


def test_a_retry_without_a_pause_does_not_pause(ctx) -> None:
    retry = build("{type: retry, attempts: 2, child: {type: plan_pick}}", ctx)
    assert isinstance(retry, Retry) and retry.pause_s == 0.0


def test_composites_keep_their_childrens_order_and_remember_progress(ctx) -> None:
    text = """\
type: sequence
name: cycle
children:
  - {type: slot_holds_part}
  - type: selector
    children: [{type: slot_machined}, {type: wait_machining}]
"""
    seq = build(text, ctx)
    assert isinstance(seq, py_trees.composites.Sequence) and seq.name == "cycle"
    assert seq.memory
    first, sel = seq.children
    assert isinstance(first, lv.SlotHoldsPart)
    assert isinstance(sel, py_trees.composites.Selector) and sel.memory
    assert [type(c) for c in sel.children] == [lv.SlotMachined, lv.WaitMachining]


def test_names_stay_unique_for_the_blackboard_and_the_log(ctx) -> None:
    text = "type: sequence\nchildren: [{type: go_home}, {type: go_home}, {type: go_home, name: x}]"
    seq = build(text, ctx)
    names = [n.name for n in seq.iterate()]
    assert len(names) == len(set(names))
    leaves = [n.name for n in seq.iterate() if isinstance(n, lv.GoHome)]
    assert leaves == ["go home", "go home #2", "x"]


def test_a_built_tree_ticks_its_motion_leaf_under_its_guard(ctx) -> None:
    """Not just the right classes: the built guard trips on the node's own limit."""
    root = build_root(
        {"type": "go_home", "max_force_n": 20.0}, parse_yaml("", "t.yaml"), (), ctx, DEFAULTS
    )
    ctx.devices.arm.ticks_per_move = 1000
    root.tick_once()
    assert root.status == Status.RUNNING
    ctx.devices.ft.value[:] = [0, 0, 25.0, 0, 0, 0]  # over the node's 20 N, under the default
    root.tick_once()
    assert root.status == Status.FAILURE
    assert ctx.devices.arm.stops >= 1 and len(ctx.events.aborts) == 1


def test_the_root_runs_the_sampler_beside_the_body_and_ends_with_the_body(ctx) -> None:
    root = build_root({"type": "slot_holds_part"}, parse_yaml("", "t.yaml"), (), ctx, DEFAULTS)
    assert isinstance(root, py_trees.composites.Parallel)
    sampler, body = root.children
    assert isinstance(sampler, FTSampler) and isinstance(body, lv.SlotHoldsPart)
    ctx.slot_state = "fed"  # the sampler never ends; the body's success ends the tree
    root.tick_once()
    assert root.status == Status.SUCCESS


def test_build_root_clears_what_a_previous_tree_left_on_the_blackboard(ctx) -> None:
    client = py_trees.blackboard.Client(name="old tree")
    client.register_key("/part/target", access=py_trees.common.Access.WRITE)
    client.set("/part/target", {"stale": True})
    build_root({"type": "plan_pick"}, parse_yaml("", "t.yaml"), (), ctx, DEFAULTS)
    assert "/part/target" not in py_trees.blackboard.Blackboard.storage


# ------------------------------------------------------------------------------------ errors
def test_an_unknown_type_names_its_line_key_and_every_valid_type(ctx) -> None:
    err = error("type: sequence\nchildren:\n  - {type: go_home}\n  - {type: fly}\n", ctx)
    assert (err.source, err.line, err.key) == ("tree.yaml", 4, "children[1].type")
    for name in REGISTRY:
        assert name in err.reason


def test_a_missing_type_and_a_node_that_is_not_a_mapping_are_refused(ctx) -> None:
    err = error("type: sequence\nchildren:\n  - {attempts: 3}\n", ctx)
    assert (err.line, err.key) == (3, "children[0]")
    assert "go_home" in err.reason  # the valid types
    err = error("type: sequence\nchildren:\n  - 42\n", ctx)
    assert (err.line, err.key) == (3, "children[0]")


def test_an_unknown_parameter_lists_the_valid_ones_of_that_type(ctx) -> None:
    err = error("type: retry\nattempts: 2\ntries: 3\nchild: {type: plan_pick}\n", ctx)
    assert (err.line, err.key) == (3, "tries")
    for valid in ("name", "attempts", "pause_s", "child"):
        assert valid in err.reason
    err = error("{type: tilt, max_force: 50}", ctx)  # the unit is part of the key's name
    assert err.key == "max_force"
    for valid in ("timeout_s", "max_force_n", "max_torque_nm"):
        assert valid in err.reason


def test_a_leaf_without_parameters_refuses_any(ctx) -> None:
    err = error("{type: plan_pick, timeout_s: 3}", ctx)
    assert err.key == "timeout_s"


@pytest.mark.parametrize(
    ("text", "key", "bound"),
    [
        ("{type: go_home, max_force_n: 301}", "max_force_n", "300"),
        ("{type: go_home, max_force_n: 0.5}", "max_force_n", "1"),
        ("{type: go_home, timeout_s: 0.05}", "timeout_s", "0.1"),
        ("{type: go_home, max_torque_nm: 31}", "max_torque_nm", "30"),
        ("{type: retry, attempts: 101, child: {type: plan_pick}}", "attempts", "100"),
        ("{type: retry, attempts: 2, pause_s: -1, child: {type: plan_pick}}", "pause_s", "60"),
        ("{type: timeout, seconds: 0, child: {type: plan_pick}}", "seconds", "0.01"),
        ("{type: ft_guard, max_force_n: 1000, child: {type: plan_pick}}", "max_force_n", "300"),
    ],
)
def test_a_value_out_of_range_names_the_key_and_the_range(ctx, text, key, bound) -> None:
    err = error(text, ctx)
    assert err.key == key and err.line == 1
    assert bound in err.reason


def test_the_bounds_themselves_are_accepted(ctx) -> None:
    guard, timeout, _ = unwrap(
        build("{type: go_home, max_force_n: 300, max_torque_nm: 0.1, timeout_s: 3600}", ctx)
    )
    assert (guard.max_force, guard.max_torque, timeout.seconds) == (300.0, 0.1, 3600.0)


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("{type: retry, child: {type: plan_pick}}", "attempts"),
        ("{type: timeout, child: {type: plan_pick}}", "seconds"),
        ("{type: stop_on_failure, child: {type: plan_pick}}", "reason"),
    ],
)
def test_a_missing_required_parameter_is_named(ctx, text, key) -> None:
    err = error(text, ctx)
    assert key in err.reason and err.line == 1


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("{type: go_home, timeout_s: '10 s'}", "timeout_s"),
        ("{type: go_home, max_force_n: true}", "max_force_n"),  # a bool is not a number
        ("{type: retry, attempts: 2.5, child: {type: plan_pick}}", "attempts"),
        ("{type: stop_on_failure, reason: 3, child: {type: plan_pick}}", "reason"),
    ],
)
def test_a_value_of_the_wrong_kind_is_refused(ctx, text, key) -> None:
    assert error(text, ctx).key == key


def test_an_integer_is_accepted_as_seconds_and_newtons(ctx) -> None:
    guard, timeout, _ = unwrap(build("{type: go_home, timeout_s: 5, max_force_n: 70}", ctx))
    assert isinstance(timeout.seconds, float) and isinstance(guard.max_force, float)


def test_structure_errors_decorator_without_child_composite_without_children(ctx) -> None:
    err = error("{type: retry, attempts: 2}", ctx)
    assert err.line == 1 and "child" in err.reason
    err = error("type: selector\nchildren: []\n", ctx)
    assert err.key == "children" and err.line == 2
    err = error("type: selector\nchildren: {type: plan_pick}\n", ctx)  # a mapping, not a list
    assert err.key == "children"


# ------------------------------------------------------------------- tree files, type list
def _config_doc(tmp_path: Path, text: str):  # type: ignore[no-untyped-def]
    path = tmp_path / "cell.yaml"
    path.write_text(text, encoding="utf-8")
    return load_yaml(path)


def test_a_tree_file_is_found_beside_the_config_before_the_shipped_ones(tmp_path) -> None:
    (tmp_path / "bushing_machining.yaml").write_text("type: go_home\n", encoding="utf-8")
    doc = _config_doc(tmp_path, "tree:\n  file: bushing_machining.yaml\n")
    spec, tree_doc, path = resolve_tree_spec(doc.data["tree"], doc, SHIPPED)
    assert spec == {"type": "go_home"} and path == ()
    assert Path(tree_doc.source).parent == tmp_path

    other = tmp_path / "elsewhere"
    other.mkdir()
    doc = _config_doc(other, "tree:\n  file: bushing_machining.yaml\n")
    spec, tree_doc, _ = resolve_tree_spec(doc.data["tree"], doc, SHIPPED)
    assert spec["type"] == "cycles"  # the shipped one
    assert Path(tree_doc.source).parent == SHIPPED


def test_an_inline_tree_is_built_from_the_config_itself(tmp_path) -> None:
    doc = _config_doc(tmp_path, "tree:\n  type: go_home\n")
    spec, tree_doc, path = resolve_tree_spec(doc.data["tree"], doc, SHIPPED)
    assert spec == {"type": "go_home"} and tree_doc is doc and path == ("tree",)


@pytest.mark.parametrize(
    "text",
    [
        "tree:\n  file: nowhere.yaml\n",
        "tree:\n  file: 3\n",
        "tree:\n  file: x.yaml\n  type: go_home\n",
    ],
)
def test_bad_tree_file_references_are_refused_at_the_tree_file_key(tmp_path, text) -> None:
    doc = _config_doc(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        resolve_tree_spec(doc.data["tree"], doc, SHIPPED)
    assert info.value.key == "tree.file" and info.value.line == 2


def test_the_type_list_names_every_type_and_its_parameters() -> None:
    text = describe_types()
    for name, nt in REGISTRY.items():
        line = next(ln for ln in text.splitlines() if ln.split()[:1] == [name])
        assert nt.kind in line
        for param in nt.params:
            assert param in text


def test_the_shipped_trees_limits_are_listed_for_cell_tree(ctx) -> None:
    from trees.render import limits_table

    doc = load_yaml(SHIPPED / "bushing_machining.yaml")
    root = TreeBuilder(ctx, doc, DEFAULTS).build(doc.data, ())
    lines = limits_table(root)
    assert "tilt: 90 N, 8 N*m, 40 s" in lines and "put back: 250 N, 30 N*m, 20 s" in lines
    assert len(lines) == 20  # every guarded motion leaf, once


@pytest.mark.parametrize("value", ["1", "maybe", "0.5"])
def test_a_bool_parameter_takes_true_or_false_only(ctx, value: str) -> None:
    assert isinstance(build("type: plan_pick\nahead: true\n", ctx), Behaviour)
    err = error(f"type: plan_pick\nahead: {value}\n", ctx)
    assert err.key.endswith("ahead") and "expected bool" in str(err)
    assert "SI" not in str(err)  # the units hint is for numbers
