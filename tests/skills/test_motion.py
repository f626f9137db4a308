"""Tick-level tests of skills/motion.py: GuardedMotion, arm/gripper motions, Sequence, wait.

Fake devices only (tests/skills/fakes.py): the checks are on statuses, arm stops, commands and
times of the injected clock, not on message text.
"""

from __future__ import annotations

import numpy as np
import pytest

from drivers.arm import ArmStatus, MotionState
from drivers.devices import Devices
from drivers.health import DeviceError
from drivers.pose import Pose
from skills.motion import Guard, GuardedMotion, Sequence, wait, wait_steady
from skills.status import SkillInputError, Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run

TARGET = Pose(np.array([0.5, 0.1, 0.2]))


def devices() -> dict:
    return {"arm": FakeArm(), "gripper": FakeGripper(), "ft": FakeFT(), "clock": FakeClock()}


def dev(d: dict) -> Devices:
    return Devices(d["arm"], d["gripper"], d["ft"], d["clock"])


class Counter:
    """A command that counts its calls; ``done`` says when the motion counts as finished."""

    def __init__(self) -> None:
        self.calls = 0
        self.done = False

    def __call__(self) -> None:
        self.calls += 1


def motion(d: dict, guard: Guard | None = None, failed=None) -> tuple[GuardedMotion, Counter]:  # type: ignore[no-untyped-def]
    c = Counter()
    m = GuardedMotion(
        "m", c, lambda: c.done, d["arm"], d["ft"], d["clock"], guard or Guard(), failed
    )
    return m, c


# ------------------------------------------------------------------------------ GuardedMotion
def test_the_command_starts_on_the_first_tick_only_and_success_follows_finished() -> None:
    d = devices()
    m, c = motion(d)
    assert c.calls == 0  # building a motion commands nothing
    for _ in range(5):
        assert m.tick().status is Status.RUNNING
    assert c.calls == 1
    c.done = True
    assert m.tick().status is Status.SUCCESS
    assert c.calls == 1 and d["arm"].stops == 0


@pytest.mark.parametrize(
    ("wrench", "trips"),
    [
        ([0, 0, 100.0, 0, 0, 0], False),  # exactly at the force limit: allowed
        ([0, 0, 100.1, 0, 0, 0], True),
        ([60.0, 60.0, 60.0, 0, 0, 0], True),  # the magnitude counts, not one axis (|F| 104)
        ([0, 0, 0, 0, 0, 6.0], False),  # exactly at the torque limit
        ([0, 0, 0, 4.0, 4.0, 4.0], True),  # |T| 6.9 over 6
    ],
)
def test_the_guard_trips_on_the_force_or_torque_magnitude_over_the_limit(wrench, trips) -> None:
    d = devices()
    m, c = motion(d, Guard(max_force=100.0, max_torque=6.0, timeout=10.0))
    assert m.tick().status is Status.RUNNING
    d["ft"].value = np.array(wrench, float)
    result = m.tick()
    if trips:
        assert result.status is Status.FAILURE
        assert d["arm"].stops == 1 and d["arm"].state is MotionState.STOPPED
    else:
        assert result.status is Status.RUNNING and d["arm"].stops == 0


def test_a_spike_on_the_very_first_tick_fails_after_the_command_and_stops_the_arm() -> None:
    d = devices()
    d["ft"].value = np.array([0, 0, 500.0, 0, 0, 0])
    m, c = motion(d)
    assert m.tick().status is Status.FAILURE
    assert c.calls == 1 and d["arm"].stops == 1


def test_the_guard_is_checked_before_finished_a_spike_fails_a_finished_motion() -> None:
    d = devices()
    m, c = motion(d)
    m.tick()
    c.done = True
    d["ft"].value = np.array([0, 0, 150.0, 0, 0, 0])
    assert m.tick().status is Status.FAILURE
    assert d["arm"].stops == 1


def test_peak_force_is_the_largest_magnitude_seen_and_resets_on_start() -> None:
    d = devices()
    m, _ = motion(d)
    for f in (10.0, 40.0, 25.0):
        d["ft"].value = np.array([0, f, 0, 0, 0, 0])
        m.tick()
    assert m.peak_force == pytest.approx(40.0)
    m.start()
    assert m.peak_force == 0.0


def test_the_timeout_runs_on_the_injected_clock_from_the_start_of_the_motion() -> None:
    d = devices()
    clock = d["clock"]
    clock.t = 100.0  # the motion's clock starts when it starts, not at zero
    m, _ = motion(d, Guard(timeout=0.5))
    assert m.tick().status is Status.RUNNING
    clock.t = 100.5
    assert m.tick().status is Status.RUNNING  # at the limit, not past it
    assert d["arm"].stops == 0
    clock.t = 100.51
    assert m.tick().status is Status.FAILURE
    assert d["arm"].stops == 1


def test_a_failed_test_fails_the_motion_and_stops_the_arm() -> None:
    d = devices()
    why = {"reason": None}
    m, c = motion(d, failed=lambda: why["reason"])
    assert m.tick().status is Status.RUNNING
    why["reason"] = "jammed"
    c.done = True  # a failure is checked before finished
    result = m.tick()
    assert result.status is Status.FAILURE and "jammed" in result.message
    assert d["arm"].stops == 1


