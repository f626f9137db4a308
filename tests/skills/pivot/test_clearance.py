"""The pivot's sweep against the bin's walls and the neighbours, and the choice of a tube's end.

The bin: the default layout's (0.22..0.72 m x -0.16..0.16 m, walls 80 mm high); the part: the
catalogue's bushing (68 mm long, 34 mm across) with its plan's l_a and alpha."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from cell.reach import ur5_reach
from drivers.parts import Gripper
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import plan_pivot
from skills.pivot.clearance import (
    STANDING_UP,
    Obstacle,
    bin_walls,
    choose_end,
    lying_part,
    pivot_clearance,
    standing_sweep,
)
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams

ROI = (0.22, 0.72, -0.16, 0.16)
WALLS = bin_walls(ROI, 0.0, 0.08, 0.005)
W = Gripper().finger_width


@pytest.fixture(scope="module")
def bushing():  # type: ignore[no-untyped-def]
    part = load_catalogue(None).get("bushing")
    plan = plan_pivot(part, Gripper(), Frictions())
    return part, PivotParams(l_a=plan.l_a, alpha=plan.alpha)


def frame(part, x: float, y: float, yaw: float) -> PivotFrame:  # type: ignore[no-untyped-def]
    return PivotFrame(part.section(W), np.array([x, y, 0.5 * part.outer]), yaw, floor_z=0.0)


def test_a_box_measures_signed_distance_inside_and_out() -> None:
    box = Obstacle("b", np.array([0.0, 0.0, 0.0]), np.array([0.1, 0.05, 0.02]), math.pi / 2)
    # turned 90 deg: its long side runs along y
    d = box.distance(np.array([[0.0, 0.0, 0.0], [0.0, 0.12, 0.0], [0.08, 0.0, 0.0]]))
    assert d[0] == pytest.approx(-0.02)  # the centre: the nearest face 20 mm away (z)
    assert d[1] == pytest.approx(0.02) and d[2] == pytest.approx(0.03)


def test_a_part_in_the_middle_of_the_bin_clears(bushing) -> None:
    part, params = bushing
    c = pivot_clearance(frame(part, 0.47, 0.0, 0.0), params, WALLS, W)
    assert c.clear and c.distance > 0.02, c.reason()


def test_a_tube_whose_tilt_would_swing_into_a_near_wall_is_pivoted_from_its_other_end(
    bushing,
) -> None:
    part, params = bushing
    # 90 mm from the +y wall to its centre, the open end away from it: the Tilt carries the
    # gripper back over the pivot end, into that wall; from the other end it clears (the
    # approach beyond an open end needs less room than the arc behind the pivot)
    f = frame(part, 0.47, 0.07, -math.pi / 2)
    away = pivot_clearance(f, params, WALLS, W)
    assert not away.clear and away.obstacle == "the bin's +y wall", away.reason()
    assert away.phase == "on the Tilt's arc"
    choice = choose_end(f, params, WALLS, W, open_ends=2, reach=ur5_reach)
    assert choice.clearance.clear
    assert choice.frame.u[1] == pytest.approx(1.0)  # the open end used now points to +y
    # a part with one open end has no other end: left blocked, saying by what
    one = choose_end(f, params, WALLS, W, open_ends=1, reach=ur5_reach)
    assert not one.clearance.clear and one.frame is f
    assert "the bin's +y wall" in one.clearance.reason()


def test_between_two_ends_that_clear_the_one_pointing_away_from_the_base_is_kept(bushing) -> None:
    part, params = bushing
    toward_base = frame(part, 0.47, 0.0, math.pi)
    choice = choose_end(toward_base, params, WALLS, W, open_ends=2, reach=ur5_reach)
    assert choice.clearance.clear and choice.frame.u[0] == pytest.approx(1.0)


def test_a_neighbour_where_the_tilt_goes_blocks_the_pivot(bushing) -> None:
    part, params = bushing
    f = frame(part, 0.47, 0.0, 0.0)
    # lying crosswise just behind the pivot end, where the Tilt carries the gripper
    behind = lying_part("a neighbour", (0.47 - 0.034 - 0.03, 0.0), math.pi / 2, 0.068, 0.034, 0.0)
    c = pivot_clearance(f, params, [*WALLS, behind], W)
    assert not c.clear and c.obstacle == "a neighbour", c.reason()
    # the gripper on the arc and the part's own base swinging back both meet it
    assert standing_sweep(f)[:, 0].min() < 0.47 - 0.034 - 0.03 + 0.017


def test_a_part_whose_base_would_stand_up_in_a_wall_does_not_clear() -> None:
    """A cookie can (one open end, 90 mm across) whose closed end lies 40 mm from the -y
    wall: the gripper's sweep over the open end clears, but standing up about G its base
    swings back 90 mm beyond G, into the wall (the twin's Tilt met it at 23 deg, 80 N)."""
    part = load_catalogue(None).get("cookie_can")
    plan = plan_pivot(part, Gripper(), Frictions())
    params = PivotParams(l_a=plan.l_a, alpha=plan.alpha)
    g_y = -0.16 + 0.04
    f = frame(part, 0.47, g_y + 0.5 * part.length, math.pi / 2)  # open end towards +y
    assert f.pivot[1] == pytest.approx(g_y)
    c = pivot_clearance(f, params, WALLS, W)
    assert not c.clear and c.tool_part == "the part" and c.phase == STANDING_UP, c.reason()
    assert c.obstacle == "the bin's -y wall"
    assert "the part would hit the bin's -y wall standing up" in c.reason()
    # twice as far from the wall it stands up clear of it
    far = frame(part, 0.47, g_y + 0.06 + 0.5 * part.length, math.pi / 2)
    assert pivot_clearance(far, params, WALLS, W).clear


def test_the_margin_is_the_configured_one(bushing) -> None:
    part, params = bushing
    f = frame(part, 0.47, 0.0, 0.0)
    loose = pivot_clearance(f, dataclasses.replace(params, clearance_margin=0.0), WALLS, W)
    tight = pivot_clearance(f, dataclasses.replace(params, clearance_margin=0.01), WALLS, W)
    assert loose.distance - tight.distance == pytest.approx(0.01)


def test_an_end_whose_sweep_leaves_the_arms_reach_does_not_clear(bushing) -> None:
    part, params = bushing
    f = frame(part, 0.47, 0.0, 0.0)  # clears the walls (above)
    asked: list[int] = []

    def to_the_grasp_only(poses) -> int | None:  # type: ignore[no-untyped-def]
        asked.append(len(poses))
        return 1  # reaches the pose above the part, not the grasp

    choice = choose_end(f, params, WALLS, W, open_ends=2, reach=to_the_grasp_only)
    assert asked == [3, 3]  # both ends: above, at the grasp, the arc's end
    assert not choice.clearance.clear
    assert choice.clearance.phase == "on the approach at alpha"
    assert "reach" in choice.clearance.reason()


def test_the_ur5_reach_passes_the_middle_of_the_bin_and_stops_a_part_beyond_it(bushing) -> None:
    part, params = bushing
    near = choose_end(frame(part, 0.47, 0.0, 0.0), params, [], W, 2, reach=ur5_reach)
    assert near.clearance.clear
    far = choose_end(frame(part, 1.2, 0.0, 0.0), params, [], W, 2, reach=ur5_reach)
    assert not far.clearance.clear and far.clearance.tool_part == "the TCP"
    assert far.clearance.phase == "coming down over the open end"  # the first pose already
