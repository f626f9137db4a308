"""FeedSlot and PickFromSlot in the twin, judged from the simulated state.

The part gets into the hole grasp by physics: it is spawned standing in the bin and Align takes
the grasp with the wrist camera. Nothing is welded or teleported; the judges read the simulator
only after the skills ended. About 3 s of wall time per scenario.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.judge import judge, judge_in_slot
from skills.slot import FeedSlot, PickFromSlot
from tests.skills.twin import BIN_SPOTS, make_twin, take_hole_grasp

SEED = 3


@pytest.fixture(scope="module")
def fed_and_picked() -> dict:
    """Align -> FeedSlot -> (judge) -> PickFromSlot -> (judge), one world."""
    tw = make_twin(SEED)
    try:
        out: dict = {"align": take_hole_grasp(tw, BIN_SPOTS[0])}
        L = tw.layout
        body = tw.bodies[0]
        out["before"] = judge_in_slot(tw.world, body, L.slot_center, L.slot_width,
                                      tw.robot.body_id)
        feed = FeedSlot(L.slot_center, tw.part, tw.dev)
        out["feed"] = tw.run(feed, 30.0)
        out["feed_skill"] = feed
        tw.settle(0.5)
        out["in_slot"] = judge_in_slot(tw.world, body, L.slot_center, L.slot_width,
                                       tw.robot.body_id)
        pick = PickFromSlot(L.slot_center, tw.part, tw.dev)
        out["pick"] = tw.run(pick, 30.0)
        out["pick_skill"] = pick
        tw.settle(0.3)
        out["held"] = judge(tw.world, body, tw.cell.machine, tw.robot.body_id,
                            tw.finger_links(), tw.finger_tips(), floor_z=L.machine_top_z)
        out["after_pick"] = judge_in_slot(tw.world, body, L.slot_center, L.slot_width,
                                          tw.robot.body_id)
        return out
    finally:
        tw.close()


def test_align_takes_the_hole_grasp_and_the_judge_sees_the_part_not_in_the_slot(
    fed_and_picked: dict,
) -> None:
    assert fed_and_picked["align"] is None
    before = fed_and_picked["before"]
    assert not before.success and before.failure == "still held by the gripper"


def test_feed_slot_leaves_the_part_upright_on_the_slot_floor(fed_and_picked: dict) -> None:
    assert fed_and_picked["feed"] is None, fed_and_picked["feed"]
    v = fed_and_picked["in_slot"]
    assert v.success, v.failure
    assert v.tilt_deg < 2.0 and abs(v.bottom_m) < 0.001 and v.offset_m < 0.0025
    assert fed_and_picked["feed_skill"].on_floor  # the FT sensor felt the floor


def test_pick_from_slot_lifts_the_part_out_in_the_hole_grasp(fed_and_picked: dict) -> None:
    assert fed_and_picked["pick"] is None, fed_and_picked["pick"]
    assert fed_and_picked["pick_skill"].seen is not None  # the camera found the rim
    held = fed_and_picked["held"]
    assert held.success, held.failure
    assert held.finger_in_hole == "finger_b" and held.height_m > 0.015
    assert not fed_and_picked["after_pick"].success


def test_a_deep_grasp_is_let_go_above_the_floor_and_the_pocket_guides_the_part() -> None:
    """Align's own depth (fingertips 40 mm below the rim): the outer finger would reach the
    machine's top before the part the slot floor, so the part drops the last 15 mm."""
    tw = make_twin(SEED + 1)
    try:
        assert take_hole_grasp(tw, BIN_SPOTS[0], wall_depth=0.040) is None
        L = tw.layout
        feed = FeedSlot(L.slot_center, tw.part, tw.dev, grip_depth=0.040)
        assert tw.run(feed, 30.0) is None
        assert not feed.on_floor and feed.drop == pytest.approx(0.015)
        tw.settle(0.5)
        v = judge_in_slot(tw.world, tw.bodies[0], L.slot_center, L.slot_width,
                          tw.robot.body_id)
        assert v.success, v.failure
        assert np.isfinite(v.tilt_deg) and v.tilt_deg < 5.0
    finally:
        tw.close()
