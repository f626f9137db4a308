"""Tick-level tests of the skill leaves of trees/behaviours.py on fake devices: Perceive, Tilt and
Align (what they publish), PutBack, and the slot and box leaves (FeedSlot, PickFromSlot,
PackInBox). For each: the success path and what it leaves behind (blackboard, slot state, box
places, events), a failure that stops the arm and reports an abort, and a halt by a parent
mid-motion that stops the arm.

The fakes are given a little world (:class:`World`): the held part's weight on the wrist and a
push back when a guarded move reaches something, so the skills' own checks pass for the right
reason. Checks are on statuses, arm stops, events and numbers, not on message wording.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import py_trees
import pytest
from py_trees.common import Access, Status

from drivers.arm import MotionState
from drivers.camera import Frame, Intrinsics
from drivers.events import EventKind
from drivers.pose import Pose
from skills.perception.bin_parts import Detection
from skills.pivot import PivotFrame
from skills.status import Failure
from tests.trees.helpers import fresh_ctx, make_ctx
from trees import behaviours as lv

GRAVITY = 9.81


@pytest.fixture
def ctx():
    return fresh_ctx()


def blackboard(name: str = "test") -> py_trees.blackboard.Client:
    client = py_trees.blackboard.Client(name=name)
    for key in ("/part/target", "/part/pivot_frame", "/part/detections", "/part/seen",
                "/cell/place", "/cell/bin_empty"):
        client.register_key(key, access=Access.WRITE)
    return client


def holding(ctx) -> None:  # type: ignore[no-untyped-def]
    """The hand holds the part (as after Align or PickFromSlot)."""
    g = ctx.devices.gripper
    g._width, g.closed_on, g._moving = g.object_width, g.object_width, False


class World:
    """Rules, not physics: the held part hangs from the wrist, and during a guarded move named
    in ``contacts`` the arm reaches its target and feels that push (N, base frame)."""

    def __init__(self, ctx, node, contacts=None, weight: bool = True, held=None) -> None:  # type: ignore[no-untyped-def]
        self.ctx, self.node = ctx, node
        self.contacts = contacts or {}
        self.weight = weight
        #: whether the part hangs from the hand (default: the gripper holds something)
        self.held = held or ctx.devices.gripper.object_detected
        self.extra = np.zeros(6)  #: a wrench added on top (tool frame), for spikes

    def step_name(self) -> str | None:
        skill = self.node.skill
        return getattr(skill, "step", None) if skill is not None else None

    def __call__(self) -> None:
        dev = self.ctx.devices
        arm = dev.arm
        force = np.zeros(3)
        if self.weight and self.held():
            force[2] -= self.ctx.part.mass * GRAVITY
        name = self.step_name()
        arm.blocked = name in self.contacts  # a force-mode push stands on its contact
        if name in self.contacts and arm.state is MotionState.MOVING and arm.queue:
            arm.pose = arm.queue[-1]
            force += np.asarray(self.contacts[name], float)
        elif name in self.contacts and arm.state is MotionState.MOVING and arm.force is not None:
            force += np.asarray(self.contacts[name], float)
        dev.ft.value = np.concatenate([arm.pose.rotation.T @ force, np.zeros(3)]) + self.extra


def run(node, ctx, world=None, ticks: int = 5000, on_tick=None) -> list[Status]:  # type: ignore[no-untyped-def]
    """Tick ``node`` until it ends; the world and the fakes advance between ticks."""
    dev = ctx.devices
    statuses: list[Status] = []
    for i in range(ticks):
        if world is not None:
            world()
        if on_tick is not None:
            on_tick(i)
        node.tick_once()
        statuses.append(node.status)
        if node.status != Status.RUNNING:
            return statuses
        dev.arm.tick()
        dev.gripper.tick()
        dev.clock.t += dev.clock.dt
    raise AssertionError(f"{node.name} did not finish: {node.feedback_message}")


def start_then_halt(node, ctx, ticks: int = 3) -> int:  # type: ignore[no-untyped-def]
    """Start ``node`` on a long first move, halt it as a parent would; the arm's stops before."""
    ctx.devices.arm.ticks_per_move = 10**6
    for _ in range(ticks):
        node.tick_once()
        assert node.status == Status.RUNNING
        ctx.devices.clock.t += ctx.devices.clock.dt
    assert ctx.devices.arm.state is MotionState.MOVING
    stops = ctx.devices.arm.stops
    node.stop(Status.INVALID)
    return stops


def spike_on(world: World, step: str, force: float = 400.0):  # type: ignore[no-untyped-def]
    """An on_tick that puts a large force on the wrist once ``step`` is under way."""

    def on_tick(_: int) -> None:
        if world.step_name() == step:
            world.extra = np.array([force, 0.0, 0.0, 0.0, 0.0, 0.0])

    return on_tick


