"""Tick-level tests of FeedSlot, PickFromSlot and PackInBox against fake devices (no physics).

The fakes reach each commanded pose after a few ticks and read whatever wrench the test sets, so
these check the skills' logic: contact ends a guarded move, a force spike fails the skill with a
reason and stops the arm, halt() stops the arm, and the sensed checks say what went wrong.
"""

from __future__ import annotations

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.arm import MotionState
from drivers.devices import Devices
from drivers.layout import tray_places
from drivers.pose import Pose
from skills.packing import PackInBox
from skills.slot import FeedSlot, PickFromSlot, travel_path
from skills.status import Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run

PART = load_catalogue().get("bushing")
SLOT = np.array([0.10, 0.45, 0.06])  # the pocket floor's centre; the machine top is 40 mm up
PLACE = np.array([0.16, -0.41, 0.005])


def devices(object_width: float | None = 0.007) -> dict:
    return {
        "arm": FakeArm(),
        "gripper": FakeGripper(object_width),
        "ft": FakeFT(),
        "clock": FakeClock(),
    }


def dev(d: dict) -> Devices:
    return Devices(d["arm"], d["gripper"], d["ft"], d["clock"])


def push_back(d: dict, world_force: tuple[float, float, float]) -> None:
    """Set the fake sensor to read ``world_force`` (N, base frame) on the tool."""
    rot = d["arm"].pose.rotation
    d["ft"].value = np.concatenate([rot.T @ np.asarray(world_force, float), np.zeros(3)])


def contact_when(skill, d: dict, step: str, world_force: tuple[float, float, float]):  # type: ignore[no-untyped-def]
    """An on_tick that, during ``step``, puts the arm at its target and the contact force on."""

    def on_tick(_: int) -> None:
        arm = d["arm"]
        if skill.step == step and arm.state is MotionState.MOVING and arm.queue:
            arm.pose = arm.queue[-1]
            push_back(d, world_force)
        elif skill.step != step:
            d["ft"].value = np.zeros(6)

    return on_tick


# ---------------------------------------------------------------------------- FeedSlot
def test_feed_slot_stops_on_the_floor_lets_go_and_drags_out() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d), weight_check=0.0)
    result, _ = run(feed, d, on_tick=contact_when(feed, d, "into the slot", (0, 0, 10.0)))
    assert result.status is Status.SUCCESS, result.message
    assert feed.on_floor and feed.insert.contact
    # let go: the jaws opened by `release` (from the fake's 85 mm); then straight up
    assert d["gripper"].width() == pytest.approx(0.085 + 0.006)
    assert d["arm"].pose.position[2] > feed.insert.contact_pose.position[2] + 0.02


def _bottom(feed: FeedSlot, pose: Pose) -> float:
    """The held part's bottom (m) with the tool at ``pose``."""
    p = feed.params
    return float(pose.position[2]) - p.tip_offset + p.grip_depth - PART.length


def test_feed_slot_inserts_fast_only_away_from_the_pockets_edge_and_floor() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d), weight_check=0.0, pocket_speed=0.06, insert_speed=0.02,
                    slow_margin=0.005, depth_tolerance=0.006)
    result, _ = run(feed, d, on_tick=contact_when(feed, d, "into the slot", (0, 0, 10.0)))
    assert result.status is Status.SUCCESS, result.message
    assert feed.on_floor and feed.insert.contact
    legs = [c for c in d["arm"].commands if c[0] == "path"][3:7]  # after travel, over, down
    bottoms = [_bottom(feed, c[1][-1]) for c in legs]
    top, floor = SLOT[2] + 0.040, SLOT[2]
    # the last fast leg stops above where a floor contact would still count as on the floor
    assert bottoms[:3] == pytest.approx([top + 0.005, top - 0.005, floor + 0.011])
    assert bottoms[3] < floor  # the last aims below the floor: the contact stops it
    assert d["arm"].speeds[3:7] == [0.06, 0.02, 0.06, 0.02]


