"""The recovery's let go after an aborted Align: a pad left pressed on the rim is moved off it
(the way the wrist is pushed) before the jaws open -- a 2F-85's tips travel along the fingers as
the jaws move, so opening on a pressed pad drives it into the part; a let go with nothing
pressing opens at once. Fake devices: the order of the commands is what is checked."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.devices import Devices
from drivers.pose import Pose
from skills.pivot import PickFromAbove, PivotFrame, PivotParams
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper
from tests.skills.twin import bushing


def _first_steps(pressed_n: float) -> tuple[FakeArm, list[str], float | None]:
    """Tick the recovery through its let go with ``pressed_n`` (N) on the wrist; the arm, the
    order of arm and jaw commands, and the jaws' width when the arm's first move began."""
    part = bushing()
    down = np.diag([1.0, -1.0, -1.0])  # fingers straight down
    arm = FakeArm(Pose(np.array([0.45, 0.0, 0.12]), down))
    gripper, ft, clock = FakeGripper(), FakeFT(), FakeClock()
    gripper._width = gripper._target = 0.058
    ft.value[2] = -pressed_n  # along the tool's z (fingers down): the part pushes the tool up
    frame = PivotFrame(part.section(gripper.finger_width), np.array([0.45, 0.0, 0.017]), 0.0, 0.0)
    params = PivotParams(l_a=0.65, alpha=0.3142)
    skill = PickFromAbove(frame, part, params, Devices(arm, gripper, ft, clock))
    order: list[str] = []
    width_at_move = None
    for _ in range(400):
        moved, opened = len(arm.commands), gripper._target
        skill.tick()
        if len(arm.commands) > moved:
            order.append("arm")
            if width_at_move is None:
                width_at_move = gripper.width()
        if gripper._target != opened:
            order.append("open")
        if skill.sequence.passed("let go"):
            break
        arm.tick()
        gripper.tick()
        clock.t += clock.dt
    return arm, order, width_at_move


def test_a_pressed_pad_is_moved_off_the_rim_before_the_jaws_open() -> None:
    arm, order, width = _first_steps(40.0)
    assert order[:2] == ["arm", "open"]
    # the jaws still shut on the wall as the arm drew back
    assert width is not None and width == pytest.approx(0.058)
    start, back = np.array([0.45, 0.0, 0.12]), arm.commands[0][1][-1].position  # type: ignore[index]
    ease = PivotParams(l_a=0.65, alpha=0.3142).ease_off
    assert back - start == pytest.approx([0.0, 0.0, ease])  # up: the way the part pushes it


def test_a_let_go_with_nothing_pressing_opens_at_once() -> None:
    _, order, _ = _first_steps(2.0)
    assert order[0] == "open"
