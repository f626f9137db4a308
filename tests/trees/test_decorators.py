"""Tick-level tests of trees/decorators.py: FTGuard, Timeout, Retry, StopOnFailure, Cycles and
FTSampler, each for success, failure and a halt by a parent mid-motion.

The children are either scripted behaviours (they count their starts, halts and ticks) or GoHome
on the fake arm, so "halted" can be checked as "the arm was told to stop". Checks are on
statuses, arm stops, events and counts, not on message wording.
"""

from __future__ import annotations

import numpy as np
import py_trees
import pytest
from py_trees.behaviour import Behaviour
from py_trees.common import Access, ParallelPolicy, Status

from drivers.health import DeviceError
from tests.trees.helpers import fresh_ctx
from trees import behaviours as lv
from trees.decorators import (
    WRENCH_KEY,
    Cycles,
    FTGuard,
    FTSampler,
    OptionalStep,
    Retry,
    StopOnFailure,
    Timeout,
)


@pytest.fixture
def ctx():
    c = fresh_ctx()
    c.devices.arm.ticks_per_move = 1000  # a long move: a GoHome stays RUNNING
    return c


class Scripted(Behaviour):
    """Returns ``script[i]`` on its i-th tick of a run (the last one repeats); counts starts,
    ticks and halts by a parent."""

    def __init__(self, name: str, *script: Status, message: str = "") -> None:
        super().__init__(name)
        self.script = list(script) or [Status.RUNNING]
        self.starts = self.ticks = self.halts = 0
        self._i = 0
        self.message = message or name

    def initialise(self) -> None:
        self.starts += 1
        self._i = 0

    def update(self) -> Status:
        self.ticks += 1
        status = self.script[min(self._i, len(self.script) - 1)]
        self._i += 1
        self.feedback_message = f"{self.message} ({status.name})"
        return status

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self.halts += 1


def tick(node: Behaviour, n: int = 1) -> Status:
    for _ in range(n):
        node.tick_once()
    return node.status


def set_wrench(value) -> None:  # type: ignore[no-untyped-def]
    client = py_trees.blackboard.Client(name="test wrench")
    client.register_key(WRENCH_KEY, access=Access.WRITE)
    client.set(WRENCH_KEY, None if value is None else np.asarray(value, float))


def halt_by_parent(node: Behaviour) -> None:
    node.stop(Status.INVALID)


# ----------------------------------------------------------------------------------- FTGuard
def test_ft_guard_passes_the_childs_result_through_under_the_limits(ctx) -> None:
    set_wrench([10.0, 0, 0, 0.5, 0, 0])
    child = Scripted("child", Status.RUNNING, Status.SUCCESS)
    guard = FTGuard("g", child, ctx, max_force=50.0, max_torque=5.0)
    assert tick(guard) == Status.RUNNING
    assert tick(guard) == Status.SUCCESS
    assert child.ticks == 2 and ctx.devices.arm.stops == 0 and not ctx.events.aborts

    fails = FTGuard("g2", Scripted("bad", Status.FAILURE), ctx, max_force=50.0, max_torque=5.0)
    assert tick(fails) == Status.FAILURE
    assert ctx.devices.arm.stops == 0 and not ctx.events.aborts  # not the guard's doing


@pytest.mark.parametrize(
    ("wrench", "trips"),
    [
        ([50.0, 0, 0, 0, 0, 0], False),  # exactly at the limit
        ([30.0, 30.0, 30.0, 0, 0, 0], True),  # |F| 52 over 50: the magnitude counts
        ([0, 0, 0, 0, 0, 5.0], False),
        ([0, 0, 0, 3.0, 3.0, 3.0], True),  # |T| 5.2 over 5
    ],
)
def test_ft_guard_trips_on_the_force_or_torque_magnitude(ctx, wrench, trips) -> None:
    set_wrench(np.zeros(6))
    child = Scripted("child")
    guard = FTGuard("g", child, ctx, max_force=50.0, max_torque=5.0)
    tick(guard)
    set_wrench(wrench)
    status = tick(guard)
    if trips:
        assert status == Status.FAILURE
        assert child.halts == 1 and child.ticks == 1  # stopped before it could tick again
        assert ctx.devices.arm.stops == 1 and len(ctx.events.aborts) == 1
    else:
        assert status == Status.RUNNING and child.ticks == 2
        assert ctx.devices.arm.stops == 0 and not ctx.events.aborts