def test_feed_slot_ends_the_insertion_on_the_first_contact() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d), pocket_speed=0.06)

    def on_tick(_: int) -> None:  # the part lands on the pocket's edge in the slow leg
        if feed.step == "into the pocket" and d["arm"].state is MotionState.MOVING:
            push_back(d, (0, 0, 10.0))

    result, _ = run(feed, d, on_tick=on_tick)
    assert result.status is Status.FAILURE
    assert "in 'into the pocket'" in result.message and "not in the slot" in result.message
    assert [leg.contact for leg in feed.legs] == [False, True, False, False]
    # up, over, down, and the two legs up to the contact: the legs after it command nothing
    assert len([c for c in d["arm"].commands if c[0] == "path"]) == 5


def test_feed_slot_fails_on_a_contact_in_a_fast_leg_near_the_floor() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d), pocket_speed=0.06)
    result, _ = run(feed, d, on_tick=contact_when(feed, d, "down the pocket", (0, 0, 10.0)))
    assert result.status is Status.FAILURE
    assert "in 'down the pocket'" in result.message and not feed.on_floor


@pytest.mark.parametrize("grip_depth, margin", [(0.030, 0.005), (0.020, 0.03)])
def test_feed_slot_legs_only_go_down_and_never_below_the_goal(grip_depth, margin) -> None:  # type: ignore[no-untyped-def]
    """A deep grasp (the part let go above the floor) and a margin too large for the pocket:
    every leg ends below the one before, none below the lowest the outer finger allows."""
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d), weight_check=0.0, pocket_speed=0.06,
                    grip_depth=grip_depth, slow_margin=margin)
    run(feed, d)  # no floor felt: the fakes push back nothing (the deep grasp lets go above it)
    paths = [c for c in d["arm"].commands if c[0] == "path"]
    assert len(paths) >= 3 + len(feed.legs)
    bottoms = [_bottom(feed, c[1][-1]) for c in paths[2:3 + len(feed.legs)]]  # down, the legs
    assert all(b < a for a, b in zip(bottoms, bottoms[1:], strict=False))
    lowest = SLOT[2] + 0.040 + feed.params.finger_clearance - PART.length + grip_depth
    assert min(bottoms) >= max(SLOT[2] - feed.params.overshoot, lowest) - 1e-9


def test_feed_slot_fails_when_the_part_meets_the_machine_above_the_pocket() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d))

    def on_tick(_: int) -> None:  # resistance at once, before the part went down
        if feed.step == "into the slot" and d["arm"].state is MotionState.MOVING:
            push_back(d, (0, 0, 10.0))

    result, _ = run(feed, d, on_tick=on_tick)
    assert result.status is Status.FAILURE
    assert "above the slot floor" in result.message and "not in the slot" in result.message


def test_feed_slot_force_spike_fails_with_a_reason_and_stops_the_arm() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d))

    def spike(_: int) -> None:
        if feed.step == "down to the slot":
            d["ft"].value = np.array([0, 0, 200.0, 0, 0, 0])

    result, _ = run(feed, d, on_tick=spike)
    assert result.status is Status.FAILURE and "force-torque guard" in result.message
    assert "down to the slot" in result.message
    assert d["arm"].stops >= 1 and d["arm"].state is MotionState.STOPPED


@pytest.mark.parametrize("ticks_into_drag", [0, 2])
def test_a_feed_stopped_while_dragging_out_leaves_the_slot_from_where_it_stopped(
    ticks_into_drag: int,
) -> None:
    """A spike while the hand drags out of the part's hole fails the feed with the part in the
    pocket and the jaws open; ``leave()`` finishes the way out: the jaws at the let go's
    opening (no close), up to the height the drag would have ended at, whatever part of the
    way it had gone."""
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d), weight_check=0.0)
    landed = contact_when(feed, d, "into the slot", (0, 0, 10.0))
    seen: dict[str, object] = {}

    def on_tick(i: int) -> None:
        landed(i)
        if feed.step == "let go":
            seen.setdefault("z", float(d["arm"].pose.position[2]))
        if feed.step == "drag the gripper out":
            seen["ticks"] = int(seen.get("ticks", 0)) + 1  # type: ignore[call-overload]
            if seen["ticks"] > ticks_into_drag:
                d["ft"].value = np.array([0, 0, 200.0, 0, 0, 0])

    result, _ = run(feed, d, on_tick=on_tick)
    assert result.status is Status.FAILURE and "drag the gripper out" in result.message
    assert feed.let_go_started
    d["ft"].value = np.zeros(6)
    opened = d["gripper"].width()
    result, _ = run(feed.leave(), d)
    assert result.status is Status.SUCCESS, result.message
    assert d["gripper"].closed_on is None and d["gripper"].width() == pytest.approx(opened)
    p = feed.params
    assert d["arm"].pose.position[2] == pytest.approx(seen["z"] + p.grip_depth + p.clear_height)