def detection(x: float, y: float, part: str = "bushing") -> Detection:
    return Detection(
        center=np.array([x, y, 0.017]), yaw=0.0, length=0.068, outer=0.034, part=part,
        open_end=np.array([x + 0.034, y, 0.017]), open_end_seen=True, confidence=0.9,
        pixels=500,
    )


# --------------------------------------------------------------------------------- Perceive
class FakeCamera:
    def __init__(self) -> None:
        self.captures = 0
        self.broken = False

    def intrinsics(self) -> Intrinsics:
        return Intrinsics(64, 48, 50.0, 50.0, 32.0, 24.0)

    def tool_T_camera(self) -> Pose:
        return Pose(np.array([0.0, 0.05, 0.02]))

    def capture(self) -> Frame:
        if self.broken:
            raise TimeoutError("no frame within 1 s")
        self.captures += 1
        return Frame(np.zeros((48, 64, 3), np.uint8), np.zeros((48, 64), np.float32), 0.0)


@pytest.fixture
def seeing(ctx, monkeypatch):  # type: ignore[no-untyped-def]
    """The context with a wrist camera whose detector reports ``found`` (a list to fill)."""
    camera = FakeCamera()
    ctx.devices = dataclasses.replace(ctx.devices, camera=camera)
    found: list[Detection] = []
    monkeypatch.setattr(
        "skills.perception.look.detect_parts", lambda *a, **k: list(found)
    )
    return camera, found


def test_perceive_looks_twice_and_publishes_the_parts_and_the_one_nearest_the_robot(
    ctx, seeing
) -> None:
    camera, found = seeing
    near, far = detection(0.30, 0.02), detection(0.62, 0.10)
    found.extend([far, near])
    node = lv.Perceive("perceive", ctx)
    statuses = run(node, ctx)
    assert statuses[0] == Status.RUNNING and statuses[-1] == Status.SUCCESS
    assert camera.captures == 3  # the wide view, the closer look, the close view over it
    assert [c[0] for c in ctx.devices.arm.commands] == ["path", "path", "path"]
    bb = blackboard()
    assert len(bb.get("/part/detections")) == 2
    seen = bb.get("/part/seen")
    assert np.allclose(seen.center, near.center) and seen.open_end_seen
    assert not ctx.events.aborts


def test_the_close_view_refines_the_chosen_part_s_pose_and_keeps_its_open_end(
    ctx, seeing, monkeypatch
) -> None:
    """The last view, over the chosen part, moves its centre and axis to what it saw there; the
    open end the earlier views decided stays (an axis seen the other way round is turned)."""
    camera, found = seeing
    near = detection(0.30, 0.02)
    found.append(near)
    close = dataclasses.replace(
        near, center=np.array([0.302, 0.023, 0.017]), yaw=math.pi + 0.01, open_end_seen=False,
        open_end=np.array([0.268, 0.023, 0.017]),
    )
    far_away = detection(0.45, 0.02)  # another part in the close view: not the chosen one
    monkeypatch.setattr(
        "skills.perception.look.detect_parts",
        lambda *a, **k: [far_away, close] if camera.captures >= 3 else [near],
    )
    node = lv.Perceive("perceive", ctx)
    statuses = run(node, ctx)
    assert statuses[-1] == Status.SUCCESS
    seen = blackboard().get("/part/seen")
    assert np.allclose(seen.center, [0.302, 0.023, 0.017])
    assert seen.yaw == pytest.approx(0.01) and seen.open_end_seen
    assert np.allclose(seen.open_end[:2], [0.302 + 0.034 * math.cos(0.01),
                                           0.023 + 0.034 * math.sin(0.01)])


def test_perceive_on_an_empty_bin_succeeds_with_nothing_and_the_plan_then_ends_the_cycles(
    ctx, seeing
) -> None:
    node = lv.Perceive("perceive", ctx)
    assert run(node, ctx)[-1] == Status.SUCCESS  # an empty bin is an answer, not a fault
    bb = blackboard()
    assert bb.get("/part/detections") == [] and bb.get("/part/seen") is None
    assert not ctx.events.aborts
    plan = lv.PlanPick("plan", ctx)
    plan.tick_once()
    assert plan.status == Status.FAILURE and bb.get("/cell/bin_empty") is True


def test_perceive_without_a_frame_fails_stops_the_arm_and_reports_an_abort(ctx, seeing) -> None:
    camera, found = seeing
    found.append(detection(0.30, 0.0))
    camera.broken = True
    node = lv.Perceive("perceive", ctx)
    assert run(node, ctx)[-1] == Status.FAILURE
    assert ctx.devices.arm.stops >= 1 and len(ctx.events.aborts) == 1
    assert not blackboard().exists("/part/detections")