def test_ft_guard_mid_motion_halts_the_leaf_and_stops_the_arm(ctx) -> None:
    set_wrench(np.zeros(6))
    leaf = lv.GoHome("home", ctx)
    guard = FTGuard("g", leaf, ctx, max_force=50.0, max_torque=5.0)
    tick(guard, 3)
    assert leaf.status == Status.RUNNING and ctx.devices.arm.commands
    set_wrench([0, 0, -80.0, 0, 0, 0])
    assert tick(guard) == Status.FAILURE
    assert leaf.status == Status.INVALID
    # the leaf's halt and the guard's own stop: the arm was told at least once, and nothing new
    # was commanded after the spike
    assert ctx.devices.arm.stops >= 1 and len(ctx.devices.arm.commands) == 1
    assert len(ctx.events.aborts) == 1


def test_ft_guard_without_a_sampler_in_the_tree_does_not_block_its_child(ctx) -> None:
    child = Scripted("child", Status.SUCCESS)
    guard = FTGuard("g", child, ctx, max_force=50.0, max_torque=5.0)
    assert tick(guard) == Status.SUCCESS


def test_ft_guard_halted_by_its_parent_halts_the_motion_below(ctx) -> None:
    set_wrench(np.zeros(6))
    leaf = lv.GoHome("home", ctx)
    guard = FTGuard("g", leaf, ctx, max_force=50.0, max_torque=5.0)
    tick(guard, 2)
    halt_by_parent(guard)
    assert leaf.status == Status.INVALID and ctx.devices.arm.stops == 1
    assert not ctx.events.aborts  # a parent's halt is not a guard trip


# ----------------------------------------------------------------------------------- Timeout
def test_timeout_lets_a_child_that_finishes_in_time_succeed(ctx) -> None:
    child = Scripted("child", Status.RUNNING, Status.RUNNING, Status.SUCCESS)
    node = Timeout("t", child, ctx, seconds=1.0)
    clock = ctx.devices.clock
    for _ in range(2):
        tick(node)
        clock.t += 0.4
    assert tick(node) == Status.SUCCESS
    assert ctx.devices.arm.stops == 0 and not ctx.events.aborts


def test_timeout_mid_motion_halts_the_leaf_stops_the_arm_and_reports_an_abort(ctx) -> None:
    leaf = lv.GoHome("home", ctx)
    node = Timeout("t", leaf, ctx, seconds=2.0)
    clock = ctx.devices.clock
    tick(node)
    clock.t += 2.0
    assert tick(node) == Status.RUNNING  # at the limit, not past it
    clock.t += 0.01
    assert tick(node) == Status.FAILURE
    assert leaf.status == Status.INVALID and ctx.devices.arm.stops >= 1
    assert len(ctx.events.aborts) == 1


def test_timeout_restarts_its_clock_when_its_child_is_started_again(ctx) -> None:
    child = Scripted("child", Status.RUNNING, Status.FAILURE)
    node = Timeout("t", child, ctx, seconds=1.0)
    clock = ctx.devices.clock
    clock.t = 10.0
    tick(node, 2)
    assert node.status == Status.FAILURE and not ctx.events.aborts
    clock.t = 10.9  # a fresh run (a retry) gets its full second again
    child.script = [Status.RUNNING]
    assert tick(node) == Status.RUNNING
    clock.t = 11.8
    assert tick(node) == Status.RUNNING
    clock.t = 11.95
    assert tick(node) == Status.FAILURE and len(ctx.events.aborts) == 1