@pytest.mark.parametrize(
    "error",
    [
        DeviceError("FT300", "/dev/ttyUSB1", "stale"),
        TimeoutError("no frame"),
        SkillInputError("no valid depth"),
    ],
)
def test_a_device_or_input_error_fails_the_step_and_stops_the_arm_instead_of_raising(error) -> None:
    d = devices()
    m, _ = motion(d)
    assert m.tick().status is Status.RUNNING

    def broken() -> np.ndarray:
        raise error

    d["ft"].wrench = broken  # type: ignore[method-assign]
    result = m.tick()
    assert result.status is Status.FAILURE
    assert d["arm"].stops == 1


def test_an_arm_that_cannot_even_stop_still_gives_a_failure_not_an_exception() -> None:
    d = devices()
    m, _ = motion(d)
    m.tick()

    def dead(*_a: object) -> None:
        raise DeviceError("UR5", "10.0.0.2", "link lost")

    d["ft"].wrench = dead  # type: ignore[method-assign]
    d["arm"].stop = dead  # type: ignore[method-assign]
    assert m.tick().status is Status.FAILURE


def test_halt_stops_the_arm_only_once_the_motion_started() -> None:
    d = devices()
    m, _ = motion(d)
    m.halt()  # nothing was commanded: nothing to stop
    assert d["arm"].stops == 0
    m.tick()
    m.halt()
    assert d["arm"].stops == 1


# ----------------------------------------------------------------- arm_motion, gripper_motion
def test_an_arm_motion_commands_once_and_succeeds_when_the_arm_is_done() -> None:
    d = devices()
    d["arm"].ticks_per_move = 4
    m = dev(d).move("go", Guard(), lambda: d["arm"].move_to(TARGET, 0.1, 0.5))
    result, ticks = run(m, d)
    assert result.status is Status.SUCCESS
    assert ticks == 4
    assert [k for k, _ in d["arm"].commands] == ["path"]
    assert np.allclose(d["arm"].pose.position, TARGET.position)


@pytest.mark.parametrize("state", [MotionState.FAULT, MotionState.STOPPED])
def test_an_arm_motion_fails_when_the_arm_faults_or_stops_under_it(state) -> None:
    d = devices()
    d["arm"].ticks_per_move = 100
    m = dev(d).move("go", Guard(), lambda: d["arm"].move_to(TARGET, 0.1, 0.5))
    assert m.tick().status is Status.RUNNING
    d["arm"].status = lambda: ArmStatus(state, "protective stop")  # type: ignore[method-assign]
    assert m.tick().status is Status.FAILURE


def test_a_gripper_motion_finishes_once_the_fingers_were_still_for_settle_seconds() -> None:
    d = devices()
    clock = d["clock"]
    m = dev(d).grip("open", Guard(), lambda: d["gripper"].open(0.05), settle=0.1)
    assert m.tick().status is Status.RUNNING  # commanded: the fingers move
    assert d["gripper"].moving()
    d["gripper"].tick()  # they stop
    assert m.tick().status is Status.RUNNING  # still for 0 s
    clock.t += 0.05
    assert m.tick().status is Status.RUNNING
    clock.t += 0.06
    assert m.tick().status is Status.SUCCESS
    assert d["gripper"].width() == pytest.approx(0.05)


def test_a_gripper_motion_fails_on_a_gripper_fault_and_stops_the_arm() -> None:
    d = devices()
    m = dev(d).grip("close", Guard(), lambda: d["gripper"].close(10.0))
    m.tick()
    d["gripper"].fault = lambda: "0x0B"  # type: ignore[method-assign]
    assert m.tick().status is Status.FAILURE
    assert d["arm"].stops == 1


# --------------------------------------------------------------------------------- Sequence
def test_a_sequence_runs_its_steps_in_order_one_tick_each_and_then_succeeds() -> None:
    d = devices()
    order: list[str] = []
    steps = [
        GuardedMotion(n, lambda n=n: order.append(n), lambda: True, d["arm"], d["ft"],
                      d["clock"], Guard())
        for n in ("a", "b", "c")
    ]
    seq = Sequence("seq", steps)
    statuses = []
    for _ in range(5):
        r = seq.tick()
        statuses.append(r.status)
        if r.done:
            break
    # each step finishes on its first tick; a finished step never starts the next in the
    # same tick (one control step per tick)
    assert statuses == [Status.RUNNING] * 3 + [Status.SUCCESS]
    assert order == ["a", "b", "c"]


def test_a_sequence_stops_at_the_first_failure_and_never_starts_the_rest() -> None:
    d = devices()
    started: list[str] = []

    def step(name: str, fails: bool) -> GuardedMotion:
        return GuardedMotion(name, lambda: started.append(name), lambda: True, d["arm"],
                             d["ft"], d["clock"], Guard(), lambda: "no" if fails else None)

    seq = Sequence("seq", [step("a", False), step("b", True), step("c", False)])
    assert seq.tick().status is Status.RUNNING
    assert seq.tick().status is Status.FAILURE
    assert started == ["a", "b"]
    assert seq.index == 1