def test_perceive_force_spike_on_the_way_fails_with_an_abort(ctx, seeing) -> None:
    _, found = seeing
    found.append(detection(0.30, 0.0))
    node = lv.Perceive("perceive", ctx)
    world = World(ctx, node, weight=False)
    world.extra = np.array([0.0, 0.0, 500.0, 0, 0, 0])
    assert run(node, ctx, world)[-1] == Status.FAILURE
    assert ctx.devices.arm.stops == 1 and len(ctx.events.aborts) == 1


def test_perceive_halted_mid_motion_stops_the_arm(ctx, seeing) -> None:
    node = lv.Perceive("perceive", ctx)
    stops = start_then_halt(node, ctx)
    assert ctx.devices.arm.stops == stops + 1 and node.status == Status.INVALID
    assert not ctx.events.aborts


# --------------------------------------------------------------------------- Tilt, Align
def target(ctx, x: float = 0.45, y: float = 0.02):  # type: ignore[no-untyped-def]
    """What PlanPick publishes for a bushing lying at (x, y) along +x."""
    section = ctx.part.section(ctx.devices.gripper.finger_width)
    frame = PivotFrame(section, np.array([x, y, 0.5 * ctx.part.outer]), 0.0, floor_z=0.0)
    return {"detection": detection(x, y), "frame": frame}


def test_tilt_publishes_the_pivot_frame_it_located_for_the_align(ctx) -> None:
    bb = blackboard()
    tgt = target(ctx)
    bb.set("/part/target", tgt)
    p = ctx.params
    ctx.devices.arm.pose = tgt["frame"].grasp_pose(p.l_a, p.alpha, p.tip_offset)
    ctx.devices.gripper._width = tgt["frame"].opening(p.l_a, p.alpha) - 0.004  # closed on H
    node = lv.Tilt("tilt", ctx)
    assert run(node, ctx)[-1] == Status.SUCCESS
    frame = bb.get("/part/pivot_frame")
    assert frame is node.tilt.frame
    # located from the closed grasp: moved along the part's axis from where it was planned
    assert not np.allclose(frame.center, tgt["frame"].center)
    assert np.allclose(frame.center[1:], tgt["frame"].center[1:])
    assert not ctx.events.aborts


def test_tilt_without_a_chosen_part_cannot_start_and_moves_nothing(ctx) -> None:
    node = lv.Tilt("tilt", ctx)
    node.tick_once()
    assert node.status == Status.FAILURE
    assert not ctx.devices.arm.commands and not blackboard().exists("/part/pivot_frame")


def test_tilt_halted_mid_arc_stops_the_arm_and_publishes_nothing(ctx) -> None:
    bb = blackboard()
    tgt = target(ctx)
    bb.set("/part/target", tgt)
    p = ctx.params
    ctx.devices.arm.pose = tgt["frame"].grasp_pose(p.l_a, p.alpha, p.tip_offset)
    node = lv.Tilt("tilt", ctx)
    for _ in range(50):
        node.tick_once()
        ctx.devices.clock.t += ctx.devices.clock.dt
    assert node.status == Status.RUNNING
    stops = ctx.devices.arm.stops
    node.stop(Status.INVALID)
    assert ctx.devices.arm.stops == stops + 1
    assert not bb.exists("/part/pivot_frame")


def standing(ctx):  # type: ignore[no-untyped-def]
    """The blackboard and the tool as a Tilt to 90 deg leaves them."""
    bb = blackboard()
    tgt = target(ctx)
    bb.set("/part/target", tgt)
    bb.set("/part/pivot_frame", tgt["frame"])
    p = ctx.params
    grasp = tgt["frame"].grasp_pose(p.l_a, p.alpha, p.tip_offset)
    ctx.devices.arm.pose = tgt["frame"].tilt_pose(grasp, 0.5 * np.pi)
    ctx.devices.gripper._width = tgt["frame"].opening(p.l_a, p.alpha)
    return bb, tgt


def test_align_success_reports_the_pick_with_where_the_part_lay(ctx) -> None:
    _, tgt = standing(ctx)
    node = lv.Align("align", ctx)
    assert run(node, ctx)[-1] == Status.SUCCESS
    picked = [d for k, d in ctx.events.events if k == "picked"]
    assert len(picked) == 1
    assert picked[0]["x"] == pytest.approx(0.45) and picked[0]["y"] == pytest.approx(0.02)
    assert "recovered" not in picked[0]
    assert ctx.devices.gripper.object_detected()


def test_align_on_nothing_fails_with_an_abort_and_no_pick(ctx) -> None:
    standing(ctx)
    ctx.devices.gripper.object_width = None  # the part is gone from between the fingers
    node = lv.Align("align", ctx)
    assert run(node, ctx)[-1] == Status.FAILURE
    assert "picked" not in ctx.events.kinds() and len(ctx.events.aborts) == 1