def test_timeout_halted_by_its_parent_halts_its_child_without_an_abort(ctx) -> None:
    child = Scripted("child")
    node = Timeout("t", child, ctx, seconds=5.0)
    tick(node)
    halt_by_parent(node)
    assert child.halts == 1 and not ctx.events.aborts


# ------------------------------------------------------------------------------------- Retry
def test_retry_succeeds_at_once_without_restarting_a_child_that_succeeds(ctx) -> None:
    child = Scripted("child", Status.RUNNING, Status.SUCCESS)
    retry = Retry("r", child, ctx, attempts=3)
    assert tick(retry) == Status.RUNNING
    assert tick(retry) == Status.SUCCESS
    assert child.starts == 1 and retry.failures == 0


def test_retry_restarts_the_child_on_the_next_tick_after_a_failure(ctx) -> None:
    child = Scripted("child", Status.FAILURE)
    retry = Retry("r", child, ctx, attempts=3)
    assert tick(retry) == Status.RUNNING and child.starts == 1 and retry.failures == 1
    assert tick(retry) == Status.RUNNING and child.starts == 2
    assert tick(retry) == Status.FAILURE and child.starts == 3 and retry.failures == 3
    assert tick(retry, 1) == Status.RUNNING  # started afresh by a parent: counts from zero
    assert retry.failures == 1


def test_retry_gives_up_early_when_the_bin_is_empty_or_the_cell_was_stopped(ctx) -> None:
    client = py_trees.blackboard.Client(name="test bin")
    client.register_key("/cell/bin_empty", access=Access.WRITE)
    client.set("/cell/bin_empty", True)
    child = Scripted("child", Status.FAILURE)
    retry = Retry("r", child, ctx, attempts=5)
    assert tick(retry) == Status.FAILURE and child.starts == 1

    client.set("/cell/bin_empty", False)
    child2 = Scripted("child2", Status.FAILURE)
    retry2 = Retry("r2", child2, ctx, attempts=5)
    ctx.events.stop("a person is needed")
    assert tick(retry2) == Status.FAILURE and child2.starts == 1


def test_retry_records_the_first_and_the_last_reason(ctx) -> None:
    class Changing(Scripted):
        def update(self) -> Status:
            self.feedback_message = f"reason {self.starts}"
            return Status.FAILURE

    retry = Retry("r", Changing("child"), ctx, attempts=3)
    tick(retry, 3)
    assert retry.status == Status.FAILURE
    assert retry.first_reason == "reason 1" and retry.last_reason == "reason 3"


def test_retry_halted_mid_motion_halts_the_leaf_and_stops_the_arm(ctx) -> None:
    leaf = lv.GoHome("home", ctx)
    retry = Retry("r", leaf, ctx, attempts=3)
    tick(retry, 2)
    assert leaf.status == Status.RUNNING
    halt_by_parent(retry)
    assert leaf.status == Status.INVALID and ctx.devices.arm.stops == 1


def test_retry_pauses_without_ticking_and_a_halt_drops_the_pending_pause(ctx) -> None:
    child = Scripted("child", Status.FAILURE)
    retry = Retry("r", child, ctx, attempts=3, pause_s=1.0)
    tick(retry)
    assert child.starts == 1
    ctx.devices.clock.t += 0.5
    assert tick(retry) == Status.RUNNING
    assert child.starts == 1 and child.ticks == 1  # pausing: the child is not ticked
    halt_by_parent(retry)
    tick(retry)  # started again by its parent: a fresh run, no pause left over
    assert child.starts == 2 and retry.failures == 1


# ---------------------------------------------------------------------------- StopOnFailure
def test_stop_on_failure_passes_success_and_running_without_stopping_the_cell(ctx) -> None:
    child = Scripted("child", Status.RUNNING, Status.SUCCESS)
    node = StopOnFailure("s", child, ctx, reason="part lost")
    assert tick(node) == Status.RUNNING
    assert tick(node) == Status.SUCCESS
    assert ctx.events.stopped is None


