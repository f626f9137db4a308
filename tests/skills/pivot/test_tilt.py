"""Tick-level tests of the Tilt (skills/pivot/tilt.py) against fake devices (no physics).

tests/skills/pivot/test_grasp.py already checks the free arc's shape (about P_c, past the tip-over
angle, fingertips off the floor) and the jaws' ease before the tip-over angle. Here: a fixed
``tilt_angle``, the located pivot, the limited squeeze, the compliant give along the fingers, the
settle after the arc, and failure (force guard, timeout) and halt mid-arc -- each stopping the arm.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from drivers.arm import MotionState
from drivers.devices import Devices
from drivers.parts import Section, delta_round
from skills.motion import Guard
from skills.pivot import PivotFrame, PivotParams, Tilt
from skills.status import Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run

SECTION = Section(0.034, 0.017, delta_round(0.034, 0.028, 0.020))
FRAME = PivotFrame(SECTION, np.array([0.5, 0.0, 0.017]), 0.0)
PARAMS = PivotParams(l_a=0.9, alpha=math.radians(16.3), locate_pivot=False)
GRASP = FRAME.grasp_pose(PARAMS.l_a, PARAMS.alpha, PARAMS.tip_offset)
OPENING = FRAME.opening(PARAMS.l_a, PARAMS.alpha)  # the jaw width where the grasp closed on H


def devices(width: float = OPENING) -> dict:
    d = {"arm": FakeArm(GRASP), "gripper": FakeGripper(0.003), "ft": FakeFT(),
         "clock": FakeClock()}
    d["gripper"]._width = width  # the grasp's closed opening
    return d


def dev(d: dict) -> Devices:
    return Devices(d["arm"], d["gripper"], d["ft"], d["clock"])


def record_servo(d: dict) -> list:
    targets: list = []
    servo = d["arm"].servo
    d["arm"].servo = lambda pose: (targets.append(pose), servo(pose))
    return targets


def test_a_fixed_tilt_angle_ends_the_arc_there_then_the_part_settles() -> None:
    d = devices()
    targets = record_servo(d)
    angle = math.radians(70.0)
    params = dataclasses.replace(PARAMS, tilt_angle=angle, settle=0.3)
    tilt = Tilt(FRAME, params, dev(d))
    progress: list[float] = []
    result, ticks = run(tilt, d, on_tick=lambda i: progress.append(tilt.arc.progress))
    assert result.status is Status.SUCCESS
    assert tilt.angle == angle and tilt.theta == pytest.approx(angle)
    end = FRAME.tilt_pose(GRASP, angle)
    assert np.allclose(targets[-1].position, end.position, atol=1e-9)
    assert np.allclose(targets[-1].rotation, end.rotation, atol=1e-9)
    # theta only grows along the arc
    assert all(b >= a for a, b in zip(progress, progress[1:], strict=False))
    # after the arc the Tilt waits for the wrist to read steady: nothing loads these fake
    # fingers, so the wait is its window, far shorter than `settle`
    arc_end = progress.index(1.0)
    waited = (ticks - arc_end) * d["clock"].dt
    assert waited == pytest.approx(params.stand_window, abs=3 * d["clock"].dt)
    assert waited < 0.3
    assert d["arm"].stops >= 1  # the streamed arc was ended with a stop


def test_the_pivot_is_located_from_where_the_grasp_closed_on_the_rim() -> None:
    # The jaws closed 5 mm narrower than planned: the part lies 3 mm nearer along -u, and so
    # does its far bottom corner, the centre of the arc.
    d = devices(width=OPENING - 0.005)
    targets = record_servo(d)
    params = dataclasses.replace(PARAMS, locate_pivot=True)
    tilt = Tilt(FRAME, params, dev(d))
    result, _ = run(tilt, d)
    assert result.status is Status.SUCCESS
    expected = FRAME.located(GRASP, OPENING - 0.005)
    shift = float((tilt.frame.center - FRAME.center) @ FRAME.u)
    assert shift < -0.001
    assert np.allclose(tilt.frame.center, expected.center)
    r0 = np.linalg.norm(GRASP.position - tilt.frame.pivot)
    for pose in targets[::25]:
        assert np.linalg.norm(pose.position - tilt.frame.pivot) == pytest.approx(r0, abs=1e-9)


def test_with_the_planned_opening_the_located_pivot_is_the_planned_one() -> None:
    d = devices()
    tilt = Tilt(FRAME, dataclasses.replace(PARAMS, locate_pivot=True), dev(d))
    result, _ = run(tilt, d)
    assert result.status is Status.SUCCESS
    assert np.allclose(tilt.frame.center, FRAME.center, atol=1e-9)


def test_the_squeeze_limits_how_far_the_jaws_may_close_along_the_arc() -> None:
    d = devices(width=0.055)
    closes: list[tuple] = []
    close = d["gripper"].close
    d["gripper"].close = lambda *a, **k: (closes.append((a, k)), close(*a, **k))
    params = dataclasses.replace(PARAMS, tilt_squeeze=0.002, tilt_ease=0.0)
    tilt = Tilt(FRAME, params, dev(d))
    result, _ = run(tilt, d)
    assert result.status is Status.SUCCESS
    assert len(closes) == 1  # once, when the arc starts
    args, kwargs = closes[0]
    assert args[0] == params.grip_force
    # the fake closes to the requested width (its object is thinner): 2 mm, not shut
    assert d["gripper"].width() == pytest.approx(0.053)


def test_without_a_squeeze_the_jaws_are_not_commanded_to_close() -> None:
    d = devices()
    closes: list = []
    d["gripper"].close = lambda *a, **k: closes.append(a)  # type: ignore[method-assign]
    result, _ = run(Tilt(FRAME, PARAMS, dev(d)), d)
    assert result.status is Status.SUCCESS and closes == []


def test_a_press_along_the_fingers_backs_the_tcp_off_at_most_tilt_backoff() -> None:
    d = devices()
    d["ft"].value = np.array([0.0, 0.0, -50.0, 0, 0, 0])  # fingers pressed onto the part
    tilt = Tilt(FRAME, PARAMS, dev(d))
    offsets: list[np.ndarray] = []
    result, _ = run(tilt, d, on_tick=lambda i: offsets.append(tilt.arc.offset.copy()))
    assert result.status is Status.SUCCESS
    norms = [float(np.linalg.norm(o)) for o in offsets]
    assert max(norms) == pytest.approx(PARAMS.tilt_backoff)  # it gave way, up to the limit
    assert max(norms) <= PARAMS.tilt_backoff + 1e-12
    assert offsets[-1][2] < 0 and np.allclose(offsets[-1][:2], 0.0)  # back along the fingers


def test_a_rigid_tilt_gives_no_way_and_a_light_press_gives_none_either() -> None:
    d = devices()
    d["ft"].value = np.array([0.0, 0.0, -50.0, 0, 0, 0])
    tilt = Tilt(FRAME, dataclasses.replace(PARAMS, tilt_backoff=0.0), dev(d))
    run(tilt, d)
    assert np.allclose(tilt.arc.offset, 0.0)

    d = devices()
    d["ft"].value = np.array([0.0, 0.0, -PARAMS.tilt_press + 1.0, 0, 0, 0])  # under the band
    tilt = Tilt(FRAME, PARAMS, dev(d))
    run(tilt, d)
    assert np.allclose(tilt.arc.offset, 0.0)


def arc_guard(tilt: Tilt) -> Guard:
    """The limits the arc runs under (however the skill derives them from its parameters)."""
    return tilt.arc.guarded.guard


def test_a_force_over_the_arc_guard_mid_arc_fails_the_tilt_and_stops_the_arm() -> None:
    d = devices()
    tilt = Tilt(FRAME, PARAMS, dev(d))
    over = arc_guard(tilt).max_force + 5.0

    def spike(i: int) -> None:
        if tilt.theta > 0.3:
            d["ft"].value = np.array([over, 0.0, 0.0, 0, 0, 0])

    result, _ = run(tilt, d, on_tick=spike)
    assert result.status is Status.FAILURE
    assert d["arm"].stops == 1 and d["arm"].state is MotionState.STOPPED
    assert 0.3 < tilt.theta < 0.4  # failed in the tick the force was read, part way up
    assert not tilt.eased  # never reached the tip-over angle


def test_a_force_just_under_the_arc_guard_on_a_stiff_axis_is_carried_through() -> None:
    d = devices()
    tilt = Tilt(FRAME, PARAMS, dev(d))
    d["ft"].value = np.array([arc_guard(tilt).max_force - 1.0, 0.0, 0.0, 0, 0, 0])
    result, _ = run(tilt, d)
    assert result.status is Status.SUCCESS
    assert np.allclose(tilt.arc.offset, 0.0)  # x does not give way (tilt_axes: z only)


def test_a_stalled_arc_times_out_and_stops_the_arm() -> None:
    d = devices()
    tilt = Tilt(FRAME, dataclasses.replace(PARAMS, tilt_speed=1e-4), dev(d))
    limit = arc_guard(tilt).timeout
    result, ticks = run(tilt, d, max_ticks=int(limit / d["clock"].dt) + 100)
    assert result.status is Status.FAILURE
    assert ticks * d["clock"].dt == pytest.approx(limit, abs=2 * d["clock"].dt)
    assert d["arm"].stops == 1 and tilt.theta < tilt.angle


def test_halt_mid_arc_stops_the_arm_and_streams_no_further_target() -> None:
    d = devices()
    targets = record_servo(d)
    tilt = Tilt(FRAME, PARAMS, dev(d))
    for _ in range(100):
        assert tilt.tick().status is Status.RUNNING
        d["clock"].t += d["clock"].dt
    assert 0.0 < tilt.arc.progress < 1.0
    streamed = len(targets)
    tilt.halt()
    assert d["arm"].stops == 1 and d["arm"].state is MotionState.STOPPED
    tilt.halt()  # a parent may halt twice: still nothing streamed after the first
    assert len(targets) == streamed


def test_the_arc_starts_from_the_measured_tool_pose_not_the_planned_grasp() -> None:
    d = devices()
    moved = dataclasses.replace(GRASP, position=GRASP.position + np.array([0.0, 0.0, 0.002]))
    d["arm"].pose = moved
    targets = record_servo(d)
    result, _ = run(Tilt(FRAME, PARAMS, dev(d)), d)
    assert result.status is Status.SUCCESS
    r = np.linalg.norm(moved.position - FRAME.pivot)
    assert np.linalg.norm(targets[0].position - FRAME.pivot) == pytest.approx(r, abs=1e-9)
    assert np.linalg.norm(targets[0].position - moved.position) < 1e-3


@pytest.mark.parametrize(
    ("rate_deg_s", "cap", "radius_rate"),
    [(30.0, 0.1, True), (180.0, 0.02, False)],
)
def test_the_arc_runs_at_the_parts_turning_rate_times_its_radius_up_to_the_cap(
    rate_deg_s: float, cap: float, radius_rate: bool
) -> None:
    d = devices()
    angle = math.radians(70.0)
    params = dataclasses.replace(
        PARAMS, tilt_angle=angle, settle=0.0, tilt_rate=math.radians(rate_deg_s), tilt_speed=cap
    )
    tilt = Tilt(FRAME, params, dev(d))
    run(tilt, d)
    radius = float(np.linalg.norm(GRASP.position - FRAME.pivot))
    expected = math.radians(rate_deg_s) * radius if radius_rate else cap
    assert tilt.arc.speed == pytest.approx(expected, rel=1e-9)
    assert tilt.arc.speed <= cap