def test_align_without_a_pivot_frame_cannot_start(ctx) -> None:
    node = lv.Align("align", ctx)
    node.tick_once()
    assert node.status == Status.FAILURE and not ctx.devices.arm.commands
    assert "picked" not in ctx.events.kinds()


def test_align_halted_mid_turn_stops_the_arm(ctx) -> None:
    standing(ctx)
    node = lv.Align("align", ctx)
    for _ in range(20):
        node.tick_once()
        ctx.devices.clock.t += ctx.devices.clock.dt
    assert node.status == Status.RUNNING
    stops = ctx.devices.arm.stops
    node.stop(Status.INVALID)
    assert ctx.devices.arm.stops == stops + 1 and "picked" not in ctx.events.kinds()


# ---------------------------------------------------------------------------------- PutBack
def test_put_back_opens_rises_goes_home_remembers_the_part_and_then_fails(ctx) -> None:
    bb = blackboard()
    bb.set("/part/target", target(ctx, 0.45, 0.02))
    holding(ctx)
    start_z = ctx.devices.arm.pose.position[2]
    node = lv.PutBack("put back", ctx)
    statuses = run(node, ctx)
    # it did all its moves and then fails on purpose, so the retry above looks again
    assert statuses[-1] == Status.FAILURE and len(statuses) > 3
    assert not ctx.events.aborts  # a put back that worked is not an abort
    assert ctx.devices.gripper.width() == pytest.approx(ctx.devices.gripper.stroke)  # open
    kinds = [c[0] for c in ctx.devices.arm.commands]
    assert kinds == ["path", "joints"]
    risen = ctx.devices.arm.commands[0][1][-1]
    assert risen.position[2] > start_z + 0.05  # straight up before going home
    assert np.allclose(ctx.devices.arm.commands[1][1], ctx.geometry.home_joints)
    assert ctx.failures == {(45, 2): 1}  # the part's place in 1 cm cells
    run(lv.PutBack("put back #2", ctx), ctx)
    assert ctx.failures == {(45, 2): 2}  # counted per failed pick
    bb.set("/part/target", target(ctx, 0.52, -0.07))
    run(lv.PutBack("put back #3", ctx), ctx)
    assert ctx.failures == {(45, 2): 2, (52, -7): 1}  # and per part


def test_put_back_without_a_chosen_part_remembers_nothing(ctx) -> None:
    run(lv.PutBack("put back", ctx), ctx)
    assert ctx.failures == {} and len(ctx.devices.arm.commands) == 2


def test_put_back_after_an_empty_bin_goes_home_without_the_rise(ctx) -> None:
    """Nothing was taken: the arm is where the look left it, high over the bin, where a rise is
    out of the UR5's reach (the twin's arm faulted there)."""
    bb = blackboard()
    bb.set("/part/target", target(ctx, 0.45, 0.02))
    bb.set("/cell/bin_empty", True)
    try:
        statuses = run(lv.PutBack("put back", ctx), ctx)
    finally:
        bb.set("/cell/bin_empty", False)
    assert statuses[-1] == Status.FAILURE and not ctx.events.aborts
    assert [c[0] for c in ctx.devices.arm.commands] == ["joints"]  # home, no rise
    assert ctx.failures == {}  # no pick failed


def test_put_back_opens_under_the_load_of_a_pinched_part_within_its_node_limit(ctx) -> None:
    holding(ctx)
    ft = ctx.devices.ft
    ft.value = np.array([0.0, 0.0, 150.0, 0, 0, 0])  # fingers still pressing

    def released(_: int) -> None:  # the load goes with the opened jaws
        if not ctx.devices.gripper.object_detected() and not ctx.devices.gripper.moving():
            ft.value = np.zeros(6)

    node = lv.PutBack("put back", ctx, max_force_n=250.0)
    assert run(node, ctx, on_tick=released)[-1] == Status.FAILURE
    assert not ctx.events.aborts and len(ctx.devices.arm.commands) == 2  # it went home


def test_put_back_goes_home_under_the_stricter_move_limit(ctx) -> None:
    """The opening and the rise may drag the fingers out of a wedged part under the node's high
    limit; a 150 N push that stays on the way home stops the arm."""
    holding(ctx)
    ctx.devices.ft.value = np.array([0.0, 0.0, 150.0, 0, 0, 0])  # it never goes away
    node = lv.PutBack("put back", ctx, max_force_n=250.0)
    assert run(node, ctx)[-1] == Status.FAILURE
    assert ctx.events.codes == [Failure.FORCE_TORQUE] and ctx.devices.arm.stops >= 1
    assert [c[0] for c in ctx.devices.arm.commands] == ["path", "joints"]  # rose, home stopped


