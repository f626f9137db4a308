"""Tick-level tests of Grasp, Tilt and the guards against fake devices."""

import dataclasses
import math

import numpy as np
import pytest

from drivers.devices import Devices
from drivers.parts import Section, delta_round
from skills.motion import Guard
from skills.pivot import Grasp, PivotFrame, PivotParams, Tilt
from skills.status import Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run

SECTION = Section(0.034, 0.017, delta_round(0.034, 0.028, 0.020))
FRAME = PivotFrame(SECTION, np.array([0.5, 0.0, 0.017]), 0.0)
PARAMS = PivotParams(l_a=0.9, alpha=math.radians(16.3))


def devices(object_width=0.055):
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


def test_grasp_opens_approaches_and_closes_keeping_s_put() -> None:
    d = devices()
    grasp = make_grasp(d)
    result, ticks = run(grasp, d)
    assert result.status is Status.SUCCESS, result.message
    kinds = [c[0] for c in d["arm"].commands]
    assert kinds == ["path", "path"]  # above the open end, then along the fingers
    at_grasp = d["arm"].commands[1][1][-1]
    planned = FRAME.grasp_pose(0.9, PARAMS.alpha, PARAMS.tip_offset)
    x = planned.rotation[:, 0]
    opening = FRAME.opening(0.9, PARAMS.alpha) + PARAMS.approach_clearance
    # the outer finger's pad (TCP + w/2 x) starts on S, pressed press_depth into it
    outer_start = at_grasp.position + 0.5 * opening * x
    outer_planned = planned.position + 0.5 * FRAME.opening(0.9, PARAMS.alpha) * x
    assert np.allclose(outer_start, outer_planned - [0, 0, PARAMS.press_depth], atol=1e-9)
    # closing: the TCP followed the outer finger, which stayed put (up to the lead)
    outer_end = d["arm"].pose.position + 0.5 * d["gripper"].width() * x
    lead = min(PARAMS.close_lead, 0.5 * PARAMS.press_depth / math.sin(PARAMS.alpha))
    assert np.linalg.norm(outer_end - outer_start) == pytest.approx(lead, abs=1e-9)
    assert d["gripper"].closed_on == pytest.approx(0.055)


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


def test_tilt_streams_the_arc_past_the_tip_angle_with_the_fingertips_off_the_floor() -> None:
    d = devices()
    grasp_pose = FRAME.grasp_pose(0.9, PARAMS.alpha, 0.005)
    d["arm"].pose = grasp_pose
    targets = []
    servo = d["arm"].servo
    d["arm"].servo = lambda pose: (targets.append(pose), servo(pose))
    params = dataclasses.replace(PARAMS, locate_pivot=False)
    tilt = Tilt(FRAME, params, dev(d))
    result, _ = run(tilt, d)
    assert result.status is Status.SUCCESS
    # past the tip-over angle, at most tilt_past_tip past it
    assert SECTION.tip_angle < tilt.angle <= SECTION.tip_angle + params.tilt_past_tip + 1e-9
    assert len(targets) > 100  # one target per control step, not one long move
    for pose in targets[::10]:  # every target lies on the arc about P_c
        r = np.linalg.norm(pose.position - FRAME.pivot)
        assert r == pytest.approx(np.linalg.norm(grasp_pose.position - FRAME.pivot), abs=1e-9)
    end = FRAME.tilt_pose(grasp_pose, tilt.angle)
    assert np.allclose(targets[-1].position, end.position)
    # the outer finger's back (the lowest corner) stays tilt_floor_clearance above the floor
    width = tilt.start_width + params.tilt_ease
    back = end.position + (0.5 * width + params.finger_thickness) * end.rotation[:, 0]
    back += params.tip_offset * end.rotation[:, 2]
    assert back[2] >= FRAME.floor_z + params.tilt_floor_clearance - 1e-9


def test_tilt_eases_the_jaws_once_just_before_the_tip_over_angle() -> None:
    d = devices()
    d["arm"].pose = FRAME.grasp_pose(0.9, PARAMS.alpha, 0.005)
    d["gripper"]._width = 0.055
    params = dataclasses.replace(PARAMS, locate_pivot=False)
    tilt = Tilt(FRAME, params, dev(d))
    widths: list[tuple[float, float]] = []
    run(tilt, d, on_tick=lambda i: widths.append((tilt.theta, d["gripper"].width())))
    ease_at = SECTION.tip_angle - params.ease_before_tip
    before = [w for th, w in widths if th < ease_at - 0.01]
    after = [w for th, w in widths if th > ease_at + 0.01]
    assert before and after
    assert max(before) == pytest.approx(0.055)  # the pinch held rigid up to there
    assert min(after) == pytest.approx(0.055 + params.tilt_ease)  # eased by tilt_ease, once
    assert tilt.eased
