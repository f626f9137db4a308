"""One source for every limit and parameter: the configuration flows down into the skills.

The cell-wide ``safety`` section, the ``skills:`` sections and a tree node's own keys decide what
a skill runs with; these tests change a value in the YAML and look for it where the skill acts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from py_trees.common import Status

from cell.assemble import prepare
from cell.cli import main
from cell.config import config_from_text, load_config, schema
from skills.status import Failure
from tests.trees.helpers import make_ctx, tick_tree
from trees import behaviours as lv
from trees.registry import describe_types
from trees.yaml_lines import ConfigError

HEAD = """\
cell: {backend: sim}
workflow: {part: bushing}
"""


def _prep(text: str, tmp_path):
    path = tmp_path / "cell.yaml"
    path.write_text(text)
    config, doc = load_config(path)
    return prepare(config, doc)


def _leaf(prep, cls):
    return next(n for n in prep.root.iterate() if isinstance(n, cls))


def test_a_node_limit_is_the_skills_guard_and_caps_its_stricter_guards(tmp_path) -> None:
    tree = """tree:
  type: sequence
  children:
    - {type: tilt, max_force_n: 90}
    - {type: align, max_force_n: 20, max_torque_nm: 3}
"""
    prep = _prep(HEAD + tree, tmp_path)
    tilt = _leaf(prep, lv.Tilt).settings()
    assert (tilt.guard.max_force, tilt.guard.max_torque) == (90.0, 8.0)  # torque: safety's
    align = _leaf(prep, lv.Align).settings()
    assert (align.guard.max_force, align.guard.max_torque) == (20.0, 3.0)
    # the slide into the hole stops at 25 N on its own, but never above the node's 20 N
    assert align.descent_guard.max_force == 20.0
    guards = {n.name: n.max_force for n in prep.root.iterate() if n.name.endswith("ft guard")}
    assert guards == {"tilt ft guard": 90.0, "align ft guard": 20.0}


def test_the_safety_section_is_the_default_of_every_guard(tmp_path) -> None:
    text = HEAD + "safety: {ft_abort_force_n: 42, ft_abort_torque_nm: 5}\n"
    prep = _prep(text + "tree:\n  type: pack_in_box\n", tmp_path)
    pack = _leaf(prep, lv.PackInBox).settings()
    assert (pack.guard.max_force, pack.guard.max_torque) == (42.0, 5.0)
    assert pack.push_guard.max_force == 30.0 and pack.push_guard.max_torque == 5.0


@pytest.mark.parametrize(("limit", "aborts"), [(45, True), (55, False)])
def test_the_skill_stops_at_the_limit_the_yaml_gives(limit: int, aborts: bool) -> None:
    """A 50 N wrench, the tree YAML's limit on either side of it: built from the YAML and
    ticked, the skill's own guard (the FT guard decorator is taken off) stops the arm at the
    new value, with the force-torque code."""
    from trees.decorators import FTGuard, Timeout
    from trees.registry import TreeBuilder
    from trees.yaml_lines import parse_yaml

    ctx = make_ctx()
    ctx.devices.arm.ticks_per_move = 20
    ctx.devices.ft.value = np.array([0.0, 0.0, 50.0, 0.0, 0.0, 0.0])
    doc = parse_yaml(f"type: go_home\nmax_force_n: {limit}\n", "tree.yaml")
    defaults = {"timeout_s": 30.0, "max_force_n": 80.0, "max_torque_nm": 8.0}
    guard = TreeBuilder(ctx, doc, defaults).build(doc.data, ())
    assert isinstance(guard, FTGuard) and isinstance(guard.decorated, Timeout)
    leaf = guard.decorated.decorated  # the skill alone: no decorator checks the wrench
    statuses = tick_tree(leaf, ctx, ticks=40)
    if aborts:
        assert statuses[-1] == Status.FAILURE
        assert ctx.devices.arm.stops >= 1
        assert ctx.events.codes == [Failure.FORCE_TORQUE]
        assert "limit 45" in ctx.events.aborts[0]
    else:
        assert statuses[-1] == Status.SUCCESS and ctx.events.aborts == []


def test_the_skills_section_reaches_the_skill_and_a_node_overrides_it(tmp_path) -> None:
    text = HEAD + """skills:
  pivot: {tilt_speed_m_s: 0.015, tilt_past_tip_deg: 6, descent_max_force_n: 18}
  slot: {grip_depth_m: 0.025}
  pack_in_box: {push_speed_m_s: 0.005}
  go_home: {joint_speed_deg_s: 30}
tree:
  type: sequence
  children:
    - {type: tilt, tilt_speed_m_s: 0.005}
    - {type: align}
    - {type: pack_in_box}
    - {type: go_home}