def test_put_back_force_spike_stops_the_arm_before_home_and_reports_an_abort(ctx) -> None:
    node = lv.PutBack("put back", ctx, max_force_n=250.0)
    world = World(ctx, node, weight=False)

    def spike_when_rising(_: int) -> None:
        seq = node.skill  # a plain Sequence: look at the step in progress
        if seq is not None and seq.steps[seq.index].name == "rise":
            world.extra = np.array([300.0, 0.0, 0.0, 0, 0, 0])

    assert run(node, ctx, world, on_tick=spike_when_rising)[-1] == Status.FAILURE
    assert len(ctx.events.aborts) == 1 and ctx.devices.arm.stops == 1
    assert [c[0] for c in ctx.devices.arm.commands] == ["path"]  # never went home


def test_put_back_halted_mid_motion_stops_the_arm(ctx) -> None:
    node = lv.PutBack("put back", ctx)
    # the jaws open first (no arm move); halt once the rise runs
    for _ in range(50):
        node.tick_once()
        ctx.devices.gripper.tick()
        ctx.devices.clock.t += ctx.devices.clock.dt
        if ctx.devices.arm.commands:
            break
    ctx.devices.arm.ticks_per_move = 10**6
    ctx.devices.arm.remaining = 10**6
    node.tick_once()
    assert node.status == Status.RUNNING and ctx.devices.arm.state is MotionState.MOVING
    stops = ctx.devices.arm.stops
    node.stop(Status.INVALID)
    assert ctx.devices.arm.stops == stops + 1 and not ctx.events.aborts


# ------------------------------------------------------------------- FeedSlot, PickFromSlot
def test_feed_slot_lets_the_part_go_on_the_slot_floor_and_marks_the_slot_fed(ctx) -> None:
    holding(ctx)
    node = lv.FeedSlot("feed slot", ctx)
    world = World(ctx, node, {"into the slot": (0.0, 0.0, 10.0)})
    assert run(node, ctx, world)[-1] == Status.SUCCESS
    assert ctx.slot_state == "fed" and ctx.events.kinds() == ["fed"]
    assert node.skill.on_floor and not ctx.events.aborts
    assert not ctx.devices.gripper.object_detected()  # let go


def test_feed_slot_fails_when_the_part_comes_out_with_the_gripper(ctx) -> None:
    holding(ctx)
    node = lv.FeedSlot("feed slot", ctx)
    # the jaws open, but the part's weight stays on the wrist: it did not stay in the slot
    world = World(ctx, node, {"into the slot": (0.0, 0.0, 10.0)}, held=lambda: True)
    assert run(node, ctx, world)[-1] == Status.FAILURE
    assert ctx.slot_state == "empty" and "fed" not in ctx.events.kinds()
    assert len(ctx.events.aborts) == 1


def test_feed_slot_force_spike_fails_stops_the_arm_and_leaves_the_slot_empty(ctx) -> None:
    holding(ctx)
    node = lv.FeedSlot("feed slot", ctx)
    world = World(ctx, node, {"into the slot": (0.0, 0.0, 10.0)})
    assert run(node, ctx, world, on_tick=spike_on(world, "down to the slot"))[-1] == (
        Status.FAILURE
    )
    assert ctx.devices.arm.stops == 1 and ctx.devices.arm.state is MotionState.STOPPED
    assert ctx.slot_state == "empty" and len(ctx.events.aborts) == 1
    assert "fed" not in ctx.events.kinds()


def test_feed_slot_halted_mid_motion_stops_the_arm(ctx) -> None:
    holding(ctx)
    node = lv.FeedSlot("feed slot", ctx)
    stops = start_then_halt(node, ctx)
    assert ctx.devices.arm.stops == stops + 1 and ctx.slot_state == "empty"


def test_pick_from_slot_takes_the_part_out_and_empties_the_slot(ctx) -> None:
    ctx.slot_state = "machined"
    node = lv.PickFromSlot("pick from slot", ctx)
    world = World(ctx, node)
    assert run(node, ctx, world)[-1] == Status.SUCCESS
    assert ctx.slot_state == "empty" and ctx.events.kinds() == ["picked_from_slot"]
    assert ctx.devices.gripper.object_detected() and not ctx.events.aborts


def test_pick_from_slot_without_the_parts_weight_fails_and_the_slot_keeps_it(ctx) -> None:
    ctx.slot_state = "machined"
    node = lv.PickFromSlot("pick from slot", ctx)
    world = World(ctx, node, weight=False)  # pinched something, but the part stayed behind
    assert run(node, ctx, world)[-1] == Status.FAILURE
    assert ctx.slot_state == "machined" and "picked_from_slot" not in ctx.events.kinds()
    assert len(ctx.events.aborts) == 1


