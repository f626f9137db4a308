"""Tick-level tests of the in-hand Align (skills/pivot/align.py) against fake devices (no physics).

The Align starts where a Tilt to 90 deg leaves the tool (fingers along the floor, the inner one
over the rim) and must end fingers down, the wall pinched ``wall_depth`` below the rim, lifted.
The checks are on poses, commands, arm stops and statuses; the twin tests (test_pivot_twin,
test_slot_twin) cover it with physics.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.arm import MotionState
from drivers.devices import Devices
from skills.motion import wait
from skills.pivot import Align, PivotFrame, PivotParams
from skills.pivot.align import hole_grasp_rotation, pinched_span, turn_centre
from skills.status import Failure, Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run

PART = load_catalogue().get("bushing")
SECTION = PART.section(FakeGripper.finger_width)
FRAME = PivotFrame(SECTION, np.array([0.5, 0.0, 0.017]), 0.0)
PARAMS = PivotParams(l_a=0.9, alpha=math.radians(16.3))
GRASP = FRAME.grasp_pose(PARAMS.l_a, PARAMS.alpha, PARAMS.tip_offset)
START = FRAME.tilt_pose(GRASP, 0.5 * math.pi)  # where the Tilt leaves the tool
OPENING = FRAME.opening(PARAMS.l_a, PARAMS.alpha)
DOWN = np.array([0.0, 0.0, -1.0])


def devices(object_width: float | None = 0.003) -> dict:
    d = {"arm": FakeArm(START), "gripper": FakeGripper(object_width), "ft": FakeFT(),
         "clock": FakeClock()}
    d["gripper"]._width = OPENING
    return d


def dev(d: dict) -> Devices:
    return Devices(d["arm"], d["gripper"], d["ft"], d["clock"])


def index(align: Align, name: str) -> int:
    """The position of the step named ``name`` in the Align's sequence."""
    return [step.name for step in align.sequence.steps].index(name)


def nothing_at_the_pinch(d: dict, align: Align):  # type: ignore[no-untyped-def]
    """An on_tick that leaves the wall to the close on it and nothing to the pinch."""
    pinch = index(align, align.pinch_step)

    def on_tick(i: int) -> None:
        if align.sequence.index >= pinch:
            d["gripper"].object_width = None

    return on_tick


def record_servo(d: dict, align: Align | None = None) -> list:
    """Every streamed target, with the step in progress and the jaw opening when it was sent."""
    targets: list = []
    servo = d["arm"].servo

    def recording(pose) -> None:  # type: ignore[no-untyped-def]
        step = align.sequence.index if align is not None else -1
        targets.append((pose, step, d["gripper"].width()))
        servo(pose)

    d["arm"].servo = recording
    return targets


def test_align_turns_fingers_down_pinches_the_wall_below_the_rim_and_lifts() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    targets = record_servo(d, align)
    result, _ = run(align, d)
    assert result.status is Status.SUCCESS
    pose = d["arm"].pose
    assert np.allclose(pose.rotation[:, 2], DOWN, atol=1e-9)  # fingers straight down
    assert abs(pose.rotation[2, 0]) < 1e-9  # the closing line horizontal ...
    assert abs(pose.rotation[:, 0] @ FRAME.normal) < 1e-9  # ... in the pivot plane
    assert d["gripper"].object_detected()
    # down along the inner wall, streamed (compliant along the closing line), then the lift
    slides = [t for t, step, _ in targets if step == index(align, "slide into the hole")]
    assert len(slides) > 10
    assert all(np.allclose(t.position[:2], slides[0].position[:2]) for t in slides)
    slide = slides[-1]
    paths = [c[1][-1] for c in d["arm"].commands if c[0] == "path"]
    assert len(paths) == 1
    (lift,) = paths
    rim = FRAME.floor_z + PART.length
    tips = slide.position[2] - PARAMS.tip_offset
    assert tips == pytest.approx(rim - PARAMS.wall_depth)
    assert lift.position[2] - slide.position[2] == pytest.approx(PARAMS.lift_height)
    assert np.allclose(lift.position[:2], pose.position[:2])  # straight up


def test_the_turn_keeps_the_rim_contact_fixed_in_the_tool_and_in_the_world() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    targets = record_servo(d, align)
    run(align, d)
    turn = [t for t, step, _ in targets if step == 0]
    assert len(turn) > 50  # streamed one control step at a time
    hook = FRAME.hook_depth(PARAMS.l_a, PARAMS.alpha)
    c = turn_centre(START, OPENING, hook, PARAMS.tip_offset)
    assert np.allclose(align.centre, c)
    local = START.rotation.T @ (c - START.position)
    for pose in turn[::10]:
        assert np.allclose(pose.rotation.T @ (c - pose.position), local, atol=1e-9)
    # the turn ends with the fingers down, by the angle it announced
    assert np.allclose(turn[-1].rotation[:, 2], DOWN, atol=1e-6)
    z0 = START.rotation[:, 2]
    assert abs(align.turn_angle) == pytest.approx(math.acos(float(z0 @ DOWN)))