def test_a_feed_stopped_before_its_let_go_has_no_leave() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d))
    feed.tick()
    feed.halt()
    assert not feed.let_go_started and not feed.finishable
    with pytest.raises(RuntimeError, match="still held"):
        feed.leave()


def test_feed_slot_halt_stops_the_arm_and_is_idempotent() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d))
    assert feed.tick().status is Status.RUNNING
    assert d["arm"].state is MotionState.MOVING
    feed.halt()
    feed.halt()
    assert d["arm"].stops >= 1 and d["arm"].state is MotionState.STOPPED


def test_feed_slot_notices_the_part_came_out_with_the_gripper() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d))
    result, _ = run(feed, d, on_tick=contact_when(feed, d, "into the slot", (0, 0, 10.0)))
    # the wrench never lost the part's weight
    assert result.status is Status.FAILURE and "came out with the gripper" in result.message


def test_feed_slot_refuses_a_grasp_too_deep_to_let_go_near_the_floor() -> None:
    d = devices()
    feed = FeedSlot(SLOT, PART, dev(d), grip_depth=0.060)
    result, _ = run(feed, d)
    assert result.status is Status.FAILURE and "too deep" in result.message


# ------------------------------------------------------------------------ PickFromSlot
def test_pick_from_slot_takes_the_hole_grasp_over_the_slot() -> None:
    d = devices()
    pick = PickFromSlot(SLOT, PART, dev(d), weight_check=0.0)
    result, _ = run(pick, d)
    assert result.status is Status.SUCCESS, result.message
    assert d["gripper"].object_detected()
    # lifted: the part's bottom (fingertips + grip depth - length) above the machine's top
    tips = d["arm"].pose.position[2] - 0.005
    assert tips + 0.020 - PART.length >= SLOT[2] + 0.040 + 0.019


def test_pick_from_slot_fails_when_the_grasp_closes_on_nothing() -> None:
    d = devices(object_width=None)
    result, _ = run(PickFromSlot(SLOT, PART, dev(d)), d)
    assert result.status is Status.FAILURE and "closed on nothing" in result.message


def test_a_pick_stopped_while_lifting_out_finishes_the_lift_with_the_part_held() -> None:
    """A spike while lifting the pinched part out of the slot fails the pick with the part in
    the hand; ``finish()`` lifts it to the height the lift would have ended at and never opens
    the jaws. Before the pinch there is nothing to finish."""
    d = devices()
    pick = PickFromSlot(SLOT, PART, dev(d), weight_check=0.0)
    assert not pick.finishable
    with pytest.raises(RuntimeError, match="nothing is held"):
        pick.finish()
    seen: dict[str, float] = {}

    def spike(_: int) -> None:
        if pick.step == "lift out of the slot" and "z" not in seen:
            seen["z"] = float(d["arm"].pose.position[2])
            d["ft"].value = np.array([0, 0, 200.0, 0, 0, 0])

    result, _ = run(pick, d, on_tick=spike)
    assert result.status is Status.FAILURE and "lift out of the slot" in result.message
    assert pick.finishable and d["gripper"].object_detected()
    d["ft"].value = np.zeros(6)
    opens = d["gripper"]._target
    result, _ = run(pick.finish(), d)
    assert result.status is Status.SUCCESS, result.message
    assert d["gripper"].object_detected() and d["gripper"]._target == opens  # never opened
    rise = (SLOT[2] + 0.040 + pick.params.clear_height) - SLOT[2]
    assert d["arm"].pose.position[2] == pytest.approx(seen["z"] + rise)


