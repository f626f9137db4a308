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


def _first_steps(pressed_n: float) -> tuple[FakeArm, list[tuple[str, float]]]:
    """Tick the recovery through its let go with ``pressed_n`` (N) on the wrist; the arm and
    the commands in order: ("arm", jaw width then) or ("jaws", the width asked)."""
    part = bushing()
    down = np.diag([1.0, -1.0, -1.0])  # fingers straight down
    arm = FakeArm(Pose(np.array([0.45, 0.0, 0.12]), down))
    gripper, ft, clock = FakeGripper(), FakeFT(), FakeClock()
    gripper._width = gripper._target = 0.058
    ft.value[2] = -pressed_n  # along the tool's z (fingers down): the part pushes the tool up
    log: list[tuple[str, float]] = []
    move_path, open_ = arm.move_path, gripper.open

    def logged_move(waypoints, speed, acceleration):  # type: ignore[no-untyped-def]
        log.append(("arm", gripper.width()))
        move_path(waypoints, speed, acceleration)

    def logged_open(width=None, speed=0.1):  # type: ignore[no-untyped-def]
        log.append(("jaws", gripper.stroke if width is None else width))
        open_(width, speed)

    arm.move_path, gripper.open = logged_move, logged_open  # type: ignore[method-assign]
    frame = PivotFrame(part.section(gripper.finger_width), np.array([0.45, 0.0, 0.017]), 0.0, 0.0)
    params = PivotParams(l_a=0.65, alpha=0.3142)
    skill = PickFromAbove(frame, part, params, Devices(arm, gripper, ft, clock))
    for _ in range(400):
        skill.tick()
        if skill.sequence.passed("let go"):
            break
        arm.tick()
        gripper.tick()
        clock.t += clock.dt
    return arm, log


def test_a_pressed_pad_is_moved_off_the_rim_before_the_jaws_open() -> None:
    arm, log = _first_steps(40.0)
    # the jaws held where they are, the arm off the part with the jaws still shut, then open
    assert [k for k, _ in log[:3]] == ["jaws", "arm", "jaws"]
    assert log[0][1] == pytest.approx(0.058) and log[1][1] == pytest.approx(0.058)
    assert log[2][1] > 0.058
    start, off = np.array([0.45, 0.0, 0.12]), arm.commands[0][1][-1].position  # type: ignore[index]
    ease = PivotParams(l_a=0.65, alpha=0.3142).ease_off
    assert off - start == pytest.approx([0.0, 0.0, ease])  # up: the way the part pushes it


def test_a_let_go_with_nothing_pressing_opens_at_once() -> None:
    _, log = _first_steps(2.0)
    assert log[0][0] == "jaws" and log[0][1] > 0.058