def test_the_jaws_centre_on_the_wall_then_ease_and_pinch_with_the_inner_pad_kept() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    targets = record_servo(d, align)
    result, _ = run(align, d)
    assert result.status is Status.SUCCESS
    close, ease = index(align, "close on the wall"), index(align, "ease off the outer wall")
    pinch = index(align, align.pinch_step)
    # the close on the wall moves no arm: the jaws close symmetrically about a still TCP
    assert not [t for t, step, _ in targets if step == close]
    assert close + 1 == ease and not [c for c in d["arm"].commands if c[0] != "path"]
    # then the jaws open twice the wall gap from where they stalled, and pinch
    widths = {round(w, 9) for _, step, w in targets if step in (ease, pinch)}
    assert {0.003, round(0.003 + 2 * PARAMS.wall_gap, 9)} <= widths
    # the ease and the pinch keep the inner pad's face where it was while the jaws moved
    for step in (ease, pinch):
        pads = [t.position - 0.5 * w * t.rotation[:, 0] for t, s, w in targets if s == step]
        assert len(pads) > 1
        for pad in pads:
            assert np.allclose(pad, pads[0], atol=1e-9)


def test_jaws_that_close_past_the_wall_fail_as_a_miss_before_the_slide() -> None:
    d = devices(object_width=None)
    align = Align(FRAME, PART, PARAMS, dev(d))
    result, _ = run(align, d)
    assert result.status is Status.FAILURE and result.code is Failure.MISSED
    assert "no wall between the fingers" in result.message
    assert align.sequence.index == index(align, "close on the wall")
    assert not [c for c in d["arm"].commands if c[0] == "path"]  # no lift


def test_a_grip_deeper_than_the_part_allows_stops_floor_clearance_above_the_floor() -> None:
    d = devices()
    params = dataclasses.replace(PARAMS, wall_depth=PART.length)  # would touch the floor
    align = Align(FRAME, PART, params, dev(d))
    targets = record_servo(d, align)
    result, _ = run(align, d)
    assert result.status is Status.SUCCESS
    slide = [t for t, step, _ in targets if step == index(align, "slide into the hole")][-1]
    tips = slide.position[2] - params.tip_offset
    assert tips == pytest.approx(FRAME.floor_z + params.floor_clearance)


def test_a_pinch_on_nothing_fails_before_the_lift_and_the_arm_is_not_lifted() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    targets = record_servo(d, align)
    result, _ = run(align, d, on_tick=nothing_at_the_pinch(d, align))
    assert result.status is Status.FAILURE
    assert not [c for c in d["arm"].commands if c[0] == "path"]  # the lift never commanded
    slide = [t for t, step, _ in targets if step == index(align, "slide into the hole")][-1]
    assert d["arm"].pose.position[2] == pytest.approx(slide.position[2])


@pytest.mark.parametrize("held", ["outer", "wall"])
def test_a_pinch_across_the_parts_outside_is_a_miss_a_pinch_of_the_wall_is_not(held) -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    pinch = index(align, align.pinch_step)
    outer, inner = pinched_span(PART, FakeGripper.finger_width)
    # the jaws stall on the whole part (both pads outside it), or on the wall a little wide
    width = PART.outer if held == "outer" else outer - inner + 0.5 * PARAMS.pinch_width_margin

    def on_tick(i: int) -> None:
        if align.sequence.index >= pinch:
            d["gripper"].object_width = width

    result, _ = run(align, d, on_tick=on_tick)
    if held == "outer":
        assert result.status is Status.FAILURE and result.code is Failure.MISSED
        assert "no finger in the hole" in result.message
        assert not [c for c in d["arm"].commands if c[0] == "path"]  # never lifted
    else:
        assert result.status is Status.SUCCESS, result.message


def test_the_pinch_is_checked_by_its_name_when_steps_are_inserted_before_it() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    g = PARAMS.guard
    extra = [wait(f"pause {k}", dev(d), g, 0.01) for k in range(3)]
    align.sequence.steps[1:1] = extra  # the pinch moves three places on
    result, _ = run(align, d, on_tick=nothing_at_the_pinch(d, align))
    assert result.status is Status.FAILURE and result.code is Failure.MISSED
    assert align.sequence.current == align.lift_step  # failed after the pinch, before the lift
    assert not [c for c in d["arm"].commands if c[0] == "path"]  # no lift commanded