def test_pick_from_slot_force_spike_and_halt_stop_the_arm() -> None:
    d = devices()
    pick = PickFromSlot(SLOT, PART, dev(d))

    def spike(_: int) -> None:
        if pick.step == "beside the wall":
            d["ft"].value = np.array([0, 0, -40.0, 0, 0, 0])  # a pad landed on the rim

    result, _ = run(pick, d, on_tick=spike)
    assert result.status is Status.FAILURE and "force-torque guard" in result.message
    assert d["arm"].stops >= 1
    d2 = devices()
    pick2 = PickFromSlot(SLOT, PART, dev(d2))
    pick2.tick()
    pick2.halt()
    pick2.halt()
    assert d2["arm"].state is MotionState.STOPPED


# --------------------------------------------------------------------------- PackInBox
#: What each push meets: the floor, then a wall or neighbour on +x and on +y (N, base frame).
PACK_CONTACTS = {"push -z onto the floor": (0, 0, 10.0), "push +x": (-10.0, 0, 0),
                 "push +y": (0, -10.0, 0)}


def run_pack(pack: PackInBox, d: dict, watch=None):  # type: ignore[no-untyped-def]
    """Run ``pack`` with each push blocked by its contact; ``watch(step)`` sees every tick."""

    def on_tick(_: int) -> None:
        arm = d["arm"]
        arm.blocked = pack.step in PACK_CONTACTS
        if pack.step in PACK_CONTACTS and arm.state is MotionState.MOVING and arm.force is not None:
            push_back(d, PACK_CONTACTS[pack.step])
        elif pack.step not in PACK_CONTACTS:
            d["ft"].value = np.zeros(6)
        if watch is not None:
            watch(pack.step)

    return run(pack, d, on_tick=on_tick)


def test_pack_in_box_pushes_down_then_x_then_y_and_lets_go() -> None:
    d = devices()
    pack = PackInBox(PLACE, PART, dev(d), weight_check=0.0)
    result, _ = run_pack(pack, d)
    assert result.status is Status.SUCCESS, result.message
    assert set(pack.contacts) == {"floor", "+x", "+y"}
    # every push ran in force mode, pressing contact_force along its axis only
    # (and the open hand's way up in force mode, giving way in the plane)
    pushes = [c for c in d["arm"].commands if c[0] == "force"]
    assert len(pushes) == 5
    f = pack.params.contact_force
    assert pushes[0][1][2] == pytest.approx(-f) and pushes[1][1][0] == pytest.approx(f)
    assert pushes[2][1][1] == pytest.approx(f)
    assert pushes[4][1][2] > 0.0  # up (measured from the empty hand: the next test)
    # the outer finger (tool x) trails on the -x, -y diagonal
    x = pack.contacts["+x"].rotation[:, 0]
    assert np.allclose(x, [-np.sqrt(0.5), -np.sqrt(0.5), 0.0])
    assert pack.placed_xy is not None
    assert d["arm"].pose.position[2] > pack.contacts["+y"].position[2] + 0.03


