"""The look's last view turned to the yaw the next skill holds the tool at, so the wrist turns in
the look's fast move between views and not in the Grasp's slower approach."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.camera import Intrinsics
from drivers.devices import Devices
from drivers.parts import Section
from drivers.pose import Pose
from skills.perception.bin_parts import Detection
from skills.perception.look import TURN_PATH, Look, camera_over, tool_yaw
from skills.pivot.clearance import likely_grasp_rotation
from skills.pivot.frame import PivotFrame
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper

#: a wrist camera off the tool's axis, as the cell's mount is (m)
MOUNT = Pose(np.array([0.0, 0.08, 0.03]), np.eye(3))


class _Camera:
    def tool_T_camera(self) -> Pose:
        return MOUNT

    def intrinsics(self) -> Intrinsics:  # a D435's colour stream at 640 x 480
        return Intrinsics(640, 480, 615.0, 615.0, 320.0, 240.0)


def _devices() -> Devices:
    return Devices(FakeArm(Pose(np.array([0.4, 0.0, 0.3]))), FakeGripper(), FakeFT(),
                   FakeClock(), _Camera())  # type: ignore[arg-type]


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.0, math.pi])
def test_the_turned_view_keeps_the_camera_over_the_point_and_looking_down(yaw: float) -> None:
    pose = camera_over((0.5, -0.1), 0.25, _devices(), yaw)
    optical = (pose @ MOUNT).position
    assert np.allclose(optical, [0.5, -0.1, 0.25])
    assert np.allclose(pose.rotation[:, 2], [0.0, 0.0, -1.0])
    assert tool_yaw(pose.rotation) == pytest.approx(_wrap(yaw), abs=1e-12)


def _frame(yaw: float, x: float = 0.5) -> PivotFrame:
    return PivotFrame(Section(a=0.03, b=0.02, delta=0.004), np.array([x, 0.0, 0.02]), yaw)


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5])
def test_the_grasps_yaw_faces_from_the_open_end_back_along_the_part(yaw: float) -> None:
    rotation = _frame(yaw).grasp_rotation(math.radians(30.0))
    # the closing line runs from the inner finger (in the hole) to the outer one on the top
    assert tool_yaw(rotation) == pytest.approx(_wrap(yaw + math.pi), abs=1e-9)


def test_a_tube_is_expected_from_its_outward_end_a_one_ended_part_from_its_open_end() -> None:
    inward = _frame(math.pi)  # open end towards the robot's base at the origin
    alpha = math.radians(30.0)
    tube = likely_grasp_rotation(inward, alpha, open_ends=2)
    one_ended = likely_grasp_rotation(inward, alpha, open_ends=1)
    assert tool_yaw(tube) == pytest.approx(math.pi, abs=1e-9)  # from the far end, x = -u
    assert tool_yaw(one_ended) == pytest.approx(0.0, abs=1e-9)
    outward = _frame(0.0)
    assert np.allclose(likely_grasp_rotation(outward, alpha, 2), outward.grasp_rotation(alpha))


def _detection(yaw: float) -> Detection:
    return Detection(
        center=np.array([0.45, 0.05, 0.02]), yaw=yaw, length=0.06, outer=0.04,
        part="bushing", open_end=np.array([0.48, 0.05, 0.02]), open_end_seen=True,
        confidence=1.0, pixels=500,
    )


def _step(look: Look, name: str):  # type: ignore[no-untyped-def]
    return next(step for step in look.sequence.steps if step.name == name)


def _close_view(grip_yaw: object) -> Pose:
    dev = _devices()
    look = Look(dev, [], (0.3, 0.7, -0.2, 0.2), (0.5, 0.0), (0.3, 0.0),  # type: ignore[arg-type]
                grip_yaw=grip_yaw)  # type: ignore[arg-type]
    look.result = _detection(0.3)
    _step(look, "camera over the part").start()
    kind, waypoints = dev.arm.commands[-1]  # type: ignore[attr-defined]
    assert kind == "path"
    return waypoints[-1]  # type: ignore[no-any-return]


def test_the_close_view_is_turned_to_the_next_skills_yaw() -> None:
    turned = _close_view(lambda d: d.yaw + math.pi)
    assert tool_yaw(turned.rotation) == pytest.approx(_wrap(0.3 + math.pi), abs=1e-9)
    assert np.allclose((turned @ MOUNT).position[:2], [0.45, 0.05])


def test_without_a_grip_yaw_the_close_view_keeps_the_look_s_own_yaw() -> None:
    plain = _close_view(None)
    assert tool_yaw(plain.rotation) == pytest.approx(0.0, abs=1e-12)


def test_a_turned_close_view_is_slowed_to_the_turn_rate() -> None:
    """Half a turn over 0.25 m of path at the look's 0.25 m/s would turn the wrist's last joint
    past its pi rad/s (the twin's arm stopped there): the move is timed by its turn."""
    dev = _devices()
    look = Look(dev, [], (0.3, 0.7, -0.2, 0.2), (0.5, 0.0), (0.3, 0.0),  # type: ignore[arg-type]
                grip_yaw=lambda d: d.yaw + math.pi)
    look.result = _detection(0.3)
    _step(look, "camera over the part").start()
    target = dev.arm.commands[-1][1][-1]  # type: ignore[attr-defined, index]
    distance, angle = Pose(np.array([0.4, 0.0, 0.3])).distance(target)
    p = look.params
    assert angle > math.radians(150.0)
    path = max(distance, TURN_PATH * angle)  # what the arm times the move by
    assert dev.arm.speeds[-1] == pytest.approx(min(p.turn_speed, path * p.turn_rate / angle))
    assert angle / p.turn_rate <= path / dev.arm.speeds[-1] + 1e-9


def test_the_turn_path_is_the_arms_own() -> None:
    """The look times a turning move as the arm does; a skill may not import the UR5's
    driver, so the one figure is held equal here."""
    from drivers.ur5.kinematics import ROTATION_LENGTH

    assert TURN_PATH == ROTATION_LENGTH


@pytest.mark.parametrize("step", ["camera over the bin", "camera beyond its end"])
def test_every_view_move_that_turns_the_tool_is_slowed_to_the_turn_rate(step: str) -> None:
    """After a drag the tool starts turned to the part; the way up to the wide view at the
    look's speed ran the wrist into the UR5's joint speed limit (the twin's arm faulted)."""
    dev = _devices()  # the tool starts half a turn from the look's own (pointing up)
    look = Look(dev, [], (0.3, 0.7, -0.2, 0.2), (0.5, 0.0), (0.3, 0.0))  # type: ignore[arg-type]
    look.result = _detection(0.3)
    _step(look, step).start()
    target = dev.arm.commands[-1][1][-1]  # type: ignore[attr-defined, index]
    distance, angle = Pose(np.array([0.4, 0.0, 0.3])).distance(target)
    p = look.params
    assert angle > math.radians(150.0)
    path = max(distance, TURN_PATH * angle)
    assert dev.arm.speeds[-1] == pytest.approx(min(p.speed, path * p.turn_rate / angle))
    assert dev.arm.speeds[-1] < p.speed  # slowed, not at the look's speed