def test_a_pad_landing_on_the_rim_trips_the_descent_guard_and_stops_the_arm() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    slide_at = index(align, "slide into the hole")
    slide = align.sequence.steps[slide_at]
    general = align.sequence.steps[0].guard
    assert slide.guard.max_force < general.max_force  # the descent is guarded more tightly
    push = 0.5 * (slide.guard.max_force + general.max_force)

    def on_tick(i: int) -> None:
        d["ft"].value = np.array(
            [0, 0, push if align.sequence.index == slide_at else 0.0, 0, 0, 0]
        )

    result, _ = run(align, d, on_tick=on_tick)
    assert result.status is Status.FAILURE
    assert align.sequence.index == slide_at
    assert d["arm"].stops >= 1 and d["arm"].state is MotionState.STOPPED
    assert not [c for c in d["arm"].commands if c[0] == "path"]  # no lift


def test_the_same_push_during_the_turn_is_within_its_guard() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    slide = align.sequence.steps[index(align, "slide into the hole")]
    turn = align.sequence.steps[0]
    push = 0.5 * (slide.guard.max_force + turn.guard.max_force)

    def on_tick(i: int) -> None:  # along tool y: no give, so the turn is unchanged
        d["ft"].value = np.array([0, push if align.sequence.index == 0 else 0.0, 0, 0, 0, 0])

    result, _ = run(align, d, on_tick=on_tick)
    assert result.status is Status.SUCCESS


def test_a_push_on_the_closing_line_during_the_turn_gives_way_a_few_millimetres_only() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    offsets: list[np.ndarray] = []

    def on_tick(i: int) -> None:
        d["ft"].value = np.array([20.0 if align.sequence.index == 0 else 0.0, 0, 0, 0, 0, 0])
        offsets.append(align.turn.offset.copy())

    result, _ = run(align, d, on_tick=on_tick)
    assert result.status is Status.SUCCESS
    largest = max(float(np.linalg.norm(o)) for o in offsets)
    assert 0.001 < largest <= align.turn.compliance.limit + 1e-12
    assert all(abs(o[1]) < 1e-12 and abs(o[2]) < 1e-12 for o in offsets)  # x only


def test_halt_mid_turn_stops_the_arm_and_nothing_more_is_streamed() -> None:
    d = devices()
    align = Align(FRAME, PART, PARAMS, dev(d))
    targets = record_servo(d, align)
    for _ in range(60):
        assert align.tick().status is Status.RUNNING
        d["clock"].t += d["clock"].dt
    assert align.sequence.index == 0 and 0.0 < align.turn.progress < 1.0
    n = len(targets)
    align.halt()
    assert d["arm"].stops == 1 and d["arm"].state is MotionState.STOPPED
    assert len(targets) == n and not d["arm"].commands


def test_halt_mid_slide_stops_the_arm() -> None:
    d = devices()
    d["arm"].ticks_per_move = 1000
    align = Align(FRAME, PART, PARAMS, dev(d))
    for _ in range(2000):
        align.tick()
        d["arm"].tick()
        d["gripper"].tick()
        d["clock"].t += d["clock"].dt
        if align.sequence.index == index(align, "slide into the hole") and (
            align.slide.progress > 0.1
        ):
            break
    assert align.sequence.index == index(align, "slide into the hole")
    assert align.slide.progress < 1.0
    stops = d["arm"].stops
    align.halt()
    assert d["arm"].stops == stops + 1 and d["arm"].state is MotionState.STOPPED


def test_a_frame_source_is_read_when_the_align_starts_not_when_it_is_built() -> None:
    d = devices()
    calls: list[int] = []

    def source() -> PivotFrame:
        calls.append(1)
        return FRAME

    align = Align(source, PART, PARAMS, dev(d))
    assert calls == []
    align.tick()
    assert calls == [1]
    result, _ = run(align, d)
    assert result.status is Status.SUCCESS and calls == [1]


# ------------------------------------------------------------------------------- helpers
def test_pinched_span_of_a_round_hole_is_the_chord_a_pad_touches() -> None:
    outer, inner = pinched_span(PART, 0.020)
    assert outer == pytest.approx(0.5 * PART.outer)
    assert inner == pytest.approx(0.5 * math.sqrt(PART.hole**2 - 0.020**2))
    square = dataclasses.replace(PART, hole_shape="rectangle")
    assert pinched_span(square, 0.020)[1] == pytest.approx(0.5 * PART.hole)
    wide_pad = pinched_span(PART, 1.0)  # wider than the hole: the pad touches on the axis
    assert wide_pad[1] == 0.0


@pytest.mark.parametrize("x", [(1.0, 0.0, 0.0), (0.3, -0.7, 0.5), (-1.0, 1.0, -2.0)])
def test_hole_grasp_rotation_points_the_fingers_down_closing_along_the_horizontal(x) -> None:
    r = hole_grasp_rotation(np.array(x))
    assert np.allclose(r.T @ r, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    assert np.allclose(r[:, 2], DOWN)
    h = np.array([x[0], x[1], 0.0]) / math.hypot(x[0], x[1])
    assert np.allclose(r[:, 0], h)
