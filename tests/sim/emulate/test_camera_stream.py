"""The D435 emulator: frames streamed over loopback into the driver's software-device path, the
twin's rendering arriving unchanged, and the camera frozen or unplugged."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from drivers.camera import Camera, Intrinsics
from drivers.health import DeviceError
from sim.camera import SimCamera, d435_intrinsics
from sim.emulate.camera_stream import CameraStreamServer, FrameSource, TwinCameraSource, to_z16

from ..conftest import add_floor
from .conftest import wait_for

rs = pytest.importorskip("pyrealsense2")
from drivers.realsense import RealSenseD435  # noqa: E402

W, H = 64, 48


class Pattern:
    """A plane at ``z`` m seen through 64 x 48 pixels, a colour ramp, a hole of no depth."""

    def __init__(self, z: float = 0.5) -> None:
        self.z = z
        self.renders = 0

    def intrinsics(self) -> Intrinsics:
        return Intrinsics(width=W, height=H, fx=50.0, fy=52.0, cx=31.5, cy=23.5)

    def frame(self) -> tuple[np.ndarray, np.ndarray]:
        self.renders += 1
        rgb = np.zeros((H, W, 3), np.uint8)
        rgb[..., 0] = np.arange(W, dtype=np.uint8)[None, :] * 3
        rgb[..., 1] = np.arange(H, dtype=np.uint8)[:, None] * 5
        rgb[..., 2] = self.renders % 256
        depth = np.full((H, W), self.z)
        depth[10:14, 20:24] = 0.0
        return rgb, depth


@pytest.fixture
def pattern() -> Pattern:
    return Pattern()


@pytest.fixture
def server(pattern: Pattern) -> Iterator[CameraStreamServer]:
    with CameraStreamServer(pattern, fps=30, serial="EMU0435") as s:
        yield s


@pytest.fixture
def cam(server: CameraStreamServer) -> Iterator[RealSenseD435]:
    c = RealSenseD435.from_stream(server.host, server.port, timeout_ms=500)
    yield c
    c.stop()


def test_frames_arrive_through_the_software_device(cam: RealSenseD435, pattern: Pattern,
                                                    server: CameraStreamServer) -> None:
    assert isinstance(pattern, FrameSource) and isinstance(cam, Camera)
    frame = cam.capture()
    assert frame.rgb.shape == (H, W, 3) and frame.depth.dtype == np.float32
    np.testing.assert_array_equal(frame.rgb[..., :2], pattern.frame()[0][..., :2])
    assert frame.depth[12, 22] == 0.0 and (frame.depth == 0.0).sum() == 16
    assert set(np.unique(frame.depth)) == {np.float32(0.0), np.float32(0.5)}
    intr = cam.intrinsics()
    assert (intr.fx, intr.fy, intr.cx, intr.cy) == pytest.approx((50.0, 52.0, 31.5, 23.5))
    assert cam.depth_scale == pytest.approx(0.001)
    row = cam.check()
    assert row.ok, row.error
    assert row.address == "EMU0435" and row.details["stream_from"] == f"{server.host}:{server.port}"
    # 30 frames a second arrive (counted by the driver's feed).
    n0, t0 = cam._feed.frames, time.monotonic()  # type: ignore[union-attr]
    time.sleep(1.0)
    rate = (cam._feed.frames - n0) / (time.monotonic() - t0)  # type: ignore[union-attr]
    assert 25 <= rate <= 32


def test_depth_is_quantised_to_depth_units() -> None:
    z = to_z16(np.array([0.0, 0.1234, 0.5, 70.0, np.nan, -1.0]))
    assert z.tolist() == [0, 123, 500, 65535, 0, 0]


def test_a_frozen_camera_times_out_and_an_unplugged_one_is_lost(
    cam: RealSenseD435, server: CameraStreamServer
) -> None:
    cam.capture()
    server.pull_cable()
    time.sleep(0.1)
    cam.timeout_ms = 300
    with pytest.raises(TimeoutError, match="no depth\\+colour frame"):
        for _ in range(5):  # frames already queued may still come out first
            cam.capture()
    server.restore()
    assert cam.capture().rgb.shape == (H, W, 3)
    server.drop_clients()
    assert wait_for(lambda: cam._feed is not None and cam._feed.error is not None, 2.0)
    with pytest.raises(DeviceError, match="frame stream lost"):
        for _ in range(5):
            cam.capture()


def test_no_stream_there_names_the_address() -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(DeviceError, match=f"127.0.0.1:{port}.*no D435 frame stream"):
        RealSenseD435.from_stream("127.0.0.1", port, timeout_ms=200)


def test_the_twins_rendering_arrives_unchanged(twin) -> None:  # noqa: ANN001
    world, robot = twin
    add_floor(world)
    lock = threading.Lock()
    intr = d435_intrinsics(160, 120)
    simcam = SimCamera(world, robot.arm.tool_pose, intrinsics=intr, noise=None)
    for _ in range(10):
        world.step()
    with CameraStreamServer(TwinCameraSource(simcam, lock), fps=10) as server:
        cam = RealSenseD435.from_stream(server.host, server.port, timeout_ms=3000)
        try:
            frame = cam.capture()
        finally:
            cam.stop()
    rgb, depth = simcam.render(simcam.world_T_camera())
    np.testing.assert_array_equal(frame.rgb, rgb)
    valid = depth > 0
    assert valid.mean() > 0.5  # the floor and the robot's surroundings are in view
    np.testing.assert_array_equal(frame.depth == 0, ~valid)
    assert np.max(np.abs(frame.depth[valid] - depth[valid])) <= 0.0005 + 1e-6  # 1 mm counts


def test_the_cell_opens_the_streamed_camera_named_in_its_configuration(
    server: CameraStreamServer,
) -> None:
    from cell.config import config_from_text
    from cell.hardware import OPENERS
    from drivers.clock import WallClock
    from drivers.pose import Pose

    class Mount:
        def tool_T_camera(self) -> Pose:
            return Pose(np.array([0.0, -0.08, -0.05]))

    cfg, _ = config_from_text(f"devices:\n  camera:\n    stream: '{server.host}:{server.port}'\n")
    cam = OPENERS["camera"](cfg.devices, Mount(), WallClock())
    try:
        assert cam.capture().rgb.shape == (H, W, 3)
        assert cam.address == "EMU0435"
        np.testing.assert_allclose(cam.tool_T_camera().position, [0.0, -0.08, -0.05])
    finally:
        cam.stop()


def test_a_client_joining_a_running_stream_gets_pairs_at_once(pattern: Pattern) -> None:
    # A cell that reconnects (or a `cell run` after `cell check-hardware`) joins a stream that
    # has sent frames for a while. Its camera's counter starts with its stream, as a D435's does
    # when the host starts it: frame numbers carried on from the first client's stream kept
    # librealsense's syncer from pairing depth with colour for seconds.
    import socket

    from drivers.realsense.stream import read_frame, read_info

    with CameraStreamServer(pattern, fps=30, serial="EMU0435") as s:
        first = RealSenseD435.from_stream(s.host, s.port, timeout_ms=1000)
        try:
            assert wait_for(lambda: s.frames_sent >= 150, 10.0)
        finally:
            first.stop()
        with socket.create_connection((s.host, s.port), timeout=2.0) as raw:
            info = read_info(raw)
            numbers = [read_frame(raw, info)[0] for _ in range(3)]
        assert 1 <= numbers[0] <= 3 and numbers == sorted(numbers)
        second = RealSenseD435.from_stream(s.host, s.port, timeout_ms=500)
        try:
            for _ in range(3):
                assert second.capture().rgb.shape == (H, W, 3)
        finally:
            second.stop()


def test_a_capture_returns_a_frame_rendered_after_it_was_asked_for() -> None:
    # The arm reports it has arrived and the skill captures at once: a frame the camera held
    # already was exposed during the end of the move (up to a period and a transfer earlier).
    class Stamped(Pattern):
        def __init__(self) -> None:
            super().__init__()
            self.started: list[float] = []  # when each render began (its "exposure")

        def frame(self) -> tuple[np.ndarray, np.ndarray]:
            self.started.append(time.monotonic())
            return super().frame()

    src = Stamped()
    with CameraStreamServer(src, fps=10, serial="EMU0435") as s:
        cam = RealSenseD435.from_stream(s.host, s.port, timeout_ms=1000)
        try:
            for _ in range(3):
                time.sleep(0.45)  # frames pile up while nobody captures
                asked = time.monotonic()
                frame = cam.capture()
                n = int(frame.rgb[0, 0, 2])  # the render's number (mod 256), see Pattern
                assert src.started[n - 1] >= asked, (n, src.started[n - 1] - asked)
        finally:
            cam.stop()
