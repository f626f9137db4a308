"""Tick-level tests of Grasp, Tilt and the guards against fake devices."""

import math

import numpy as np
import pytest

from skills.mechanics.contact import Section, delta_round
from skills.motion import Devices, Guard
from skills.pivot import Grasp, PivotFrame, PivotParams, Tilt
from skills.status import Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run

SECTION = Section(0.034, 0.017, delta_round(0.034, 0.028, 0.020))
FRAME = PivotFrame(SECTION, np.array([0.5, 0.0, 0.017]), 0.0)
PARAMS = PivotParams(l_a=0.9, alpha=math.radians(16.3))


def devices(object_width=0.003):
    return {
        "arm": FakeArm(),
        "gripper": FakeGripper(object_width),
        "ft": FakeFT(),
        "clock": FakeClock(),
    }


def dev(d) -> Devices:
    return Devices(d["arm"], d["gripper"], d["ft"], d["clock"])


def make_grasp(d):
    return Grasp(FRAME, PARAMS, dev(d))


def test_grasp_opens_approaches_and_closes() -> None:
    d = devices()
    result, ticks = run(make_grasp(d), d)
    assert result.status is Status.SUCCESS, result.message
    kinds = [c[0] for c in d["arm"].commands]
    assert kinds == ["path", "path", "path"]  # above the open end, along the fingers, press
    at_grasp = d["arm"].commands[1][1][-1]
    assert np.allclose(at_grasp.position, FRAME.grasp_pose(0.9, PARAMS.alpha, 0.005).position)
    pressed = d["arm"].commands[2][1][-1]
    assert np.allclose(at_grasp.position - pressed.position, [0, 0, PARAMS.press_depth])
    assert d["gripper"].closed_on == pytest.approx(0.003)


def test_grasp_fails_when_the_fingers_close_on_nothing() -> None:
    d = devices(object_width=None)
    result, _ = run(make_grasp(d), d)
    assert result.status is Status.FAILURE and "closed on nothing" in result.message


def test_force_guard_stops_the_arm_within_one_tick() -> None:
    d = devices()
    grasp = make_grasp(d)

    def spike(i: int) -> None:
        if i == 6:
            d["ft"].value = np.array([0, 0, 200.0, 0, 0, 0])

    result, tick = run(grasp, d, on_tick=spike)
    assert tick == 6
    assert result.status is Status.FAILURE and "force-torque guard" in result.message
    assert d["arm"].stops >= 1


def test_timeout_stops_the_arm() -> None:
    d = devices()
    d["arm"].ticks_per_move = 10**9  # never arrives
    params = PivotParams(l_a=0.9, alpha=0.3, guard=Guard(timeout=0.5))
    grasp = Grasp(FRAME, params, dev(d))
    result, tick = run(grasp, d)
    assert result.status is Status.FAILURE and "timeout" in result.message
    # the limit is per motion: the jaws opened first (about 0.1 s), then the move timed out
    assert 0.5 < tick * d["clock"].dt < 0.7
    assert d["arm"].stops == 1


def test_grasp_refuses_an_opening_beyond_the_stroke() -> None:
    d = devices()
    d["gripper"].stroke = 0.05
    with pytest.raises(ValueError, match="jaw opening"):
        make_grasp(d)


def test_tilt_follows_the_arc() -> None:
    d = devices()
    grasp_pose = FRAME.grasp_pose(0.9, PARAMS.alpha, 0.005)
    d["arm"].pose = grasp_pose
    tilt = Tilt(FRAME, PARAMS, dev(d))
    result, _ = run(tilt, d)
    assert result.status is Status.SUCCESS
    path = d["arm"].commands[0][1]
    assert len(path) == 45
    assert np.allclose(path[-1].position, FRAME.tilt_pose(grasp_pose, math.pi / 2).position)