@pytest.mark.parametrize("follow", [None, 0.35])
def test_pack_in_box_lets_go_with_the_inner_finger_easing_off_the_wall(
    follow: float | None,
) -> None:
    """The jaws open symmetrically; the arm follows the outer finger (tool +x) out by
    ``release_follow`` of the opening the gripper reports (0 by default: it stands still),
    under half, so the finger in the hole moves off the wall it pressed, towards the hole's
    centre, and never into it. Run at the default and at a follow that moves the arm."""
    d = devices()
    given = {} if follow is None else {"release_follow": follow}
    pack = PackInBox(PLACE, PART, dev(d), weight_check=0.0, **given)
    assert follow is not None or pack.params.release_follow == 0.0
    seen: dict[str, object] = {}
    follow_errors: list[float] = []

    def watch(step: str) -> None:
        if step == "relax the push" and "before" not in seen:
            seen["before"] = d["arm"].pose
            seen["commands"] = len(d["arm"].commands)
        if step == "let go":
            seen.setdefault("width", d["gripper"].width())
            # while the jaws move the arm is never ahead of follow x the reported opening
            opened = d["gripper"].width() - seen["width"]
            moved = float((d["arm"].pose.position - seen["before"].position) @ x_of(seen))
            follow_errors.append(moved - pack.params.release_follow * opened)
        if step == "off the wall" and "after" not in seen:
            seen["after"] = d["arm"].pose

    def x_of(s: dict[str, object]) -> np.ndarray:
        return s["before"].rotation[:, 0]  # type: ignore[union-attr]

    result, _ = run_pack(pack, d, watch)
    assert result.status is Status.SUCCESS, result.message
    before, after = seen["before"], seen["after"]
    x = before.rotation[:, 0]  # the outer finger's side
    follow = pack.params.release_follow
    assert 0.0 <= follow < 0.5
    assert after.position == pytest.approx(
        before.position + follow * pack.params.release * x, abs=1e-9
    )
    assert max(follow_errors) <= 1e-9  # never ahead of the jaws
    # the inner finger (at -x, moving -x by half the opening) ends off the wall by this much
    assert float((0.5 - follow) * pack.params.release) > 0.0005
    # after the relax (a move to where the TCP is): off the wall, then the withdrawal in
    # force mode (up, giving way in the plane)
    later = d["arm"].commands[seen["commands"] - 1 :]
    paths = [c for c in later if c[0] == "path"]
    relax, off, up = paths
    assert relax[1][-1].position == pytest.approx(before.position)
    back = off[1][-1].position - after.position
    assert back == pytest.approx(-pack.params.release_clearance * x, abs=1e-9)
    # up in force mode until the fingertips clear the rim, then the rest by a position move
    forces = [i for i, c in enumerate(later) if c[0] == "force"]
    assert forces and later[forces[-1]][1][2] > 0.0
    assert next(i for i, c in enumerate(later) if c is up) > forces[-1]
    p = pack.params
    rise = up[1][-1].position - off[1][-1].position
    assert rise[:2] == pytest.approx(0.0, abs=1e-6) and rise[2] > 0.0
    # the fingertips end clear_height above the part's rim
    tips = up[1][-1].position[2] - p.tip_offset
    assert tips == pytest.approx(PLACE[2] + PART.length + p.clear_height, abs=1e-9)


def test_pack_in_box_fails_when_nothing_stops_the_push() -> None:
    d = devices()
    pack = PackInBox(PLACE, PART, dev(d), weight_check=0.0)

    def on_tick(_: int) -> None:
        d["arm"].blocked = pack.step == "push -z onto the floor"
        if pack.step == "push -z onto the floor" and d["arm"].state is MotionState.MOVING:
            push_back(d, (0, 0, 10.0))
        elif pack.step != "push -z onto the floor":
            d["ft"].value = np.zeros(6)

    result, _ = run(pack, d, on_tick=on_tick)
    assert result.status is Status.FAILURE and "no wall or part on +x felt" in result.message


def test_pack_in_box_force_spike_fails_with_a_reason_and_halt_stops_the_arm() -> None:
    d = devices()
    pack = PackInBox(PLACE, PART, dev(d))

    def spike(_: int) -> None:
        if pack.step == "over the place":
            d["ft"].value = np.array([150.0, 0, 0, 0, 0, 0])

    result, _ = run(pack, d, on_tick=spike)
    assert result.status is Status.FAILURE and "force-torque guard" in result.message
    assert d["arm"].stops >= 1
    d2 = devices()
    pack2 = PackInBox(PLACE, PART, dev(d2))
    pack2.tick()
    pack2.halt()
    pack2.halt()
    assert d2["arm"].stops >= 1 and d2["arm"].state is MotionState.STOPPED


def test_tray_places_fill_from_the_plus_x_plus_y_corner() -> None:
    places = tray_places((0.0225, 0.1775, -0.51, -0.39), 0.005, 0.034)
    assert len(places) == 12
    assert places[0, 0] == pytest.approx(0.1775 - 0.01775)
    assert places[0, 1] == pytest.approx(-0.39 - 0.01775)
    assert places[1, 0] < places[0, 0] and places[1, 1] == places[0, 1]  # along -x first
    assert places[4, 1] < places[0, 1]  # then the next row, towards -y
    assert np.allclose(places[:, 2], 0.005)


