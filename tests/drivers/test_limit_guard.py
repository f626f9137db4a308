"""The force-torque limit checked at the sensor's rate (drivers/limit_guard.py): the guard
itself, the FT300 driver feeding it from its reader thread while the tick is busy, the twin's
sensor feeding it every sample, and a guarded motion arming it and reporting its trip."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from drivers.arm import MotionState
from drivers.ft300 import FT300
from drivers.limit_guard import LimitGuard
from skills.motion import Guard, GuardedMotion
from skills.status import Failure, Status
from tests.drivers.peers import ft300_peer
from tests.skills.fakes import FakeArm, FakeClock, FakeFT


class Stops:
    def __init__(self) -> None:
        self.calls: list[tuple[float, str]] = []  #: (time.monotonic(), thread name)

    def __call__(self) -> None:
        self.calls.append((time.monotonic(), threading.current_thread().name))


def wrench(fz: float = 0.0, tz: float = 0.0) -> np.ndarray:
    return np.array([0.0, 0.0, fz, 0.0, 0.0, tz])


def test_nothing_armed_nothing_stops() -> None:
    g, stops = LimitGuard(), Stops()
    g.connect_stop(stops)
    assert g.feed(wrench(500.0)) is None
    assert stops.calls == [] and g.trip() is None


def test_a_sample_over_either_limit_stops_once_and_disarms() -> None:
    g, stops = LimitGuard(), Stops()
    g.connect_stop(stops)
    g.arm("press", 30.0, 2.0)
    assert g.feed(wrench(29.9, 1.9)) is None
    trip = g.feed(wrench(0.0, 2.1), stamp=4.0)
    assert trip is not None and len(stops.calls) == 1
    lim = trip.limits
    assert (lim.name, lim.max_force, lim.max_torque, trip.sample_time) == ("press", 30, 2, 4)
    assert trip.torque == pytest.approx(2.1) and trip.stop_error == ""
    assert g.feed(wrench(99.0)) is None  # disarmed: one stop per trip
    assert len(stops.calls) == 1 and g.trip() == trip
    g.arm("next", 30.0, 2.0)  # a motion that starts has seen the trip
    assert g.trip() is None


def test_the_newest_motion_s_limits_are_in_force() -> None:
    g, stops = LimitGuard(), Stops()
    g.connect_stop(stops)
    old = g.arm("slide", 25.0, 8.0)
    g.arm("press", 60.0, 8.0)  # replaces the slide's, even if its owner never disarms
    g.disarm(old)  # a stale token disarms nothing
    assert g.feed(wrench(40.0)) is None
    assert g.feed(wrench(61.0)) is not None and g.trip().limits.name == "press"


def test_a_stop_that_fails_is_kept_in_the_trip_and_the_reader_lives_on() -> None:
    g = LimitGuard()

    def broken() -> None:
        raise OSError("link down")

    g.connect_stop(broken)
    g.arm("m", 10.0, 1.0)
    trip = g.feed(wrench(11.0))
    assert trip is not None and "link down" in trip.stop_error
    unconnected = LimitGuard()
    unconnected.arm("m", 10.0, 1.0)
    assert unconnected.feed(wrench(11.0)).stop_error  # nothing to stop: said, not hidden


def test_the_ft300_reader_stops_the_arm_while_the_tick_is_busy() -> None:
    """The tick thread sleeps (a long planning tick) and never reads the wrench; the sample
    over the limit stops the arm from the sensor's reader thread, bias removed."""
    start = time.monotonic()

    def step(seq: int) -> list[float]:  # 50 N at rest (the tool's weight), 120 N after 0.3 s
        return [0.0, 0.0, 120.0 if time.monotonic() - start > 0.3 else 50.0, 0.0, 0.0, 0.0]

    stops = Stops()
    with ft300_peer(wrench_of=step) as peer, FT300(peer.port, stale_after=1.0) as ft:
        ft.bias()
        ft.limits.connect_stop(stops)
        ft.limits.arm("arc", 60.0, 8.0)  # 50 N of weight zeroed: 70 N over it trips
        busy_until = time.monotonic() + 0.8
        time.sleep(0.8)  # the tick: no wrench() call in here
        assert stops.calls, "nothing stopped the arm during the long tick"
        t_stop, thread = stops.calls[0]
        assert t_stop < busy_until and thread.startswith("ft300")
        trip = ft.limits.trip()
        assert trip is not None and trip.force == pytest.approx(70.0, abs=0.5)
        assert peer.sent is not None
        first_over = min(t for _, t in peer.sent if t - start > 0.3)
        assert trip.sample_time >= first_over  # the sample's arrival, on the same clock
        assert len(stops.calls) == 1


def test_a_guarded_motion_arms_its_limits_and_reports_the_sensor_s_trip() -> None:
    arm, ft, clock = FakeArm(), FakeFT(), FakeClock()
    ft.limits = LimitGuard(clock.now)  # type: ignore[attr-defined]
    ft.limits.connect_stop(arm.stop)  # type: ignore[attr-defined]
    m = GuardedMotion("arc", lambda: arm.move_to(arm.tool_pose(), 0.1, 0.5), lambda: False,
                      arm, ft, clock, Guard(max_force=40.0, max_torque=4.0))
    assert m.tick().status is Status.RUNNING  # started: armed with the motion's limits
    assert arm.status().state is MotionState.MOVING
    ft.limits.feed(wrench(45.0))  # type: ignore[attr-defined]  # between two ticks
    assert arm.status().state is MotionState.STOPPED  # stopped by the sensor, before the tick
    ft.value = wrench(5.0)  # the reading the tick sees has fallen again
    result = m.tick()
    assert result.status is Status.FAILURE and result.code is Failure.FORCE_TORQUE
    assert ft.limits.armed is None  # type: ignore[attr-defined]


def test_a_motion_that_ends_or_is_halted_disarms() -> None:
    arm, ft, clock = FakeArm(), FakeFT(), FakeClock()
    ft.limits = LimitGuard(clock.now)  # type: ignore[attr-defined]
    done = {"v": False}
    m = GuardedMotion("m", lambda: None, lambda: done["v"], arm, ft, clock, Guard(40.0, 4.0))
    m.tick()
    assert ft.limits.armed is not None  # type: ignore[attr-defined]
    done["v"] = True
    assert m.tick().status is Status.SUCCESS
    assert ft.limits.armed is None  # type: ignore[attr-defined]
    m.start()
    assert ft.limits.armed is not None  # type: ignore[attr-defined]
    m.halt()
    assert ft.limits.armed is None  # type: ignore[attr-defined]
