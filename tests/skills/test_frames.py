"""A step that looks: inline for the twin's camera, off the tick for a streaming camera, and a
failed capture fails the step as a device does."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from drivers.camera import Frame, Intrinsics
from drivers.devices import Devices
from drivers.pose import Pose
from skills.frames import frame_step
from skills.motion import Guard
from skills.status import Failure, Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper


class Cam:
    """A camera whose ``capture`` waits for ``release`` (a frame period, say)."""

    def __init__(self, background: bool) -> None:
        self.captures_in_background = background
        self.release = threading.Event()
        self.captures = 0
        self.error: Exception | None = None

    def intrinsics(self) -> Intrinsics:
        return Intrinsics(width=4, height=3, fx=1.0, fy=1.0, cx=2.0, cy=1.5)

    def tool_T_camera(self) -> Pose:
        return Pose(np.zeros(3), np.eye(3))

    def capture(self) -> Frame:
        assert self.release.wait(10.0), "the test never released the frame"
        self.captures += 1
        if self.error is not None:
            raise self.error
        return Frame(rgb=np.zeros((3, 4, 3), np.uint8), depth=np.ones((3, 4), np.float32),
                     stamp=0.0)


def _devices(cam: Cam) -> Devices:
    return Devices(FakeArm(Pose(np.array([0.4, 0.0, 0.3]))), FakeGripper(), FakeFT(),
                   FakeClock(), cam)  # type: ignore[arg-type]


def _step(dev: Devices, seen: list[float], failed=None):  # type: ignore[no-untyped-def]
    return frame_step("look", dev, Guard(60.0, 8.0, 5.0),
                      lambda frame, pose: float(frame.depth.mean()), seen.append, failed,
                      Failure.NOTHING_FOUND)


def test_a_streaming_camera_is_waited_for_off_the_tick() -> None:
    cam = Cam(background=True)
    seen: list[float] = []
    step = _step(_devices(cam), seen)
    # The capture is held: were it on the tick, this tick would not return until released.
    assert step.tick().status is Status.RUNNING
    assert step.tick().status is Status.RUNNING and seen == []
    cam.release.set()
    for _ in range(500):
        result = step.tick()
        if result.status is not Status.RUNNING:
            break
        threading.Event().wait(0.01)
    assert result.status is Status.SUCCESS and seen == [1.0] and cam.captures == 1


def test_the_twins_camera_is_captured_inline_and_judged_on_the_same_tick() -> None:
    cam = Cam(background=False)
    cam.release.set()
    seen: list[float] = []
    step = _step(_devices(cam), seen, failed=lambda: "nothing there" if seen[-1] > 0.5 else None)
    result = step.tick()
    assert result.status is Status.FAILURE and result.code is Failure.NOTHING_FOUND
    assert "nothing there" in result.message and seen == [1.0]


@pytest.mark.parametrize("background", [True, False])
def test_a_capture_that_times_out_fails_the_step_as_a_lost_device(background: bool) -> None:
    cam = Cam(background)
    cam.error = TimeoutError("D435: no depth+colour frame within 1000 ms")
    cam.release.set()
    step = _step(_devices(cam), [])
    for _ in range(500):
        result = step.tick()
        if result.status is not Status.RUNNING:
            break
        threading.Event().wait(0.01)
    assert result.status is Status.FAILURE and result.code is Failure.DEVICE_LOST
    assert "no depth+colour frame" in result.message
