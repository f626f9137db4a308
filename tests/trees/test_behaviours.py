"""Tick-level tests of the behaviours and decorators against fake devices (no physics)."""

from __future__ import annotations

import numpy as np
import py_trees
import pytest
from py_trees.common import Status

from tests.trees.helpers import make_ctx, tick_tree
from trees import behaviours as lv
from trees.decorators import Cycles, FTGuard, FTSampler, Retry, StopOnFailure, Timeout


def _beside_sampler(
    sampler: FTSampler, body: py_trees.behaviour.Behaviour
) -> py_trees.composites.Parallel:
    """The shipped root's shape: the FT sampler in parallel with the body, ending with it."""
    return py_trees.composites.Parallel(
        "root",
        policy=py_trees.common.ParallelPolicy.SuccessOnSelected(children=[body]),
        children=[sampler, body],
    )


@pytest.fixture
def ctx():
    py_trees.blackboard.Blackboard.clear()
    return make_ctx()


def test_go_home_runs_then_succeeds_with_a_joint_move(ctx) -> None:
    node = lv.GoHome("home", ctx)
    statuses = tick_tree(node, ctx, ticks=10)
    assert statuses[0] == Status.RUNNING and statuses[-1] == Status.SUCCESS
    assert ctx.devices.arm.commands[0][0] == "joints"
    assert np.allclose(ctx.devices.arm.commands[0][1], ctx.geometry.home_joints)
    assert "home" in node.feedback_message


def test_ft_guard_fails_within_one_tick_stops_the_arm_and_says_why(ctx) -> None:
    leaf = lv.GoHome("home", ctx)
    guard = FTGuard("guard", leaf, ctx, max_force=50.0, max_torque=5.0)
    root = _beside_sampler(FTSampler("ft", ctx), guard)
    ctx.devices.arm.ticks_per_move = 100  # a long move
    root.tick_once()
    assert guard.status == Status.RUNNING and leaf.status == Status.RUNNING
    stops = ctx.devices.arm.stops
    ctx.devices.ft.value = np.array([0.0, 0.0, 75.0, 0, 0, 0])  # a spike
    root.tick_once()
    assert guard.status == Status.FAILURE
    assert leaf.status == Status.INVALID  # halted by its parent
    assert ctx.devices.arm.stops > stops
    assert "75.0 N" in guard.feedback_message and "limit 50" in guard.feedback_message
    assert ctx.events.aborts and "force-torque abort" in ctx.events.aborts[-1]


def test_terminate_stops_the_motion_when_a_parent_halts_and_is_idempotent(ctx) -> None:
    ctx.devices.arm.ticks_per_move = 100
    leaf = lv.GoHome("home", ctx)
    leaf.tick_once()
    assert leaf.status == Status.RUNNING
    stops = ctx.devices.arm.stops
    leaf.stop(Status.INVALID)
    assert ctx.devices.arm.stops == stops + 1
    assert "halted" in leaf.feedback_message
    leaf.stop(Status.INVALID)  # a second halt does not command anything again
    assert ctx.devices.arm.stops == stops + 1


def test_timeout_uses_the_injected_clock_not_wall_time(ctx) -> None:
    ctx.devices.arm.ticks_per_move = 10_000
    node = Timeout("t", lv.GoHome("home", ctx), ctx, seconds=0.5)
    clock = ctx.devices.clock
    node.tick_once()
    assert node.status == Status.RUNNING
    clock.t += 0.49
    node.tick_once()
    assert node.status == Status.RUNNING  # wall time is irrelevant; 0.49 s of cell time passed
    clock.t += 0.02
    node.tick_once()
    assert node.status == Status.FAILURE
    assert "timeout after 0.5" in node.feedback_message
    assert ctx.devices.arm.stops >= 1


class _FailsNTimes(py_trees.behaviour.Behaviour):
    def __init__(self, n: int) -> None:
        super().__init__("flaky")
        self.n, self.runs = n, 0

    def initialise(self) -> None:
        self.runs += 1

    def update(self) -> Status:
        if self.runs <= self.n:
            self.feedback_message = f"failure {self.runs}"
            return Status.FAILURE
        return Status.SUCCESS