def test_a_sequence_names_its_current_step_and_the_steps_it_has_passed() -> None:
    d = devices()
    steps = [
        GuardedMotion(n, lambda: None, lambda: True, d["arm"], d["ft"], d["clock"], Guard())
        for n in ("a", "b")
    ]
    seq = Sequence("seq", steps)
    assert seq.current == "a" and not seq.passed("a")
    seq.tick()  # "a" finishes: the sequence moves on
    assert seq.current == "b" and seq.passed("a") and not seq.passed("b")
    seq.tick()
    assert seq.current == "done" and seq.passed("b")
    assert not seq.passed("no such step")


def test_halt_stops_the_step_in_progress_and_nothing_once_the_sequence_is_done() -> None:
    d = devices()
    d["arm"].ticks_per_move = 100
    device = dev(d)
    seq = Sequence("seq", [device.move("go", Guard(), lambda: d["arm"].move_to(TARGET, 0.1, 1))])
    seq.halt()  # not started: nothing to stop
    assert d["arm"].stops == 0
    seq.tick()
    assert d["arm"].state is MotionState.MOVING
    seq.halt()  # mid-motion: the arm stops
    assert d["arm"].stops == 1 and d["arm"].state is MotionState.STOPPED

    d2 = devices()
    quick = Sequence("q", [dev(d2).move("go", Guard(), lambda: d2["arm"].move_to(TARGET, 1, 1))])
    result, _ = run(quick, d2)
    assert result.status is Status.SUCCESS
    quick.halt()
    assert d2["arm"].stops == 0


# ------------------------------------------------------------------------------------ wait
def test_wait_holds_for_its_seconds_of_the_cell_clock_and_commands_nothing() -> None:
    d = devices()
    w = wait("settle", dev(d), Guard(), 0.3)
    result, ticks = run(w, d)
    assert result.status is Status.SUCCESS
    assert ticks * d["clock"].dt == pytest.approx(0.3, abs=d["clock"].dt)
    assert d["arm"].commands == [] and d["arm"].stops == 0


def test_a_steady_wait_ends_once_the_wrist_force_holds_still_for_its_window() -> None:
    d = devices()
    w = wait_steady("stand", dev(d), Guard(), band=1.0, window=0.05, longest=0.3)
    result, ticks = run(w, d)  # nothing loads the fingers: steady from the start
    assert result.status is Status.SUCCESS
    assert ticks * d["clock"].dt == pytest.approx(0.05, abs=d["clock"].dt)
    assert d["arm"].commands == [] and d["arm"].stops == 0


def test_a_steady_wait_lasts_while_the_part_rocks_on_the_fingers_but_not_past_its_longest() -> None:
    d = devices()
    rocking = lambda i: setattr(d["ft"], "value", np.array([0, 0, 5.0 * (i % 2), 0, 0, 0]))  # noqa: E731,E501
    w = wait_steady("stand", dev(d), Guard(), band=1.0, window=0.05, longest=0.3)
    result, ticks = run(w, d, on_tick=rocking)
    assert result.status is Status.SUCCESS
    assert ticks * d["clock"].dt == pytest.approx(0.3, abs=d["clock"].dt)

    d = devices()
    settling = lambda i: setattr(d["ft"], "value", np.array([0, 0, 5.0 * (i % 2) if i < 10 else 2.0, 0, 0, 0]))  # noqa: E731,E501
    w = wait_steady("stand", dev(d), Guard(), band=1.0, window=0.05, longest=0.3)
    result, ticks = run(w, d, on_tick=settling)
    assert result.status is Status.SUCCESS
    assert 10 < ticks < 10 + 0.05 / d["clock"].dt + 2  # the window after the rocking stopped


def test_a_steady_wait_never_ends_on_one_reading_after_a_long_tick() -> None:
    """A tick longer than the window: the reading before it still counts, so a force that
    jumped across the long tick is not steady."""
    d = devices()
    w = wait_steady("stand", dev(d), Guard(), band=1.0, window=0.05, longest=1.0)
    w.tick()  # starts; one reading at 0 N
    d["clock"].t += 0.2  # one long tick
    d["ft"].value = np.array([0, 0, 5.0, 0, 0, 0])
    assert w.tick().status is Status.RUNNING  # 0 N then 5 N across the window: not steady
    d["clock"].t += 0.06
    assert w.tick().status is Status.SUCCESS  # 5 N held over the window


def test_wait_is_guarded_a_push_while_holding_still_fails_it() -> None:
    d = devices()
    w = wait("settle", dev(d), Guard(max_force=20.0), 5.0)
    spike = lambda i: setattr(d["ft"], "value", np.array([0, 0, 30.0, 0, 0, 0])) if i == 3 else None  # noqa: E731,E501
    result, ticks = run(w, d, on_tick=spike)
    assert result.status is Status.FAILURE and ticks == 3
    assert d["arm"].stops == 1