def test_travel_path_goes_around_the_base() -> None:
    from drivers.pose import Pose

    start = Pose(np.array([0.1, 0.45, 0.2]), np.diag([1.0, -1.0, -1.0]))
    end = Pose(np.array([0.1, -0.45, 0.2]), np.diag([1.0, -1.0, -1.0]))
    path = travel_path(start, end, 0.30)
    pts = np.array([p.position for p in [start, *path]])
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        s = np.linspace(0, 1, 50)[:, None]
        seg = a[:2] + s * (b[:2] - a[:2])
        assert np.min(np.linalg.norm(seg, axis=1)) > 0.25


# ---------------------------------------------------------------------------- the weight checks
def test_the_weight_check_reads_the_mean_over_its_hold_not_one_swinging_sample() -> None:
    """A held part rocking on a pad's corner swings the wrist's reading: the reference and the
    check are means over their holds, so the one low sample at the end does not call a held
    part left behind, while a part really lost is still seen as lost."""
    from skills.motion import Guard
    from skills.slot import WrenchReference

    d = devices()
    ref = WrenchReference(dev(d))
    weight = 1.5

    def hold_reading(readings: list[float]) -> None:
        hold = ref.hold("hold", Guard(), 0.1)
        hold.start()
        for i in range(100):
            push_back(d, (0.0, 0.0, readings[i % len(readings)]))
            d["clock"].t += d["clock"].dt
            if hold.tick().status is not Status.RUNNING:
                return
        raise AssertionError("the hold never ended")

    hold_reading([0.0, 0.2, -0.2])  # the empty gripper
    ref.read()
    assert ref.force is not None and abs(ref.force[2]) < 0.1
    # held: -1.5 N on average, the last sample swung to -0.5 N
    hold_reading([-1.5, -1.4, -1.6, -1.5, -1.5, -1.5, -1.6, -1.4, -1.5, -1.5, -1.5, -1.5, -0.5])
    push_back(d, (0.0, 0.0, -0.5))
    assert ref.gained() > 0.5 * weight
    hold_reading([-0.1, 0.1])  # lost: nothing hangs from the fingers
    assert ref.gained() < 0.5 * weight


def test_the_weight_checks_mean_leaves_out_the_first_half_of_its_hold() -> None:
    """The hold begins as the motion before it stops (a force mode's stop, an arm trailing its
    stream): that transient is not averaged into the reading."""
    from skills.motion import Guard
    from skills.slot import WrenchReference

    d = devices()
    ref = WrenchReference(dev(d))
    ref.read()  # the empty gripper: 0 N
    hold = ref.hold("settle", Guard(), 0.2)
    hold.start()
    while True:
        t = d["clock"].t
        push_back(d, (0.0, 0.0, -4.0 if t < 0.09 else -1.5))  # braking, then the part's weight
        d["clock"].t += d["clock"].dt
        if hold.tick().status is not Status.RUNNING:
            break
    assert ref.gained() == pytest.approx(1.5)


def test_packing_withdraws_measured_from_the_empty_hand_read_before_the_let_go() -> None:
    """The way up gives way in the plane to what the hanging reading (less the part's weight)
    does not explain: a finger pressing the hole's wall as it begins is let go of, not held."""
    from skills.slot import GRAVITY

    d = devices()
    pack = PackInBox(PLACE, PART, dev(d), weight_check=0.0)
    hanging = (0.3, -0.2, -PART.mass * GRAVITY - 0.4)  # the part, the sensor's offset

    def watch(step: str) -> None:
        if step in ("hold still", "read the hanging part"):
            push_back(d, hanging)
        elif step == "withdraw up":
            push_back(d, (4.0, 3.0, -0.4))  # a pad corner pressed into the wall
            if d["arm"].force is not None:
                commanded.append(d["arm"].force)

    commanded: list = []
    result, _ = run_pack(pack, d, watch)
    assert result.status is Status.SUCCESS, result.message
    selection, wrench, limits = commanded[0]
    assert selection.tolist()[:3] == [True, True, True]
    assert wrench[0] == pytest.approx(-0.3) and wrench[1] == pytest.approx(0.2)
    assert wrench[2] == pytest.approx(0.4 + pack.params.contact_force)
    assert limits[0] == limits[1] == pytest.approx(pack.params.release_speed)
    assert limits[2] == pytest.approx(pack.params.approach_speed)