def test_retry_counts_attempts_and_gives_up_after_the_limit(ctx) -> None:
    flaky = _FailsNTimes(2)
    retry = Retry("retry", flaky, ctx, attempts=3)
    for _ in range(10):
        retry.tick_once()
        if retry.status != Status.RUNNING:
            break
    assert retry.status == Status.SUCCESS and flaky.runs == 3

    flaky = _FailsNTimes(5)
    retry = Retry("retry2", flaky, ctx, attempts=3)
    for _ in range(10):
        retry.tick_once()
        if retry.status != Status.RUNNING:
            break
    assert retry.status == Status.FAILURE and flaky.runs == 3
    assert "gave up after 3 of 3" in retry.feedback_message
    assert "failure 3" in retry.feedback_message


def test_retry_pauses_on_the_cell_clock_before_the_next_attempt(ctx) -> None:
    flaky = _FailsNTimes(1)
    retry = Retry("retry", flaky, ctx, attempts=2, pause_s=1.0)
    clock = ctx.devices.clock
    retry.tick_once()
    assert retry.status == Status.RUNNING and flaky.runs == 1 and "retrying" in (
        retry.feedback_message
    )
    for _ in range(5):  # ticks within the pause: the child is not restarted
        clock.t += 0.19
        retry.tick_once()
    assert retry.status == Status.RUNNING and flaky.runs == 1
    clock.t += 0.1
    retry.tick_once()
    assert retry.status == Status.SUCCESS and flaky.runs == 2


def test_holding_part_fails_on_an_empty_hand_or_a_gripper_fault(ctx) -> None:
    gripper = ctx.devices.gripper
    node = lv.HoldingPart("held", ctx)
    gripper.closed_on, gripper._moving = 0.003, False
    node.tick_once()
    assert node.status == Status.SUCCESS
    gripper.closed_on = None
    node.tick_once()
    assert node.status == Status.FAILURE and "empty" in node.feedback_message
    gripper.closed_on = 0.003
    gripper.fault = lambda: "0x0B"  # type: ignore[method-assign]
    node.tick_once()
    assert node.status == Status.FAILURE and "0x0B" in node.feedback_message


def test_a_stop_after_a_retry_names_what_failed_first(ctx) -> None:
    class FailsThenEmpty(_FailsNTimes):
        def update(self) -> Status:
            self.feedback_message = "timeout" if self.runs == 1 else "the hand is empty"
            return Status.FAILURE

    node = StopOnFailure("s", Retry("r", FailsThenEmpty(9), ctx, attempts=2), ctx, "part lost")
    for _ in range(3):
        node.tick_once()
    assert node.status == Status.FAILURE
    assert ctx.events.stopped == "part lost: the hand is empty (first attempt: timeout)"


def test_stop_on_failure_stops_the_cell_with_the_reason(ctx) -> None:
    node = StopOnFailure("s", _FailsNTimes(1), ctx, reason="part lost")
    node.tick_once()
    assert node.status == Status.FAILURE
    assert ctx.events.stopped == "part lost: failure 1"


def test_cycles_repeat_until_the_count_and_stop_after_failures_in_a_row(ctx) -> None:
    ctx.limits.cycles = 3
    ok = py_trees.behaviours.Success("ok")
    cycles = Cycles("cycles", ok, ctx)
    for _ in range(10):
        cycles.tick_once()
        if cycles.status != Status.RUNNING:
            break
    assert cycles.status == Status.SUCCESS and cycles.done == 3

    py_trees.blackboard.Blackboard.clear()
    ctx2 = make_ctx()
    ctx2.limits.max_failed_cycles = 2
    cycles = Cycles("cycles2", py_trees.behaviours.Failure("bad"), ctx2)
    for _ in range(10):
        cycles.tick_once()
        if cycles.status != Status.RUNNING:
            break
    assert cycles.status == Status.FAILURE
    assert "2 cycles in a row failed" in ctx2.events.stopped