def test_stop_on_failure_stops_the_cell_with_its_reason_and_the_childs(ctx) -> None:
    node = StopOnFailure("s", Scripted("child", Status.FAILURE, message="dropped"), ctx, "lost")
    assert tick(node) == Status.FAILURE
    assert ctx.events.stopped is not None
    assert "lost" in ctx.events.stopped and "dropped" in ctx.events.stopped


def test_stop_on_failure_halted_mid_motion_stops_the_arm_and_not_the_cell(ctx) -> None:
    leaf = lv.GoHome("home", ctx)
    node = StopOnFailure("s", leaf, ctx, reason="part lost")
    tick(node, 2)
    halt_by_parent(node)
    assert leaf.status == Status.INVALID and ctx.devices.arm.stops == 1
    assert ctx.events.stopped is None


# ------------------------------------------------------------------------------------ Optional
def test_an_optional_step_that_fails_lets_the_cycle_go_on_and_says_it_was_skipped(ctx) -> None:
    child = Scripted("look ahead", Status.RUNNING, Status.FAILURE, message="nothing seen")
    node = OptionalStep("while the machine runs", child, ctx)
    assert tick(node) == Status.RUNNING
    assert tick(node) == Status.SUCCESS
    assert "skipped" in node.feedback_message and "nothing seen" in node.feedback_message
    assert ctx.events.stopped is None


def test_an_optional_step_does_not_hide_a_stop_the_cell_was_told_to_make(ctx) -> None:
    inner = StopOnFailure("s", Scripted("child", Status.FAILURE), ctx, reason="part lost")
    node = OptionalStep("opt", inner, ctx)
    assert tick(node) == Status.FAILURE
    assert ctx.events.stopped is not None


# ------------------------------------------------------------------------------------ Cycles
def test_cycles_count_each_success_publish_it_and_end_at_the_count(ctx) -> None:
    ctx.limits.cycles = 2
    child = Scripted("cycle", Status.RUNNING, Status.SUCCESS)
    cycles = Cycles("c", child, ctx)
    reader = py_trees.blackboard.Client(name="reader")
    reader.register_key("/cell/cycles_done", access=Access.READ)
    statuses = [tick(cycles) for _ in range(4)]
    assert statuses == [Status.RUNNING, Status.RUNNING, Status.RUNNING, Status.SUCCESS]
    assert cycles.done == 2 and reader.get("/cell/cycles_done") == 2
    assert child.starts == 2
    assert [d["cycle"] for k, d in ctx.events.events if k == "cycle_done"] == [1, 2]


def test_a_resumed_cell_goes_on_counting_from_the_cycles_it_had_done(ctx) -> None:
    ctx.limits.cycles, ctx.limits.cycles_done = 3, 2
    cycles = Cycles("c", Scripted("cycle", Status.SUCCESS), ctx)
    assert tick(cycles) == Status.SUCCESS and cycles.done == 3


def test_cycles_end_with_success_once_the_bin_is_empty(ctx) -> None:
    ctx.limits.cycles = 10
    client = py_trees.blackboard.Client(name="test bin")
    client.register_key("/cell/bin_empty", access=Access.WRITE)
    client.set("/cell/bin_empty", True)
    cycles = Cycles("c", Scripted("cycle", Status.FAILURE), ctx)  # plan pick found nothing
    assert tick(cycles) == Status.SUCCESS
    assert cycles.done == 0 and ctx.events.stopped is None


def test_a_success_resets_the_count_of_failed_cycles_in_a_row(ctx) -> None:
    ctx.limits.cycles, ctx.limits.max_failed_cycles = 10, 2
    child = Scripted("cycle")
    cycles = Cycles("c", child, ctx)
    outcomes = [Status.FAILURE, Status.SUCCESS, Status.FAILURE, Status.SUCCESS, Status.FAILURE]
    for outcome in outcomes:
        child.script = [outcome]
        assert tick(cycles) == Status.RUNNING  # never two failures in a row
    assert cycles.failed_in_a_row == 1 and ctx.events.stopped is None
    child.script = [Status.FAILURE]
    assert tick(cycles) == Status.FAILURE
    assert ctx.events.stopped is not None
    assert ctx.events.kinds().count("cycle_failed") == 4