"""
    prep = _prep(text, tmp_path)
    assert prep.ctx.params.tilt_speed == 0.015
    assert prep.ctx.params.tilt_past_tip == pytest.approx(math.radians(6))
    tilt = _leaf(prep, lv.Tilt).settings()
    assert tilt.tilt_speed == 0.005  # the node's own
    align = _leaf(prep, lv.Align).settings()
    assert align.tilt_speed == 0.015 and align.descent_guard.max_force == 18.0
    # one hole grasp for the whole cell: the slot's depth is Align's and the packing's
    assert align.wall_depth == 0.025
    pack = _leaf(prep, lv.PackInBox).settings()
    assert pack.grip_depth == 0.025 and pack.push_speed == 0.005
    home = _leaf(prep, lv.GoHome).settings()
    assert home.joint_speed == pytest.approx(math.radians(30))


@pytest.mark.parametrize(
    ("text", "key", "words"),
    [
        ("skills:\n  pivot: {tilt_speed_m_s: 5}\n", "skills.pivot.tilt_speed_m_s", "0.1"),
        ("skills:\n  pivot: {tilt_speed: 0.01}\n", "skills.pivot.tilt_speed", "tilt_speed_m_s"),
        ("skills:\n  pivot: {tilt_speed_m_s: '1 cm/s'}\n", "skills.pivot.tilt_speed_m_s",
         "unit is in the key's name"),
        ("skills:\n  grasp: {}\n", "skills.grasp", "pivot"),
    ],
)
def test_bad_skill_values_name_the_key_and_the_reason(text: str, key: str, words: str) -> None:
    with pytest.raises(ConfigError) as info:
        config_from_text(HEAD + text, "cell.yaml")
    assert info.value.key == key and words in str(info.value), str(info.value)


def test_a_node_override_is_checked_against_its_skills_range(tmp_path) -> None:
    with pytest.raises(ConfigError) as info:
        _prep(HEAD + "tree:\n  type: tilt\n  tilt_speed_m_s: 3\n", tmp_path)
    assert info.value.key == "tree.tilt_speed_m_s" and "[0.001, 0.1]" in str(info.value)
    with pytest.raises(ConfigError) as info:
        _prep(HEAD + "tree:\n  type: go_home\n  tilt_speed_m_s: 0.01\n", tmp_path)
    assert "joint_speed_deg_s" in str(info.value)  # the valid keys are listed


def test_types_and_schema_show_each_key_with_unit_range_and_default() -> None:
    text = describe_types()
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("tilt_speed_m_s"))
    assert "[0.001, 0.1]" in line and "m/s" in line and "default 0.07" in line
    assert "tilt_past_tip_deg" in text and "default 4" in text
    props = schema()["$defs"]
    pivot = next(v for k, v in props.items() if k.startswith("SkillsPivot"))
    speed = pivot["properties"]["tilt_speed_m_s"]
    assert (speed["default"], speed["minimum"], speed["maximum"]) == (0.07, 0.001, 0.1)


def test_cli_bad_skill_value_exits_2_without_traceback(tmp_path, capsys) -> None:
    path = tmp_path / "cell.yaml"
    path.write_text(HEAD + "skills:\n  slot: {insert_speed_m_s: -1}\n")
    assert main(["tree", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "cell.yaml:4" in err and "insert_speed_m_s" in err and "Traceback" not in err


def test_the_experiments_take_the_skills_from_a_configuration(tmp_path, capsys) -> None:
    """`cell pivot --config` and `cell compare --config` run the skills with a file's
    skills.pivot section and safety limits; no code edit tunes a skill."""
    from lab.pivot_cmd import pivot_overrides

    path = tmp_path / "cell.yaml"
    path.write_text("skills:\n  pivot: {tilt_speed_m_s: 0.015}\nsafety: {ft_abort_force_n: 70}\n")
    over = pivot_overrides(path)
    assert over["tilt_speed"] == 0.015 and over["guard"].max_force == 70.0
    assert pivot_overrides(None) == {}  # the defaults: nothing changed
    path.write_text("skills:\n  pivot: {tilt_speed_m_s: 2}\n")
    code = main(["pivot", "--part", "bushing", "--config", str(path), "--json", "x.json"])
    err = capsys.readouterr().err
    assert code == 2 and "skills.pivot.tilt_speed_m_s" in err and "Traceback" not in err


def test_sim_servoj_hands_the_drivers_servo_law_to_the_twins_trials() -> None:
    """``sim.servoj`` (on by default) makes the twin's arm follow the stream by devices.arm's
    servoj values, as the UR follows the driver's servoL; off, the trials keep their own arm
    (None)."""
    from lab.pivot_cmd import trial_config

    assert trial_config(None).servo == (0.05, 1000.0)  # nothing given: the shipped default
    assert trial_config(None, ["sim.seed=1"]).servo == (0.05, 1000.0)
    assert trial_config(None, ["sim.servoj=false"]).servo is None
    sets = ["devices.arm.servo_lookahead_s=0.08", "devices.arm.servo_gain=500"]
    on = trial_config(None, sets)
    assert on.servo == (0.08, 500.0)