def test_wait_machining_polls_the_machine_on_the_cell_clock(ctx) -> None:
    node = lv.WaitMachining("wait", ctx)
    node.tick_once()
    assert node.status == Status.RUNNING
    ctx.devices.clock.t += 4.0
    node.tick_once()
    assert node.status == Status.RUNNING and "machining" in node.feedback_message
    ctx.devices.clock.t += 1.5
    node.tick_once()
    assert node.status == Status.SUCCESS
    assert ctx.events.kinds() == ["machined"]


def test_a_machine_started_ahead_is_not_started_again_and_the_wait_is_what_is_left(ctx) -> None:
    start = lv.StartMachining("start", ctx)
    start.tick_once()
    assert start.status == Status.SUCCESS and ctx.machine.busy()
    ctx.devices.clock.t += 4.0  # the arm looks at the bin meanwhile
    wait = lv.WaitMachining("wait", ctx)
    wait.tick_once()
    assert wait.status == Status.RUNNING
    ctx.devices.clock.t += 1.5  # 5 s after the start, not after the wait's
    wait.tick_once()
    assert wait.status == Status.SUCCESS
    assert ctx.machine.cycles == 1
    # the next part's wait starts the machine itself
    wait2 = lv.WaitMachining("wait", ctx)
    wait2.tick_once()
    assert wait2.status == Status.RUNNING and ctx.machine.cycles == 2


def test_plan_pick_on_an_empty_bin_fails_and_marks_it_empty(ctx) -> None:
    node = lv.PlanPick("plan", ctx)
    client = py_trees.blackboard.Client(name="test")
    client.register_key("/part/detections", access=py_trees.common.Access.WRITE)
    client.set("/part/detections", [])
    node.tick_once()
    assert node.status == Status.FAILURE
    assert "no bushing left" in node.feedback_message
    reader = py_trees.blackboard.Client(name="reader")
    reader.register_key("/cell/bin_empty", access=py_trees.common.Access.READ)
    assert reader.get("/cell/bin_empty") is True


def test_a_leaf_without_its_input_fails_with_a_reason_not_a_crash(ctx) -> None:
    node = lv.Grasp("grasp", ctx)
    node.tick_once()
    assert node.status == Status.FAILURE
    assert "cannot start" in node.feedback_message and "/part/target" in node.feedback_message


def test_update_never_blocks_one_tick_is_one_step(ctx) -> None:
    """A long motion stays RUNNING tick after tick: update() returns at once each time."""
    ctx.devices.arm.ticks_per_move = 50
    node = lv.GoHome("home", ctx)
    statuses = tick_tree(node, ctx, ticks=20)
    assert all(s == Status.RUNNING for s in statuses)


def test_a_dead_ft_stream_stops_the_tree_and_the_arm(ctx) -> None:
    from drivers.health import DeviceError

    class DeadFT:
        def wrench(self):  # type: ignore[no-untyped-def]
            raise DeviceError("FT300", "/dev/ttyUSB1", "newest sample is 0.20 s old")

    ctx.devices.arm.ticks_per_move = 100
    leaf = lv.GoHome("home", ctx)
    sampler = FTSampler("ft", ctx)
    root = _beside_sampler(sampler, leaf)
    root.tick_once()
    assert root.status == Status.RUNNING
    stops = ctx.devices.arm.stops
    object.__setattr__(ctx.devices, "ft", DeadFT())
    root.tick_once()
    assert root.status == Status.FAILURE
    # The sampler stops the arm itself (the leaf then fails), or the parallel halts the leaf.
    assert leaf.status in (Status.FAILURE, Status.INVALID) and ctx.devices.arm.stops > stops
    assert "0.20 s old" in ctx.events.stopped


