"""Tick-level tests of the behaviours and decorators against fake devices (no physics)."""

from __future__ import annotations

import numpy as np
import py_trees
import pytest
from py_trees.common import Status

from drivers.machine import TimedMachine
from drivers.pose import Pose
from skills.motion import Devices, Guard
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper
from tests.trees.helpers import Recorder, make_ctx, tick_tree
from trees import behaviours as lv
from trees.decorators import Cycles, FTGuard, FTSampler, Retry, StopOnFailure, Timeout


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
    root = py_trees.composites.Parallel(
        "root",
        policy=py_trees.common.ParallelPolicy.SuccessOnSelected(children=[guard]),
        children=[FTSampler("ft", ctx), guard],
    )
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
    node = lv.GraspBehaviour("grasp", ctx)
    node.tick_once()
    assert node.status == Status.FAILURE
    assert "cannot start" in node.feedback_message and "/part/target" in node.feedback_message


def test_update_never_blocks_one_tick_is_one_step(ctx) -> None:
    """A long motion stays RUNNING tick after tick: update() returns at once each time."""
    ctx.devices.arm.ticks_per_move = 50
    node = lv.GoHome("home", ctx)
    statuses = tick_tree(node, ctx, ticks=20)
    assert all(s == Status.RUNNING for s in statuses)


def test_recorder_helper_is_an_events_sink() -> None:
    rec = Recorder()
    rec.event("fed")
    rec.abort("x")
    rec.stop("why")
    rec.stop("later")
    assert rec.kinds() == ["fed"] and rec.aborts == ["x"] and rec.stopped == "why"


def test_devices_are_used_only_through_the_interfaces() -> None:
    """The fakes obey the interfaces the behaviours use (a guard against drift)."""
    dev = Devices(FakeArm(Pose()), FakeGripper(), FakeFT(), FakeClock())
    assert isinstance(TimedMachine(dev.clock, 1.0).busy(), bool)
    assert Guard().max_force > 0


def test_a_dead_ft_stream_stops_the_tree_and_the_arm(ctx) -> None:
    from drivers.health import DeviceError

    class DeadFT:
        def wrench(self):  # type: ignore[no-untyped-def]
            raise DeviceError("FT300", "/dev/ttyUSB1", "newest sample is 0.20 s old")

    ctx.devices.arm.ticks_per_move = 100
    leaf = lv.GoHome("home", ctx)
    sampler = FTSampler("ft", ctx)
    root = py_trees.composites.Parallel(
        "root",
        policy=py_trees.common.ParallelPolicy.SuccessOnSelected(children=[leaf]),
        children=[sampler, leaf],
    )
    root.tick_once()
    assert root.status == Status.RUNNING
    stops = ctx.devices.arm.stops
    object.__setattr__(ctx.devices, "ft", DeadFT())
    root.tick_once()
    assert root.status == Status.FAILURE
    assert leaf.status == Status.INVALID and ctx.devices.arm.stops > stops
    assert "0.20 s old" in ctx.events.stopped