def test_a_part_that_came_up_with_the_open_hand_is_gripped_again_and_the_packing_fails() -> None:
    """The weight check after the withdrawal still reads the part: it hangs on the finger in
    its hole. The jaws close on it again (so the retry can pack it once more, and no part
    dangles from one finger) and the step fails with the check's code."""
    from skills.slot import GRAVITY
    from skills.status import Failure

    d = devices()
    pack = PackInBox(PLACE, PART, dev(d))
    hanging = (0.0, 0.0, -PART.mass * GRAVITY)

    def watch(step: str) -> None:
        if step in ("hold still", "read the hanging part", "settle", "part left in the box"):
            push_back(d, hanging)  # before and, wrongly, after the let go

    result, _ = run_pack(pack, d, watch)
    assert result.status is Status.FAILURE and result.code is Failure.CHECK_FAILED
    assert "came up with the gripper" in result.message and "gripped again" in result.message
    assert d["gripper"].closed_on is not None  # the jaws closed on the part again
    assert d["gripper"].width() == pytest.approx(d["gripper"].object_width)
    # the check's verdict, not an interruption: no way out is offered (opening would drop it)
    assert pack.let_go_started and pack.step == PackInBox.CHECK_STEP and not pack.finishable
    with pytest.raises(RuntimeError):
        pack.leave()


def test_a_part_left_in_the_box_is_not_gripped_again() -> None:
    from skills.slot import GRAVITY

    d = devices()
    pack = PackInBox(PLACE, PART, dev(d))
    hanging = (0.0, 0.0, -PART.mass * GRAVITY)

    def watch(step: str) -> None:
        if step in ("hold still", "read the hanging part"):
            push_back(d, hanging)

    result, _ = run_pack(pack, d, watch)
    assert result.status is Status.SUCCESS, result.message
    assert d["gripper"].width() > d["gripper"].object_width + 0.004  # left open


def test_the_way_up_gives_way_until_the_fingertips_measured_in_the_hole_are_out() -> None:
    """The force mode's way up lasts as deep as the tips were found to reach below the rim when
    the part stood on the floor (a grasp that slipped deeper), not the nominal depth only."""
    d = devices()
    pack = PackInBox(PLACE, PART, dev(d), weight_check=0.0)
    p = pack.params
    assert pack._tip_depth() == pytest.approx(p.grip_depth)  # nothing measured yet
    deeper = 0.006
    tcp_z = PLACE[2] + PART.length - p.grip_depth - deeper + p.tip_offset
    pack.contacts["floor"] = Pose(np.array([0.16, -0.41, tcp_z]), np.eye(3))
    assert pack._tip_depth() == pytest.approx(p.grip_depth + deeper)
    pack.contacts["floor"] = Pose(np.array([0.16, -0.41, tcp_z + 2 * deeper]), np.eye(3))
    assert pack._tip_depth() == pytest.approx(p.grip_depth)  # never less than the nominal


def test_a_part_that_came_up_but_the_jaws_close_on_nothing_says_so() -> None:
    from skills.slot import GRAVITY
    from skills.status import Failure

    d = devices(object_width=None)  # the part fell off the finger meanwhile
    pack = PackInBox(PLACE, PART, dev(d))
    hanging = (0.0, 0.0, -PART.mass * GRAVITY)

    def watch(step: str) -> None:
        if step in ("hold still", "read the hanging part", "settle", "part left in the box"):
            push_back(d, hanging)

    result, _ = run_pack(pack, d, watch)
    assert result.status is Status.FAILURE and result.code is Failure.CHECK_FAILED
    assert "closed empty" in result.message