def test_a_short_ft_link_loss_fails_the_motion_then_the_tree_goes_on(ctx) -> None:
    """Within ``ft_link_grace`` the sampler keeps the tree alive, but no guarded motion runs
    without a wrench; a loss longer than the grace stops the cell."""
    from drivers.health import DeviceError

    real = ctx.devices.ft
    lost = {"on": False}

    class FlakyFT:
        def wrench(self):  # type: ignore[no-untyped-def]
            if lost["on"]:
                raise DeviceError("FT300", "/dev/ttyUSB1", "no sample")
            return real.wrench()

    object.__setattr__(ctx.devices, "ft", FlakyFT())
    ctx.limits.ft_link_grace = 0.5
    ctx.devices.arm.ticks_per_move = 100
    guard = FTGuard("guard", lv.GoHome("home", ctx), ctx, max_force=50.0, max_torque=5.0)
    sampler = FTSampler("ft", ctx)
    root = _beside_sampler(sampler, guard)
    root.tick_once()
    assert guard.status == Status.RUNNING
    stops = ctx.devices.arm.stops
    lost["on"] = True
    root.tick_once()
    assert root.status == Status.FAILURE  # the guarded motion failed at once ...
    assert guard.status == Status.FAILURE and "link lost" in guard.feedback_message
    assert ctx.events.stopped is None  # ... the cell did not stop
    assert ctx.devices.arm.stops > stops
    # A motion that has not started waits for the link instead of failing.
    waiting = FTGuard("guard2", lv.GoHome("home2", ctx), ctx, max_force=50.0, max_torque=5.0)
    sampler.tick_once()
    commands = len(ctx.devices.arm.commands)
    waiting.tick_once()
    assert waiting.status == Status.RUNNING and "waiting for the force-torque link" in (
        waiting.feedback_message
    )
    assert len(ctx.devices.arm.commands) == commands  # nothing was commanded
    ctx.devices.clock.t += 0.3
    lost["on"] = False
    sampler.tick_once()
    assert sampler.status == Status.RUNNING and "link back" in sampler.feedback_message
    waiting.tick_once()
    assert waiting.decorated.status == Status.RUNNING  # started once the wrench was back
    assert len(ctx.devices.arm.commands) == commands + 1
    lost["on"] = True
    sampler.tick_once()
    ctx.devices.clock.t += 0.6
    sampler.tick_once()
    assert sampler.status == Status.FAILURE
    assert ctx.events.stopped and "lost for 0.60 s" in ctx.events.stopped


def test_a_motion_waits_for_a_spike_to_pass_before_it_starts_and_trips_if_it_stays(ctx) -> None:
    root_ft = ctx.devices.ft
    sampler = FTSampler("ft", ctx)
    guard = FTGuard("guard", lv.GoHome("home", ctx), ctx, max_force=50.0, max_torque=5.0)
    root_ft.value = np.array([0.0, 0.0, 200.0, 0, 0, 0])  # a spike as the motion would start
    sampler.tick_once()
    guard.tick_once()
    assert guard.status == Status.RUNNING and "settle" in guard.feedback_message
    assert not ctx.devices.arm.commands  # nothing commanded into a spike
    root_ft.value = np.zeros(6)
    ctx.devices.clock.t += 0.02
    sampler.tick_once()
    guard.tick_once()
    assert guard.decorated.status == Status.RUNNING and ctx.devices.arm.commands

    ctx.devices.arm.commands.clear()
    stuck = FTGuard("guard2", lv.GoHome("home2", ctx), ctx, max_force=50.0, max_torque=5.0)
    root_ft.value = np.array([0.0, 0.0, 200.0, 0, 0, 0])  # a load that does not go away
    sampler.tick_once()
    stuck.tick_once()
    assert stuck.status == Status.RUNNING
    ctx.devices.clock.t += ctx.limits.ft_settle + 0.01
    stuck.tick_once()
    assert stuck.status == Status.FAILURE and "force-torque abort" in stuck.feedback_message
    assert not ctx.devices.arm.commands


def test_the_look_ahead_gate_holds_on_every_cycle_but_the_last(ctx) -> None:
    ctx.limits.cycles = 3
    board = py_trees.blackboard.Client(name="cycles")
    board.register_key("/cell/cycles_done", access=py_trees.common.Access.WRITE)
    outcomes = []
    for done in range(3):
        board.set("/cell/cycles_done", done)
        node = lv.CycleFollows("follows", ctx)
        node.tick_once()
        outcomes.append(node.status)
    assert outcomes == [Status.SUCCESS, Status.SUCCESS, Status.FAILURE]