def test_pick_from_slot_force_spike_and_halt_stop_the_arm(ctx) -> None:
    ctx.slot_state = "machined"
    node = lv.PickFromSlot("pick from slot", ctx)
    world = World(ctx, node)
    assert run(node, ctx, world, on_tick=spike_on(world, "down to the rim"))[-1] == (
        Status.FAILURE
    )
    assert ctx.devices.arm.stops == 1 and len(ctx.events.aborts) == 1
    assert ctx.slot_state == "machined"

    py_trees.blackboard.Blackboard.clear()
    ctx2 = make_ctx()
    node2 = lv.PickFromSlot("pick from slot", ctx2)
    stops = start_then_halt(node2, ctx2)
    assert ctx2.devices.arm.stops == stops + 1 and not ctx2.events.aborts


# ---------------------------------------------------------------------------------- PackInBox
PUSHES = {
    "push -z onto the floor": (0.0, 0.0, 10.0),
    "push +x": (-10.0, 0.0, 0.0),
    "push +y": (0.0, -10.0, 0.0),
}


def test_pack_in_box_fills_the_first_free_place_and_reports_it(ctx) -> None:
    ctx.filled.add(0)  # a resumed cell: place 0 is taken
    holding(ctx)
    node = lv.PackInBox("pack in box", ctx)
    world = World(ctx, node, PUSHES)
    assert run(node, ctx, world)[-1] == Status.SUCCESS
    assert ctx.filled == {0, 1}
    assert [(k, d) for k, d in ctx.events.events] == [("packed", {"place": 1})]
    assert blackboard().get("/cell/place") == 1
    assert set(node.skill.contacts) == {"floor", "+x", "+y"}
    assert not ctx.devices.gripper.object_detected() and not ctx.events.aborts


def test_pack_in_box_with_the_box_full_cannot_start_and_moves_nothing(ctx) -> None:
    ctx.filled.update({0, 1})
    holding(ctx)
    node = lv.PackInBox("pack in box", ctx)
    node.tick_once()
    assert node.status == Status.FAILURE
    assert not ctx.devices.arm.commands and "packed" not in ctx.events.kinds()


def test_pack_in_box_with_nothing_to_push_on_fails_with_an_abort_and_fills_nothing(ctx) -> None:
    holding(ctx)
    node = lv.PackInBox("pack in box", ctx)
    world = World(ctx, node, {"push -z onto the floor": (0.0, 0.0, 10.0)})  # no walls
    assert run(node, ctx, world)[-1] == Status.FAILURE
    assert ctx.filled == set() and "packed" not in ctx.events.kinds()
    assert len(ctx.events.aborts) == 1


def test_pack_in_box_force_spike_and_halt_stop_the_arm(ctx) -> None:
    holding(ctx)
    node = lv.PackInBox("pack in box", ctx)
    world = World(ctx, node, PUSHES)
    assert run(node, ctx, world, on_tick=spike_on(world, "over the place"))[-1] == (
        Status.FAILURE
    )
    assert ctx.devices.arm.stops == 1 and len(ctx.events.aborts) == 1
    assert ctx.filled == set()

    py_trees.blackboard.Blackboard.clear()
    ctx2 = make_ctx()
    holding(ctx2)
    node2 = lv.PackInBox("pack in box", ctx2)
    stops = start_then_halt(node2, ctx2)
    assert ctx2.devices.arm.stops == stops + 1 and ctx2.filled == set()


def test_perceive_decides_on_the_failure_code_not_the_words(ctx, seeing) -> None:
    """A lost camera whose message happens to read like an empty bin is still a failure, and
    its abort carries the device-lost code the soak and the reports count by."""
    camera, _ = seeing
    monkey_message = "no part found in the bin (camera timeout)"
    camera.capture = lambda: (_ for _ in ()).throw(TimeoutError(monkey_message))  # type: ignore[method-assign]
    node = lv.Perceive("perceive", ctx)
    assert run(node, ctx)[-1] == Status.FAILURE
    assert ctx.events.codes == [Failure.DEVICE_LOST]
    assert monkey_message in ctx.events.aborts[0]


def test_an_empty_bin_is_an_answer_by_its_code(ctx, seeing) -> None:
    node = lv.Perceive("perceive", ctx)
    assert run(node, ctx)[-1] == Status.SUCCESS
    assert node.failure is None and ctx.events.codes == []


# ------------------------------------------------------- plan_pick: walls, ends, drags
def lying(x: float, y: float, yaw: float) -> Detection:
    return Detection(
        center=np.array([x, y, 0.017]), yaw=yaw, length=0.068, outer=0.034, part="bushing",
        open_end=np.array([x + 0.034 * np.cos(yaw), y + 0.034 * np.sin(yaw), 0.017]),
        open_end_seen=True, confidence=0.9, pixels=500,
    )


def settle(node) -> None:  # type: ignore[no-untyped-def]
    """Tick a planning leaf until it is done (its sweeps are spread over ticks)."""
    import time

    node.tick_once()
    for _ in range(2000):
        if node.status != Status.RUNNING:
            return
        time.sleep(0.005)
        node.tick_once()


