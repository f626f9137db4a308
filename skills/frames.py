"""A camera frame, and what a skill computes from it, as a step that never blocks a tick.

Why: a real D435's ``capture()`` waits for a pair exposed after the call (one to two frame
periods: 33-66 ms at 30 fps, 170-330 ms for the emulated camera at 6 fps), and the detection on
it takes 100-200 ms more. Inside one tick that stalled ``cell run``'s control loop for up to
1.2 s (measured against ``cell emulate``), with every guard blind meanwhile. So where the camera
streams in real time (``Camera.captures_in_background``: the D435 driver) the capture and the
computation run on a worker thread, and the step stays RUNNING under its guard until they are
done. The twin's camera renders the world the tick is stepping (PyBullet is not thread-safe, and
simulated time stands still during a tick), so there both run inline, as before.

The arm's pose is read on the tick thread when the step starts: every capturing step starts with
the arm at rest, and the frame is exposed after that (see the D435 driver's ``capture``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

from drivers.camera import Camera, Frame
from drivers.devices import Devices
from drivers.pose import Pose
from skills.motion import Failed, Guard, GuardedMotion
from skills.offtick import OffTick
from skills.status import Failure

T = TypeVar("T")


class FrameJob(Generic[T]):
    """One ``capture()`` and ``work(frame, world_T_camera)``; inline or on a worker thread
    (:class:`skills.offtick.OffTick`), as the camera streams."""

    def __init__(self, camera: Camera, arm_pose: Callable[[], Pose],
                 work: Callable[[Frame, Pose], T]) -> None:
        self._camera, self._arm_pose, self._work = camera, arm_pose, work
        self._job: OffTick[T] | None = None

    @property
    def background(self) -> bool:
        return bool(getattr(self._camera, "captures_in_background", False))

    def start(self) -> None:
        pose = self._arm_pose() @ self._camera.tool_T_camera()
        camera, work = self._camera, self._work
        self._job = OffTick("frame-job", lambda: work(camera.capture(), pose), self.background)
        self._job.start()

    def done(self) -> bool:
        """True once finished; raises what the capture or the work raised (on the tick)."""
        assert self._job is not None, "a frame job is done only once started"
        return self._job.done()

    @property
    def result(self) -> T:
        assert self._job is not None
        return self._job.result


def frame_step(
    name: str,
    dev: Devices,
    guard: Guard,
    work: Callable[[Frame, Pose], T],
    use: Callable[[T], None],
    failed: Callable[[], str | Failed | None] | None = None,
    failure: Failure = Failure.CHECK_FAILED,
    wanted: Callable[[], bool] | None = None,
) -> GuardedMotion:
    """A step that takes a frame, computes ``work`` on it (off the tick where the camera streams
    in real time), then hands the result to ``use`` on the tick thread and judges ``failed()``.
    A capture that fails (no frame, a lost stream) fails the step as any device does.
    ``wanted()`` False when the step starts: no frame is taken, and nothing is used."""
    job: FrameJob[T] | None = None
    used = False

    def start() -> None:
        nonlocal used, job
        camera = dev.camera
        assert camera is not None, f"{name}: a step that looks needs a camera"
        used = False
        if wanted is not None and not wanted():
            job, used = None, True
            return
        job = FrameJob(camera, dev.arm.tool_pose, work)
        job.start()

    def judged() -> str | Failed | None:
        # GuardedMotion asks this before finished(): the frame's result is used here, on the
        # tick it is ready, and judged at once.
        nonlocal used
        if not used and job is not None and job.done():
            used = True
            use(job.result)
        if not used or failed is None:
            return None
        return failed()

    def finished() -> bool:
        return used

    return GuardedMotion(name, start, finished, dev.arm, dev.ft, dev.clock, guard, judged, failure)


__all__ = ["FrameJob", "frame_step"]