def test_back_over_slot_is_a_joint_move_to_where_the_feed_ended_or_home(ctx) -> None:
    resumed = lv.BackOverSlot("back", ctx)  # no feed in this run (a resumed cell): home
    assert tick_tree(resumed, ctx, ticks=10)[-1] == Status.SUCCESS
    assert np.allclose(ctx.devices.arm.commands[-1][1], ctx.geometry.home_joints)
    over_slot = np.array([1.2, -1.1, 1.4, -1.8, -1.6, 0.3])
    ctx.feed_end_joints = over_slot
    node = lv.BackOverSlot("back", ctx)
    statuses = tick_tree(node, ctx, ticks=10)
    assert statuses[-1] == Status.SUCCESS
    assert ctx.devices.arm.commands[-1][0] == "joints"
    assert np.allclose(ctx.devices.arm.commands[-1][1], over_slot)


def test_back_over_slot_ends_where_the_pick_looks_at_the_slot_from(ctx) -> None:
    import dataclasses

    from cell.reach import UR5_MODEL
    from drivers.ur5.kinematics import HOME_JOINTS, forward_kinematics
    from skills.slot import PickFromSlot
    from tests.trees.test_leaves import FakeCamera

    ctx.devices = dataclasses.replace(ctx.devices, camera=FakeCamera())
    ctx.arm_model = UR5_MODEL
    arm = ctx.devices.arm
    arm.forward, arm.q = forward_kinematics, HOME_JOINTS.copy()  # at home, as after a look
    arm.pose = forward_kinematics(arm.q)
    ctx.feed_end_joints = np.array([1.2, -1.1, 1.4, -1.8, -1.6, 0.3])
    node = lv.BackOverSlot("back", ctx)
    assert tick_tree(node, ctx, ticks=10)[-1] == Status.SUCCESS
    kind, joints = arm.commands[-1]
    # where the pick from the slot's own look goes (its first step's target)
    pick = PickFromSlot(np.asarray(ctx.geometry.slot_center, float), ctx.part, ctx.devices)
    pick.tick()
    view = arm.commands[-1][1][-1]
    assert kind == "joints" and arm.commands[-1][0] == "path"
    pos_err, ang_err = forward_kinematics(np.asarray(joints)).distance(view)
    assert pos_err < 1e-6 and ang_err < 1e-6
    # without the arm's kinematics: the feed's joints, as before
    ctx.arm_model = None
    node = lv.BackOverSlot("back", ctx)
    assert tick_tree(node, ctx, ticks=10)[-1] == Status.SUCCESS
    assert np.allclose(arm.commands[-1][1], ctx.feed_end_joints)


def _finisher_first(ctx, finisher, step, gate: bool):  # type: ignore[no-untyped-def]
    """The shipped tree's shape around a step that hands the part over: a retry (3 attempts)
    of a selector with memory -- the finisher, else the step (gated by ``holding_part`` for the
    feed and the packing) -- each under an FT guard, beside the FT sampler."""
    first = FTGuard("g1", finisher, ctx, 60.0, 8.0)
    guarded = FTGuard("g2", step, ctx, 60.0, 8.0)
    second = (
        py_trees.composites.Sequence(
            "while held", memory=True, children=[lv.HoldingPart("held", ctx), guarded]
        )
        if gate
        else guarded
    )
    body = py_trees.composites.Selector("finish, or the step", memory=True,
                                        children=[first, second])
    retry = Retry("retry", body, ctx, attempts=3, pause_s=1.0)
    return retry, _beside_sampler(FTSampler("ft", ctx), retry)


def _run_with_spike(ctx, root, step_of, spike_step, contact=None):  # type: ignore[no-untyped-def]
    """Tick ``root`` to its end; one 197 N sample as the step's skill enters ``spike_step``;
    ``contact(step)`` gives the world force (N) the fakes feel in a step, if any."""
    dev, spiked = ctx.devices, []
    for _ in range(5000):
        root.tick_once()
        if root.status != Status.RUNNING:
            break
        step = step_of()
        force = contact(step) if contact is not None else None
        if step == spike_step and not spiked:
            spiked.append(step)
            dev.ft.value = np.array([0.0, 0.0, 197.0, 0.0, 0.0, 0.0])
        elif force is not None:
            dev.ft.value = np.concatenate([dev.arm.pose.rotation.T @ np.asarray(force, float),
                                           np.zeros(3)])
        else:
            dev.ft.value = np.zeros(6)
        dev.arm.tick()
        dev.gripper.tick()
        dev.clock.t += dev.clock.dt
    assert spiked
    return root.status