def test_plan_pick_prefers_a_part_the_pivot_clears_and_takes_a_tube_from_the_end_that_does(
    ctx,
) -> None:
    bb = blackboard()
    walled = lying(0.283, 0.069, np.radians(165))  # its end 29 mm from the -x wall
    free = lying(0.47, 0.07, -np.pi / 2)  # its Tilt would swing into the +y wall from this end
    bb.set("/part/detections", [walled, free])
    bb.set("/part/seen", walled)
    node = lv.PlanPick("plan", ctx)
    settle(node)
    assert node.status == Status.SUCCESS
    tgt = bb.get("/part/target")
    assert tgt["detection"] is free and tgt["reposition"] is None
    assert tgt["frame"].u[1] == pytest.approx(1.0)  # pivoted from its other end
    clears = lv.PivotClears("clears", ctx)
    clears.tick_once()
    assert clears.status == Status.SUCCESS


def test_plan_pick_plans_a_drag_when_no_part_clears_and_the_drag_leaf_needs_one(ctx) -> None:
    bb = blackboard()
    walled = lying(0.283, 0.069, np.radians(165))
    bb.set("/part/detections", [walled])
    node = lv.PlanPick("plan", ctx)
    settle(node)
    assert node.status == Status.SUCCESS
    tgt = bb.get("/part/target")
    assert tgt["detection"] is walled and tgt["reposition"] is not None
    assert tgt["reposition"].shift[0] > 0.0  # away from the -x wall
    clears = lv.PivotClears("clears", ctx)
    clears.tick_once()
    assert clears.status == Status.FAILURE
    drag = lv.Reposition("drag", ctx)
    statuses = run(drag, ctx)
    assert statuses[-1] == Status.SUCCESS, drag.feedback_message
    assert [e for e in ctx.events.events if e[0] == EventKind.REPOSITIONED]


def test_plan_pick_names_a_part_nothing_frees_and_leaves_it(ctx) -> None:
    bb = blackboard()
    walled = lying(0.283, 0.069, np.radians(165))
    # neighbours of another kind pressed against both its sides: not picked, but in the way
    hem = [
        dataclasses.replace(lying(0.283, 0.069 + s * 0.036, np.radians(165)), part="cup")
        for s in (-1.0, 1.0)
    ]
    bb.set("/part/detections", [walled, *hem])
    node = lv.PlanPick("plan", ctx)
    settle(node)
    assert node.status == Status.FAILURE and bb.get("/cell/bin_empty") is True
    ends = [e for e in ctx.events.events if e[0] == EventKind.BIN_EMPTY]
    reasons = [x["reason"] for x in ends[-1][1]["left"]]
    assert any(r.startswith("no pivot clears") and "no drag frees it" in r for r in reasons)


@pytest.mark.parametrize(
    "how", ["leaning", "leaning, 3 mm up", "on a neighbour", "leaning, its open end not made out"]
)
def test_plan_pick_lays_a_raised_part_down_instead_of_pivoting_it_as_it_lies(ctx, how) -> None:
    """A part free for the pivot where it lies, but off the floor: laid down first (the pivot
    turns it about its far corner on the floor). A part 5 mm higher is pivoted as it lies."""
    bb = blackboard()
    free = lying(0.47, 0.0, 0.0)
    raised = {
        "leaning": dataclasses.replace(free, tilted=True, raised=0.009),
        "leaning, 3 mm up": dataclasses.replace(free, tilted=True, raised=0.003),
        "on a neighbour": dataclasses.replace(free, raised=0.034),
        "leaning, its open end not made out": dataclasses.replace(
            free, tilted=True, open_end_seen=False, raised=0.009
        ),
    }[how]
    bb.set("/part/detections", [raised])
    node = lv.PlanPick("plan", ctx)
    settle(node)
    assert node.status == Status.SUCCESS, node.feedback_message
    move = bb.get("/part/target")["reposition"]
    assert move is not None and move.kind.value == "lay down"
    assert move.drop == pytest.approx(raised.raised)
    bb.set("/part/detections", [dataclasses.replace(free, raised=0.005)])
    node = lv.PlanPick("plan", ctx)
    settle(node)
    assert node.status == Status.SUCCESS and bb.get("/part/target")["reposition"] is None


def test_plan_pick_spreads_its_sweeps_over_ticks(ctx) -> None:
    bb = blackboard()
    bb.set("/part/detections", [lying(0.47, 0.0, 0.0)])
    node = lv.PlanPick("plan", ctx)
    node.tick_once()
    assert node.status == Status.RUNNING  # the first tick only starts the work
    settle(node)
    assert node.status == Status.SUCCESS
    # halted mid-way, it starts afresh the next time
    node2 = lv.PlanPick("plan again", ctx)
    node2.tick_once()
    node2.stop(Status.INVALID)
    settle(node2)
    assert node2.status == Status.SUCCESS


