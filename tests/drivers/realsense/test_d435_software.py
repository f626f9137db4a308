"""The D435 driver on pyrealsense2's software device: real librealsense frames, syncer and align.

A ``rs.software_device`` with a depth sensor (Z16, depth units 1 mm) and a colour sensor (RGB8)
with known, different intrinsics and a known depth-to-colour extrinsic; the tests inject
synthetic frames and check what ``capture()`` returns. The device streams what the test shows it at
``FPS`` from a thread, as a camera streams continuously (a capture returns a pair exposed after it
was asked for, so pushing one pair and then capturing would wait forever). Not exercised here (no
camera): the ``rs.pipeline`` start on a real device (only its "nothing connected" branch runs), USB
behaviour, and frame drops of a real stream.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from drivers.camera import Camera
from drivers.health import DeviceError
from drivers.pose import Pose
from drivers.realsense import RealSenseD435, depth_to_metres

rs = pytest.importorskip("pyrealsense2")

W, H, FPS = 64, 48, 30
DEPTH_UNITS = 0.001
DEPTH_K = (50.0, 50.0, 31.5, 23.5)  # fx, fy, cx, cy of the depth imager
COLOUR_K = (60.0, 60.0, 32.0, 24.0)  # of the colour imager
BASELINE = 0.015  # m: the colour optical centre seen from the depth one, along +x


def _intr(k: tuple[float, float, float, float]) -> Any:
    i = rs.intrinsics()
    i.width, i.height = W, H
    i.fx, i.fy, i.ppx, i.ppy = k
    i.model = rs.distortion.none
    i.coeffs = [0.0] * 5
    return i


def _stream(kind: Any, fmt: Any, bpp: int, uid: int, k: tuple[float, ...]) -> Any:
    s = rs.video_stream()
    s.type, s.index, s.uid = kind, 0, uid
    s.width, s.height, s.fps, s.bpp, s.fmt = W, H, FPS, bpp, fmt
    s.intrinsics = _intr(k)
    return s


@dataclass
class SoftD435:
    """A software device shaped like a D435 and a way to push frame pairs into it."""

    dev: Any
    depth_sensor: Any
    colour_sensor: Any
    depth_profile: Any
    colour_profile: Any
    n: int = 0
    keep: deque[np.ndarray] = field(default_factory=lambda: deque(maxlen=256))
    scene: tuple[np.ndarray | None, np.ndarray | None] | None = None  #: what it streams
    stopped: threading.Event = field(default_factory=threading.Event)

    def show(self, depth_mm: np.ndarray | None, rgb: np.ndarray | None) -> None:
        """From now on the stream carries this depth (mm) and colour (None: that stream drops)."""
        self.scene = (depth_mm, rgb)

    def stream(self) -> None:
        """Push the scene shown at ``FPS`` until :attr:`stopped` is set (run on a thread)."""
        while not self.stopped.wait(1.0 / FPS):
            if self.scene is not None:
                self.push(*self.scene)

    def push(self, depth_mm: np.ndarray | None, rgb: np.ndarray | None) -> None:
        self.n += 1
        ts = self.n * 1000.0 / FPS
        if depth_mm is not None:
            d = np.ascontiguousarray(depth_mm, np.uint16)
            self.keep.append(d)
            f = rs.software_video_frame()
            f.pixels, f.stride, f.bpp = d, W * 2, 2
            f.timestamp, f.frame_number = ts, self.n
            f.domain = rs.timestamp_domain.hardware_clock
            f.profile, f.depth_units = self.depth_profile, DEPTH_UNITS
            self.depth_sensor.on_video_frame(f)
        if rgb is not None:
            c = np.ascontiguousarray(rgb, np.uint8)
            self.keep.append(c)
            g = rs.software_video_frame()
            g.pixels, g.stride, g.bpp = c, W * 3, 3
            g.timestamp, g.frame_number = ts, self.n
            g.domain = rs.timestamp_domain.hardware_clock
            g.profile = self.colour_profile
            self.colour_sensor.on_video_frame(g)


def make_soft_d435() -> SoftD435:
    dev = rs.software_device()
    dev.register_info(rs.camera_info.serial_number, "SW0435")
    dev.register_info(rs.camera_info.firmware_version, "5.16.0.1")
    dev.register_info(rs.camera_info.name, "Software D435")
    ds = dev.add_sensor("Stereo Module")
    cs = dev.add_sensor("RGB Camera")
    dp = ds.add_video_stream(_stream(rs.stream.depth, rs.format.z16, 2, 0, DEPTH_K))
    ds.add_read_only_option(rs.option.depth_units, DEPTH_UNITS)
    cp = cs.add_video_stream(_stream(rs.stream.color, rs.format.rgb8, 3, 1, COLOUR_K))
    ex = rs.extrinsics()
    ex.rotation = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    ex.translation = [BASELINE, 0.0, 0.0]
    dp.register_extrinsics_to(cp, ex)
    dev.create_matcher(rs.matchers.default)
    return SoftD435(dev, ds, cs, dp.as_video_stream_profile(), cp.as_video_stream_profile())


@pytest.fixture
def soft() -> Iterator[SoftD435]:
    d = make_soft_d435()
    thread = threading.Thread(target=d.stream, daemon=True)
    thread.start()
    yield d
    d.stopped.set()
    thread.join(timeout=2.0)


@pytest.fixture
def cam(soft: SoftD435) -> Iterator[RealSenseD435]:
    c = RealSenseD435.from_device(soft.dev, W, H, FPS, timeout_ms=1000,
                                  tool_T_camera=Pose(np.array([0.0, -0.08, -0.05])))
    yield c
    c.stop()


def colour_pattern() -> np.ndarray:
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[..., 0] = np.arange(W, dtype=np.uint8)[None, :] * 3
    rgb[..., 1] = np.arange(H, dtype=np.uint8)[:, None] * 5
    rgb[..., 2] = 77
    return rgb


def test_capture_returns_metres_and_the_colour_image(soft: SoftD435, cam: RealSenseD435) -> None:
    assert isinstance(cam, Camera)
    soft.show(np.full((H, W), 500, np.uint16), colour_pattern())
    frame = cam.capture()
    assert frame.depth.dtype == np.float32 and frame.depth.shape == (H, W)
    assert frame.rgb.dtype == np.uint8 and frame.rgb.shape == (H, W, 3)
    np.testing.assert_array_equal(frame.rgb, colour_pattern())
    # A plane at 0.5 m, parallel to both imagers, is 0.5 m everywhere after alignment (the depth
    # imager's wider field of view covers every colour pixel).
    np.testing.assert_allclose(frame.depth, 0.5, atol=1e-6)
    assert cam.depth_scale == pytest.approx(DEPTH_UNITS)
    np.testing.assert_allclose(cam.tool_T_camera().position, [0.0, -0.08, -0.05])


def test_intrinsics_are_the_colour_stream_s(cam: RealSenseD435) -> None:
    intr = cam.intrinsics()
    assert (intr.width, intr.height) == (W, H)
    assert (intr.fx, intr.fy, intr.cx, intr.cy) == pytest.approx(COLOUR_K)


def test_invalid_depth_stays_zero_where_it_lands(soft: SoftD435, cam: RealSenseD435) -> None:
    depth = np.full((H, W), 500, np.uint16)
    depth[20:28, 26:34] = 0  # a hole (no stereo match) around the depth image's centre
    soft.show(depth, colour_pattern())
    d = cam.capture().depth
    # The hole's centre (u, v) = (29.5, 23.5) in the depth image, at 0.5 m:
    # x = (29.5 - 31.5) / 50 * 0.5 = -0.02 m; in the colour frame x + 0.015 = -0.005 m
    # -> u = 60 * -0.005 / 0.5 + 32 = 31.4, v = 24.
    assert d[24, 31] == 0.0 and d[23, 30] == 0.0
    assert (d == 0.0).sum() >= 8 * 8  # magnified by 60/50, never filled in
    assert set(np.unique(d)) <= {np.float32(0.0), np.float32(0.5)}  # no invented depths


def test_alignment_moves_a_depth_edge_by_the_baseline_parallax(
    soft: SoftD435, cam: RealSenseD435
) -> None:
    depth = np.full((H, W), 500, np.uint16)
    depth[:, 40:] = 1000  # a step: 0.5 m left of depth column 39.5, 1.0 m right of it
    soft.show(depth, colour_pattern())
    d = cam.capture().depth
    row = d[24]
    first_far = int(np.argmax(row > 0.75))
    # The edge ray x/z = (39.5 - 31.5) / 50 = 0.16 seen from the colour imager: at z = 1.0 m
    # u = 60 (0.16 + 0.015 / 1.0) + 32 = 42.5; at z = 0.5 m u = 60 (0.16 + 0.03) + 32 = 43.4.
    assert 42 <= first_far <= 45
    assert np.all(row[:40] == np.float32(0.5)) and np.all(row[46:] == np.float32(1.0))


def test_no_frame_is_a_timeout_error(soft: SoftD435) -> None:
    cam = RealSenseD435.from_device(soft.dev, W, H, FPS, timeout_ms=150)
    try:
        with pytest.raises(TimeoutError, match="SW0435") as err:
            cam.capture()
        assert not isinstance(err.value, RuntimeError)
        soft.show(np.full((H, W), 500, np.uint16), colour_pattern())
        assert cam.capture().rgb.shape == (H, W, 3)
        soft.show(np.full((H, W), 500, np.uint16), None)  # depth without colour is not a frame
        with pytest.raises(TimeoutError):
            cam.capture()
    finally:
        cam.stop()


def test_check_reports_identity_and_valid_fraction(soft: SoftD435, cam: RealSenseD435) -> None:
    depth = np.full((H, W), 800, np.uint16)
    depth[:, :10] = 0
    soft.show(depth, colour_pattern())
    result = cam.check()
    assert result.ok, result.error
    assert result.address == "SW0435"
    assert result.details["serial"] == "SW0435"
    assert result.details["firmware"] == "5.16.0.1"
    assert result.details["depth_median_m"] == "0.800"
    assert 0.7 < float(result.details["depth_valid_fraction"]) < 1.0


def test_check_fails_on_a_blind_camera(soft: SoftD435, cam: RealSenseD435) -> None:
    soft.show(np.zeros((H, W), np.uint16), colour_pattern())
    result = cam.check()
    assert not result.ok and "valid" in (result.error or "")
    cam.stop()
    bare = RealSenseD435.from_device(make_soft_d435().dev, W, H, FPS, timeout_ms=100)
    try:
        result = bare.check()
    finally:
        bare.stop()
    assert not result.ok and "no depth+colour frame" in (result.error or "")


def test_capture_before_start_is_a_device_error() -> None:
    with pytest.raises(DeviceError, match="not started"):
        RealSenseD435(serial="123").capture()


def test_no_camera_connected_names_the_serial() -> None:
    # The real hardware path up to device discovery: nothing is plugged in here.
    with pytest.raises(DeviceError, match="no RealSense camera connected|not connected") as err:
        RealSenseD435(serial="012345678901").start()
    assert err.value.address == "012345678901"


def test_depth_conversion_keeps_zero_invalid() -> None:
    raw = np.array([[0, 1, 1000, 65535]], np.uint16)
    m = depth_to_metres(raw, 0.0001)
    assert m.dtype == np.float32
    np.testing.assert_allclose(m, [[0.0, 0.0001, 0.1, 6.5535]], rtol=1e-6)
    with pytest.raises(ValueError):
        depth_to_metres(raw, 0.0)


def test_the_driver_module_does_not_import_pyrealsense2() -> None:
    code = "import sys, drivers.realsense; assert 'pyrealsense2' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)