def _step_of(node):  # type: ignore[no-untyped-def]
    return lambda: node.skill.step if node.status == Status.RUNNING and node.skill else ""


def test_a_packing_stopped_past_its_let_go_is_finished_by_leave_box_not_lost(ctx) -> None:
    """A spike on the way up, after the let go: the hand is empty, so the packing cannot start
    again; the retry's next attempt takes the hand out of the box instead, and the part counts
    as packed in the place it was let go in (one PACKED event, the place filled once)."""
    from skills.slot import GRAVITY
    from tests.skills.test_slot_packing_fakes import PACK_CONTACTS

    dev = ctx.devices
    dev.gripper.object_width = 0.003
    dev.gripper.close(20.0)
    dev.gripper.tick()
    pack, leave = lv.PackInBox("pack", ctx), lv.LeaveBox("leave", ctx)
    retry, root = _finisher_first(ctx, leave, pack, gate=True)
    hanging = (0.0, 0.0, -ctx.part.mass * GRAVITY)

    def contact(step: str):  # type: ignore[no-untyped-def]
        dev.arm.blocked = step in PACK_CONTACTS
        if step in PACK_CONTACTS and dev.arm.force is not None:
            return PACK_CONTACTS[step]
        return hanging if step in ("hold still", "read the hanging part") else None

    status = _run_with_spike(ctx, root, _step_of(pack), "withdraw up", contact)
    assert status == Status.SUCCESS, retry.feedback_message
    assert leave.status == Status.SUCCESS  # the finisher did it, not a packing run again
    assert len(ctx.events.aborts) == 1 and "197.0 N" in ctx.events.aborts[0]
    assert retry.failures == 1
    assert ctx.events.kinds() == ["packed"] and ctx.events.events[0][1] == {"place": 0}
    assert ctx.filled == {0} and ctx.left_in_box is None
    assert not dev.gripper.object_detected()


def test_leave_box_fails_without_moving_when_no_packing_was_left_half_done(ctx) -> None:
    leave = lv.LeaveBox("leave", ctx)
    leave.tick_once()
    assert leave.status == Status.FAILURE and leave.feedback_message == ""  # names no cause
    assert ctx.devices.arm.commands == [] and ctx.events.aborts == []


def test_a_finisher_takes_no_parameters_of_its_own(ctx) -> None:
    with pytest.raises(TypeError, match="takes no skill parameters"):
        lv.LeaveSlot("leave", ctx, weight_check=0.0)


def test_a_feed_stopped_while_dragging_out_is_finished_by_leave_slot(ctx) -> None:
    """As for the packing: a spike while dragging out leaves the part in the pocket and the
    hand open; the hand comes out and the part counts as fed once (FED, the slot fed)."""
    from drivers.events import SlotState

    dev = ctx.devices
    dev.gripper.object_width = 0.003
    dev.gripper.close(20.0)
    dev.gripper.tick()
    feed, leave = lv.FeedSlot("feed", ctx, weight_check=0.0), lv.LeaveSlot("leave", ctx)
    retry, root = _finisher_first(ctx, leave, feed, gate=True)

    def contact(step: str):  # type: ignore[no-untyped-def]
        if step.startswith("into the slot") and dev.arm.queue:
            dev.arm.pose = dev.arm.queue[-1]  # the floor stops the part: contact
            return (0.0, 0.0, 10.0)
        return None

    status = _run_with_spike(ctx, root, _step_of(feed), "drag the gripper out", contact)
    assert status == Status.SUCCESS, retry.feedback_message
    assert leave.status == Status.SUCCESS
    assert len(ctx.events.aborts) == 1 and "197.0 N" in ctx.events.aborts[0]
    assert retry.failures == 1
    assert ctx.events.kinds() == ["fed"] and ctx.slot_state is SlotState.FED
    assert ctx.left_in_slot is None and ctx.feed_end_joints is not None


