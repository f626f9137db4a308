"""Tick-level tests of Grasp, Tilt and the guards against fake devices."""

import dataclasses
import math

import numpy as np
import pytest

from drivers.devices import Devices
from drivers.parts import Section, delta_round
from skills.motion import Guard
from skills.pivot import Grasp, PivotFrame, PivotParams, Tilt
from skills.pivot.grasp import pinch_press
from skills.status import Failure, Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run

SECTION = Section(0.034, 0.017, delta_round(0.034, 0.028, 0.020))
FRAME = PivotFrame(SECTION, np.array([0.5, 0.0, 0.017]), 0.0)
PARAMS = PivotParams(l_a=0.9, alpha=math.radians(16.3))


def devices(object_width=0.055, closing_speed=None):
    """Fakes; ``closing_speed`` (m/s): the jaws move at it (None: in one tick)."""
    gripper = FakeGripper(object_width)
    gripper.step = None if closing_speed is None else closing_speed * 0.008
    return {
        "arm": FakeArm(),
        "gripper": gripper,
        "ft": FakeFT(),
        "clock": FakeClock(),
    }


def dev(d) -> Devices:
    return Devices(d["arm"], d["gripper"], d["ft"], d["clock"])


def make_grasp(d):
    return Grasp(FRAME, PARAMS, dev(d))


def s_top(dz: float = 0.0) -> float:
    """Height (m) of the part's top surface where S lies: the frame's, ``dz`` off."""
    return FRAME.floor_z + 2.0 * SECTION.b + dz


def surface(d, grasp: Grasp, top: float, stiffness: float = 20000.0):
    """An ``on_tick`` hook: the part's top at ``top`` pushes back on the outer fingertip as a
    spring of ``stiffness`` (N/m) once the tip is below it, and holds a force-mode descent
    where it pushes with the touch force."""
    arm, ft, gripper = d["arm"], d["ft"], d["gripper"]
    x, z = grasp.rotation[:, 0], grasp.rotation[:, 2]

    def hook(_: int) -> None:
        pose = arm.tool_pose()
        width = gripper.width()
        tip = pose.position + 0.5 * width * x + (PARAMS.tip_offset + gripper.tip_advance(width)) * z
        depth = top - float(tip[2])
        push = stiffness * depth if depth > 0 else 0.0
        arm.blocked = push >= PARAMS.touch_force  # the descent goes on until it feels S
        ft.value = np.concatenate([pose.rotation.T @ np.array([0.0, 0.0, push]), np.zeros(3)])

    return hook


def test_grasp_feels_s_where_it_is_and_closes_pressing_it() -> None:
    # The part's top lies 1.5 mm lower than the frame says (a height error the camera left).
    d = devices(closing_speed=0.05)
    grasp = make_grasp(d)
    top = s_top(-0.0015)
    result, _ = run(grasp, d, on_tick=surface(d, grasp, top))
    assert result.status is Status.SUCCESS, result.message
    kinds = [c[0] for c in d["arm"].commands]
    # above the open end, down to the pre-approach, to the standoff, feel S
    assert kinds == ["path", "path", "path", "force"]
    # each leg its own move, ending where the next begins: over the pre-approach pose, then on it
    over, down = d["arm"].commands[0][1], d["arm"].commands[1][1]
    assert len(over) == 1 and len(down) == 1
    assert down[0].position[:2] == pytest.approx(over[0].position[:2], abs=1e-9)
    assert float(over[0].position[2]) >= float(down[0].position[2]) + PARAMS.approach_height - 1e-9
    # the height was measured where the tip met S (within the spring's give at the touch force)
    assert grasp.s_height == pytest.approx(top, abs=2 * PARAMS.touch_force / 20000.0)
    assert grasp.frame.floor_z == pytest.approx(FRAME.floor_z - 0.0015, abs=0.0005)
    # the arm pressed S with what the pinch needs (at least half of it when the jaws settled)
    assert grasp.press > PARAMS.touch_force
    pushed = float(d["arm"].pose.rotation @ d["ft"].value[:3] @ np.array([0.0, 0.0, 1.0]))
    assert pushed >= 0.5 * grasp.press
    # closing: the TCP followed half the closing (the outer pad stays on S up to the lead)
    x = grasp.rotation[:, 0]
    pressed = -grasp._press_offset * np.array([0.0, 0.0, 1.0])  # the press moved it down
    moved = (d["arm"].pose.position - grasp._touched.position - pressed) @ x
    closing = grasp._closed_from - d["gripper"].width()
    assert moved == pytest.approx(0.5 * closing + min(PARAMS.close_lead, 0.5 * closing), abs=1e-9)
    assert d["gripper"].closed_on == pytest.approx(0.055)