def test_cycles_end_with_failure_at_once_when_the_cell_was_stopped(ctx) -> None:
    ctx.limits.max_failed_cycles = 5

    class StopsTheCell(Scripted):
        def update(self) -> Status:
            ctx.events.stop("part lost")
            return Status.FAILURE

    cycles = Cycles("c", StopsTheCell("cycle"), ctx)
    assert tick(cycles) == Status.FAILURE
    assert ctx.events.stopped == "part lost"


def test_cycles_halted_mid_motion_stop_the_arm_without_counting_a_cycle(ctx) -> None:
    leaf = lv.GoHome("home", ctx)
    cycles = Cycles("c", leaf, ctx)
    tick(cycles, 2)
    halt_by_parent(cycles)
    assert leaf.status == Status.INVALID and ctx.devices.arm.stops == 1
    assert cycles.done == 0 and "cycle_done" not in ctx.events.kinds()
    assert "cycle_failed" not in ctx.events.kinds()


# ---------------------------------------------------------------------------------- FTSampler
def test_the_sampler_writes_the_newest_wrench_every_tick_and_never_ends(ctx) -> None:
    sampler = FTSampler("ft", ctx)
    reader = py_trees.blackboard.Client(name="reader")
    reader.register_key(WRENCH_KEY, access=Access.READ)
    for f in (1.0, 2.0, 3.0):
        ctx.devices.ft.value = np.array([0, 0, f, 0, 0, 0])
        assert tick(sampler) == Status.RUNNING
        assert reader.get(WRENCH_KEY)[2] == f


def test_a_lost_stream_with_no_grace_stops_the_cell_and_the_arm_at_once(ctx) -> None:
    ctx.limits.ft_link_grace = 0.0
    sampler = FTSampler("ft", ctx)
    tick(sampler)

    def dead():  # type: ignore[no-untyped-def]
        raise DeviceError("FT300", "/dev/ttyUSB1", "no sample")

    ctx.devices.ft.wrench = dead  # type: ignore[method-assign]
    assert tick(sampler) == Status.FAILURE
    assert ctx.events.stopped is not None and ctx.devices.arm.stops == 1
    assert len(ctx.events.aborts) == 1


def test_a_lost_arm_link_stops_the_cell_at_once_with_its_own_code(ctx) -> None:
    from drivers.arm import ArmStatus, MotionState
    from drivers.events import StopKind
    from skills.status import Failure

    sampler = FTSampler("ft", ctx)
    assert tick(sampler) == Status.RUNNING
    lost = ArmStatus(MotionState.FAULT, "lost connection to the controller", link_lost=True)
    ctx.devices.arm.status = lambda: lost  # type: ignore[method-assign]
    assert tick(sampler) == Status.FAILURE
    assert ctx.events.stop_code is StopKind.ARM_LINK_LOST
    assert ctx.events.codes == [Failure.DEVICE_LOST] and ctx.devices.arm.stops == 1
    # A fault that is not the link (a protective stop) is the motions' to handle, not a stop.
    other = FTSampler("ft2", ctx)
    ctx.devices.arm.status = lambda: ArmStatus(  # type: ignore[method-assign]
        MotionState.FAULT, "protective stop", protective_stop=True)
    assert tick(other) == Status.RUNNING


def test_the_sampler_beside_a_guarded_motion_fails_it_within_one_tick_of_a_spike(ctx) -> None:
    leaf = lv.GoHome("home", ctx)
    guard = FTGuard("g", leaf, ctx, max_force=50.0, max_torque=5.0)
    root = py_trees.composites.Parallel(
        "root", policy=ParallelPolicy.SuccessOnSelected(children=[guard]),
        children=[FTSampler("ft", ctx), guard],
    )
    tick(root, 3)
    assert root.status == Status.RUNNING
    ctx.devices.ft.value = np.array([0, 0, 60.0, 0, 0, 0])
    assert tick(root) == Status.FAILURE
    assert leaf.status == Status.INVALID and ctx.devices.arm.stops >= 1