def test_leave_slot_fails_without_moving_when_no_feed_was_left_half_done(ctx) -> None:
    leave = lv.LeaveSlot("leave", ctx)
    leave.tick_once()
    assert leave.status == Status.FAILURE and leave.feedback_message == ""
    assert ctx.devices.arm.commands == [] and ctx.events.aborts == []


def test_a_pick_from_the_slot_stopped_while_lifting_is_finished_by_lift_from_slot(ctx) -> None:
    """A spike while lifting the pinched part: the part is in the hand, so the lift is
    finished (the jaws never open again) and the part counts as picked once; the slot is
    empty. A fresh pick cannot start while that lift is unfinished."""
    from drivers.events import SlotState

    dev = ctx.devices
    dev.gripper.object_width = 0.003
    ctx.slot_state = SlotState.MACHINED
    pick, lift = lv.PickFromSlot("pick", ctx, weight_check=0.0), lv.LiftFromSlot("lift", ctx)
    retry, root = _finisher_first(ctx, lift, pick, gate=False)
    opens: list[int] = []
    original_open = dev.gripper.open

    def counted_open(*a, **k):  # type: ignore[no-untyped-def]
        opens.append(1)
        original_open(*a, **k)

    dev.gripper.open = counted_open  # type: ignore[method-assign]
    status = _run_with_spike(ctx, root, _step_of(pick), "lift out of the slot")
    assert status == Status.SUCCESS, retry.feedback_message
    assert lift.status == Status.SUCCESS and retry.failures == 1
    assert len(opens) == 1  # the pick's own open over the wall, never again with the part
    assert len(ctx.events.aborts) == 1
    assert ctx.events.kinds() == ["picked_from_slot"] and ctx.slot_state is SlotState.EMPTY
    assert ctx.lifting_from_slot is None and dev.gripper.object_detected()


def test_no_fresh_pick_from_the_slot_while_a_lift_is_unfinished(ctx) -> None:
    pick = lv.PickFromSlot("pick", ctx)
    ctx.lifting_from_slot = object()  # type: ignore[assignment]
    pick.tick_once()
    assert pick.status == Status.FAILURE and "lift out of the slot unfinished" in (
        pick.feedback_message
    )
    assert ctx.devices.arm.commands == []


def test_a_stop_names_the_steps_failure_not_the_finisher_that_did_not_apply(ctx) -> None:
    """With nothing left halfway the finisher fails silently: the person is told what failed
    (here the empty hand), not that there was nothing to finish."""
    retry, _ = _finisher_first(ctx, lv.LeaveBox("leave", ctx), lv.PackInBox("pack", ctx),
                               gate=True)
    node = StopOnFailure("s", retry, ctx, "part lost")
    for _ in range(1000):
        node.tick_once()
        if node.status != Status.RUNNING:
            break
        ctx.devices.clock.t += ctx.devices.clock.dt
    assert node.status == Status.FAILURE
    assert ctx.events.stopped == "part lost: the hand is empty"


def test_a_stop_does_not_name_an_old_failure_of_a_step_that_was_passed_over(ctx) -> None:
    """A node keeps the status of its last run: an optional look that failed earlier in the
    cycle is not why a later step failed, and the stop names the later step."""
    from trees.decorators import OptionalStep

    class Fails(py_trees.behaviour.Behaviour):
        def __init__(self, name: str, why: str) -> None:
            super().__init__(name=name)
            self.why = why

        def update(self) -> Status:
            self.feedback_message = self.why
            return Status.FAILURE

    body = py_trees.composites.Sequence("machine and pack", memory=True, children=[
        OptionalStep("while the machine runs", Fails("look", "no bushing left to pick"), ctx),
        Fails("pack", "the hand is empty"),
    ])
    node = StopOnFailure("s", body, ctx, "part lost")
    node.tick_once()
    assert node.status == Status.FAILURE
    assert ctx.events.stopped == "part lost: the hand is empty"