@pytest.mark.parametrize("stop_in", ["off the wall", "withdraw up", "up clear"])
def test_a_packing_stopped_past_its_let_go_leaves_the_box_from_where_it_stopped(
    stop_in: str,
) -> None:
    """A spike on the way up fails the packing with the part already standing in its place and
    the hand open. ``leave()`` finishes the way out from where the arm stopped: the jaws open
    the whole way (no close), the open hand off the wall only if that move had not run, up
    giving way in force mode, then clear of the rim; the weight check passes (the hand is
    empty)."""
    from skills.slot import GRAVITY

    d = devices()
    pack = PackInBox(PLACE, PART, dev(d))
    hanging = (0.0, 0.0, -PART.mass * GRAVITY)
    spiked: list[str] = []

    def watch(step: str) -> None:
        if step in ("hold still", "read the hanging part"):
            push_back(d, hanging)
        if step == stop_in and not spiked:
            spiked.append(step)
            d["ft"].value = np.array([0.0, 0.0, 197.0, 0.0, 0.0, 0.0])  # one sample

    result, _ = run_pack(pack, d, watch)
    assert result.status is Status.FAILURE and "force-torque guard" in result.message
    assert pack.let_go_started
    open_width = d["gripper"].width()
    stopped_at = d["arm"].pose.position.copy()
    d["ft"].value = np.zeros(6)
    before = len(d["arm"].commands)
    leave = pack.leave()
    names = [s.name for s in leave.sequence.steps]
    assert ("off the wall" in names) == (stop_in == "off the wall")
    assert names[-1] == "part left in the box"
    result, _ = run(leave, d)
    assert result.status is Status.SUCCESS, result.message
    assert d["gripper"].closed_on is None and d["gripper"].width() >= open_width - 1e-9
    later = d["arm"].commands[before:]
    assert any(c[0] == "force" and c[1][2] > 0.0 for c in later)  # up, giving way
    tips = d["arm"].pose.position[2] - pack.params.tip_offset
    assert tips >= PLACE[2] + PART.length + pack.params.clear_height - 1e-9
    assert d["arm"].pose.position[:2] == pytest.approx(stopped_at[:2], abs=0.005)


def test_leave_before_the_let_go_is_refused_the_part_is_still_held() -> None:
    d = devices()
    pack = PackInBox(PLACE, PART, dev(d))

    def spike(_: int) -> None:
        if pack.step == "push +x":
            d["ft"].value = np.array([150.0, 0, 0, 0, 0, 0])

    result, _ = run_pack(pack, d, lambda step: spike(0))
    assert result.status is Status.FAILURE and not pack.let_go_started
    assert not pack.finishable
    with pytest.raises(RuntimeError, match="still held"):
        pack.leave()


def test_leaving_again_goes_off_the_wall_to_the_same_place_not_further() -> None:
    """A stop in "off the wall", then a stop in the first leave's way up: each leave moves the
    hand off the wall to the one place fixed from where the let go left it, at the height it
    stands -- never a further release_clearance each time, never back down."""
    d = devices()
    pack = PackInBox(PLACE, PART, dev(d), weight_check=0.0)
    stops = {"n": 0}

    def watch(step: str) -> None:
        if step == "let go":
            stops["let_go_xy"] = d["arm"].pose.position[:2].copy()
        if step == "off the wall" and stops["n"] == 0:
            stops["n"] = 1
            d["ft"].value = np.array([0.0, 0.0, 197.0, 0.0, 0.0, 0.0])

    result, _ = run_pack(pack, d, watch)
    assert result.status is Status.FAILURE and pack.finishable
    d["ft"].value = np.zeros(6)
    first = pack.leave()
    assert "off the wall" in [m.name for m in first.sequence.steps]

    def spike_up(_: int) -> None:
        if first.step == "withdraw up":
            d["ft"].value = np.array([0.0, 0.0, 197.0, 0.0, 0.0, 0.0])

    result, _ = run(first, d, on_tick=spike_up)
    assert result.status is Status.FAILURE
    d["ft"].value = np.zeros(6)
    z_before = d["arm"].pose.position[2]
    second = pack.leave()
    assert "off the wall" not in [m.name for m in second.sequence.steps]  # it ran once
    result, _ = run(second, d)
    assert result.status is Status.SUCCESS, result.message
    off = stops["let_go_xy"] - pack.params.release_clearance * pack._x[:2]
    assert d["arm"].pose.position[:2] == pytest.approx(off, abs=1e-9)
    assert d["arm"].pose.position[2] >= z_before