@pytest.mark.parametrize("realtime", [False, True])
def test_plan_pick_sweeps_off_the_tick_where_time_runs_on_and_inline_in_the_twin(
    ctx, monkeypatch, realtime: bool
) -> None:
    """On hardware's clock the clearance sweeps run on a worker thread (a tick must come round
    every period); on the twin's they run on the tick, one part a tick (simulated time stands
    still while it computes). Either way the same part and end are chosen."""
    import threading

    from drivers.clock import WallClock

    if realtime:
        ctx = dataclasses.replace(ctx, devices=dataclasses.replace(ctx.devices, clock=WallClock()))
    bb = blackboard()
    walled = lying(0.283, 0.069, np.radians(165))
    free = lying(0.47, 0.07, -np.pi / 2)
    bb.set("/part/detections", [walled, free])
    bb.set("/part/seen", walled)
    swept_on: list[str] = []
    plain = lv.choose_end

    def spy(*args, **kwargs):  # type: ignore[no-untyped-def]
        swept_on.append(threading.current_thread().name)
        return plain(*args, **kwargs)

    monkeypatch.setattr(lv, "choose_end", spy)
    node = lv.PlanPick("plan", ctx)
    settle(node)
    assert node.status == Status.SUCCESS
    tgt = bb.get("/part/target")
    assert tgt["detection"] is free and tgt["frame"].u[1] == pytest.approx(1.0)
    expected = "off-tick plan pick" if realtime else threading.current_thread().name
    assert swept_on == [expected, expected]


def _grasp_commands(ctx, node, ticks: int = 40) -> list[str]:  # type: ignore[no-untyped-def]
    """Tick the Grasp leaf with the fakes stepping; the kinds of the arm's commands so far."""
    for _ in range(ticks):
        node.tick_once()
        ctx.devices.arm.tick()
        ctx.devices.gripper.tick()
        ctx.devices.clock.t += ctx.devices.clock.dt
    return [c[0] for c in ctx.devices.arm.commands]


def test_grasp_out_of_straight_reach_goes_home_by_a_joint_move_first(ctx) -> None:
    """A plan made from home (``reach``) that the arm cannot follow in straight moves from where
    it stands (``reach_here``) starts with the joint move home, then the Grasp's own moves."""
    bb = blackboard()
    bb.set("/part/target", target(ctx))
    ctx.reach_here = lambda poses: 0  # nothing straight from here
    node = lv.Grasp("grasp", ctx)
    kinds = _grasp_commands(ctx, node)
    assert kinds[0] == "joints"
    assert np.allclose(ctx.devices.arm.commands[0][1], ctx.geometry.home_joints)
    assert len(kinds) > 1 and kinds[1] != "joints"  # then the Grasp moves


def test_grasp_in_straight_reach_moves_straight_away(ctx) -> None:
    bb = blackboard()
    bb.set("/part/target", target(ctx))
    ctx.reach_here = lambda poses: None
    node = lv.Grasp("grasp", ctx)
    kinds = _grasp_commands(ctx, node)
    assert kinds and "joints" not in kinds


# ------------------------------------------------------------------ the look while machining
def taken(ctx, name: str) -> Status:  # type: ignore[no-untyped-def]
    """What the next pick's ``planned_ahead`` condition says now."""
    node = lv.PlannedAhead(name, ctx)
    node.tick_once()
    return node.status


def test_a_plan_made_ahead_is_taken_once_and_a_plan_made_now_is_not_ahead(ctx) -> None:
    bb = blackboard()
    bb.set("/part/detections", [lying(0.47, 0.0, 0.0)])
    ahead = lv.PlanPick("plan ahead", ctx, ahead=True)
    settle(ahead)
    assert ahead.status == Status.SUCCESS
    assert taken(ctx, "planned ahead") == Status.SUCCESS
    # a failed pick puts the part back: the bin moved, the next attempt must look again
    assert taken(ctx, "planned ahead again") == Status.FAILURE
    settle(ahead)  # planned ahead once more, then a plan made now replaces it
    now = lv.PlanPick("plan", ctx)
    settle(now)
    assert now.status == Status.SUCCESS
    assert taken(ctx, "planned ahead third") == Status.FAILURE


def test_a_look_ahead_that_finds_nothing_to_pick_leaves_no_plan_to_take(ctx) -> None:
    bb = blackboard()
    bb.set("/part/detections", [])
    ahead = lv.PlanPick("plan ahead", ctx, ahead=True)
    settle(ahead)
    assert ahead.status == Status.FAILURE
    assert taken(ctx, "planned ahead") == Status.FAILURE