def test_grasp_fails_as_a_miss_when_there_is_no_top_surface() -> None:
    d = devices(closing_speed=0.05)
    grasp = make_grasp(d)
    far_below = s_top(-0.05)
    result, _ = run(grasp, d, on_tick=surface(d, grasp, far_below))
    assert result.status is Status.FAILURE and result.code is Failure.MISSED
    assert grasp.s_height is None


def test_grasp_fails_as_a_miss_when_the_fingers_close_on_nothing() -> None:
    d = devices(object_width=None, closing_speed=0.05)
    grasp = make_grasp(d)
    result, _ = run(grasp, d, on_tick=surface(d, grasp, s_top()))
    assert result.status is Status.FAILURE and result.code is Failure.MISSED
    assert d["gripper"].width() < grasp.opening - PARAMS.rim_tolerance


@pytest.mark.parametrize(("past", "ok"), [(0.009, True), (0.015, False)])
def test_jaws_that_follow_a_turning_part_past_the_rim_are_a_grasp_within_the_rim_tolerance(
    past: float, ok: bool
) -> None:
    # A light part turning about G under the pinch lets the jaws close past the planned rim
    # contact before they stall on it: 9 mm past (over Align's 6 mm wall tolerance, within the
    # Grasp's 12 mm) is a grasp, 15 mm past is a miss.
    opening = FRAME.opening(PARAMS.l_a, PARAMS.alpha)
    assert PARAMS.width_tolerance < 0.009 < PARAMS.rim_tolerance < 0.015
    d = devices(object_width=opening - past, closing_speed=0.05)
    grasp = make_grasp(d)
    result, _ = run(grasp, d, on_tick=surface(d, grasp, s_top()))
    if ok:
        assert result.status is Status.SUCCESS, result.message
    else:
        assert result.status is Status.FAILURE and result.code is Failure.MISSED
        assert "past the rim" in result.message


def settled_reading(d, grasp: Grasp, hook, scale):
    """``hook``, with the wrist's reading scaled by ``scale(i)`` on each tick ``i`` once the
    closed fingers stand still (a contact that rings, or an outer finger that let S go)."""
    ft, gripper = d["ft"], d["gripper"]

    def wrapped(i: int) -> None:
        hook(i)
        if grasp._touched is not None and not gripper.moving():
            ft.value = ft.value * scale(i)

    return wrapped


@pytest.mark.parametrize("phase", [0, 1])
def test_grasp_confirms_the_press_from_its_mean_while_settled_not_one_ringing_sample(
    phase: int,
) -> None:
    # The press at S swings between 1.7 and 0.3 of itself tick by tick once the jaws stopped:
    # whichever sample comes last, its mean holds S.
    d = devices(closing_speed=0.05)
    grasp = make_grasp(d)
    hook = surface(d, grasp, s_top())
    result, _ = run(grasp, d, on_tick=settled_reading(
        d, grasp, hook, lambda i: 1.7 if (i + phase) % 2 else 0.3))
    assert result.status is Status.SUCCESS, result.message
    assert grasp.settled_press >= PARAMS.press_confirm * grasp.press


def test_grasp_fails_as_a_miss_when_s_reads_unpressed_all_the_while_settled() -> None:
    d = devices(closing_speed=0.05)
    grasp = make_grasp(d)
    hook = surface(d, grasp, s_top())
    result, _ = run(grasp, d, on_tick=settled_reading(d, grasp, hook, lambda i: 0.1))
    assert result.status is Status.FAILURE and result.code is Failure.MISSED
    assert d["gripper"].object_detected()  # the jaws held: it was the press that failed
    assert grasp.settled_press < PARAMS.press_confirm * grasp.press


def test_pinch_press_is_what_friction_alone_cannot_hold() -> None:
    # F (cos a / mu - sin a): 20 N at 16.3 deg with mu 0.5 needs 32.8 N; a high friction none.
    assert pinch_press(20.0, math.radians(16.3), 0.5) == pytest.approx(
        20.0 * (math.cos(math.radians(16.3)) / 0.5 - math.sin(math.radians(16.3)))
    )
    assert pinch_press(20.0, math.radians(60.0), 2.0) == 0.0


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
    params = dataclasses.replace(PARAMS, locate_pivot=False, tilt_ease=0.003)
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
