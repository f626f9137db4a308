"""The Intel RealSense D435 over ``pyrealsense2``: :class:`RealSenseD435` implements ``Camera``.

Depth and colour stream together; each capture aligns depth to the colour image (``rs.align``),
so pixel (u, v) of ``Frame.depth`` is the range (m) of pixel (u, v) of ``Frame.rgb`` and the
colour intrinsics are the only ones perception needs. Depth counts are converted with the depth
sensor's own scale. A capture that gets no complete depth + colour pair within ``timeout_ms``
raises ``TimeoutError`` (the ``Camera`` contract), not librealsense's ``RuntimeError``.

``pyrealsense2`` is imported inside methods only: importing this module, the twin, and the tests
that do not touch a camera never need librealsense or libusb.

Two ways in, one frame path:

* ``RealSenseD435(serial, width, height, fps, ...).start()``: the hardware path, an
  ``rs.pipeline`` on the camera with that serial (or the only one connected).
* ``RealSenseD435.from_device(dev, ...)``: opens the depth and colour sensors of an already
  built ``rs.device`` directly into an ``rs.syncer``. The tests feed it a
  ``rs.software_device`` (librealsense 2.59 does not list a software device in a context, so a
  pipeline cannot be started on one); everything after "a frameset arrived" is shared.
* ``RealSenseD435.from_stream(host, port, ...)``: a camera whose frames arrive over a socket
  (:mod:`drivers.realsense.stream`; the emulator's D435 sends them). It builds a software device
  shaped by the stream's header and a thread pushes each received pair into it, so from the
  frameset on (syncer, align, depth scale, intrinsics) it is the hardware path. A stream that
  stops or closes is a camera that delivers no frames: ``capture()`` raises ``TimeoutError``.
"""

from __future__ import annotations

import socket
import threading
import time
from collections import deque
from typing import Any, Protocol

import numpy as np

from drivers.camera import Frame, Intrinsics
from drivers.clock import Clock, WallClock
from drivers.health import CheckResult, DeviceError, backoff_delays
from drivers.pose import Pose
from drivers.realsense.frames import colour_to_rgb, depth_to_metres, intrinsics_from_rs
from drivers.realsense.stream import StreamInfo, read_frame, read_info

DEVICE = "RealSense D435"


def _rs() -> Any:
    """``pyrealsense2``, imported on the hardware path only."""
    import pyrealsense2 as rs

    return rs


def _polled(queue: Any) -> tuple[bool, Any]:
    """A frameset already waiting in a pipeline or syncer, without waiting (``poll_for_frames``
    answers a frameset that is empty when none is queued)."""
    frames = queue.poll_for_frames()
    return (bool(frames) and frames.size() > 0), frames


class _Source(Protocol):
    """Where framesets come from: a pipeline (hardware) or a syncer over opened sensors."""

    def try_wait(self, timeout_ms: int) -> tuple[bool, Any]: ...

    def poll(self) -> tuple[bool, Any]: ...

    def stop(self) -> None: ...


class _PipelineSource:
    def __init__(self, pipeline: Any) -> None:
        self._pipe = pipeline

    def try_wait(self, timeout_ms: int) -> tuple[bool, Any]:
        return self._pipe.try_wait_for_frames(timeout_ms)

    def poll(self) -> tuple[bool, Any]:
        return _polled(self._pipe)

    def stop(self) -> None:
        self._pipe.stop()


class _SyncerSource:
    def __init__(self, sensors: list[Any], syncer: Any) -> None:
        self._sensors, self._syncer = sensors, syncer

    def try_wait(self, timeout_ms: int) -> tuple[bool, Any]:
        return self._syncer.try_wait_for_frames(timeout_ms)

    def poll(self) -> tuple[bool, Any]:
        return _polled(self._syncer)

    def stop(self) -> None:
        for s in self._sensors:
            s.stop()
        for s in self._sensors:
            s.close()


def software_d435(rs: Any, info: StreamInfo) -> tuple[Any, Any, Any, Any, Any]:
    """A ``rs.software_device`` shaped by ``info``: a depth sensor (Z16, ``depth_units``) and a
    colour sensor (RGB8) with the same intrinsics and an identity extrinsic between them (the
    stream's depth is aligned to colour already). Returns the device, both sensors and both
    video stream profiles."""
    def stream(kind: Any, fmt: Any, bpp: int, uid: int) -> Any:
        intr = rs.intrinsics()
        intr.width, intr.height = info.width, info.height
        intr.fx, intr.fy, intr.ppx, intr.ppy = info.fx, info.fy, info.cx, info.cy
        intr.model, intr.coeffs = rs.distortion.none, [0.0] * 5
        st = rs.video_stream()
        st.type, st.index, st.uid = kind, 0, uid
        st.width, st.height, st.fps, st.bpp, st.fmt = info.width, info.height, info.fps, bpp, fmt
        st.intrinsics = intr
        return st

    dev = rs.software_device()
    dev.register_info(rs.camera_info.serial_number, info.serial)
    dev.register_info(rs.camera_info.firmware_version, info.firmware)
    dev.register_info(rs.camera_info.name, info.name)
    ds, cs = dev.add_sensor("Stereo Module"), dev.add_sensor("RGB Camera")
    dp = ds.add_video_stream(stream(rs.stream.depth, rs.format.z16, 2, 0))
    ds.add_read_only_option(rs.option.depth_units, info.depth_units)
    cp = cs.add_video_stream(stream(rs.stream.color, rs.format.rgb8, 3, 1))
    ex = rs.extrinsics()
    ex.rotation = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    ex.translation = [0.0, 0.0, 0.0]
    dp.register_extrinsics_to(cp, ex)
    dev.create_matcher(rs.matchers.default)
    return dev, ds, cs, dp.as_video_stream_profile(), cp.as_video_stream_profile()


def _same_geometry(depth: Any, colour: Any) -> bool:
    """Depth and colour profiles with equal intrinsics and an identity extrinsic between them."""
    a, b = depth.get_intrinsics(), colour.get_intrinsics()
    same = ((a.width, a.height, a.fx, a.fy, a.ppx, a.ppy, a.model, list(a.coeffs))
            == (b.width, b.height, b.fx, b.fy, b.ppx, b.ppy, b.model, list(b.coeffs)))
    try:
        ex = depth.get_extrinsics_to(colour)
    except RuntimeError:  # no extrinsic registered: not known to be one geometry
        return False
    identity = np.allclose(ex.rotation, np.eye(3).ravel()) and np.allclose(ex.translation, 0.0)
    return bool(same and identity)


class _StreamFeed:
    """Receives frame pairs from the socket and pushes them into the software device's sensors
    (a thread). librealsense reads a pushed frame's pixels without copying, so the last few
    buffers are kept alive here."""

    KEEP = 64  #: frame buffers kept alive (more than the syncer and align can hold)

    def __init__(self, rs: Any, sock: socket.socket, info: StreamInfo, sensors: tuple[Any, Any],
                 profiles: tuple[Any, Any]) -> None:
        self._rs, self._sock, self.info = rs, sock, info
        self._sensors, self._profiles = sensors, profiles
        self._keep: deque[Any] = deque(maxlen=self.KEEP)
        self._stop = threading.Event()
        self.frames = 0  #: pairs pushed
        self.error: str | None = None  #: why the feed ended, if the stream failed
        self._thread = threading.Thread(target=self._run, name="d435-stream", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
        self._thread.join(timeout=2.0)

    def _run(self) -> None:
        rs, info = self._rs, self.info
        w = info.width
        try:
            while not self._stop.is_set():
                number, ts, depth, rgb = read_frame(self._sock, info)
                for sensor, profile, pixels, bpp, units in (
                    (self._sensors[0], self._profiles[0], depth, 2, info.depth_units),
                    (self._sensors[1], self._profiles[1], rgb, 3, None),
                ):
                    self._keep.append(pixels)
                    f = rs.software_video_frame()
                    f.pixels, f.stride, f.bpp = pixels, w * bpp, bpp
                    f.timestamp, f.frame_number = ts, number
                    f.domain = rs.timestamp_domain.hardware_clock
                    f.profile = profile
                    if units is not None:
                        f.depth_units = units
                    sensor.on_video_frame(f)
                self.frames += 1
        except (OSError, ConnectionError, ValueError) as exc:
            if not self._stop.is_set():
                self.error = str(exc)


class RealSenseD435:
    """An eye-in-hand D435 (implements ``drivers.camera.Camera``).

    Configuration: ``serial`` (``None``: the only camera connected), ``width`` x ``height`` at
    ``fps`` for both streams (the D435 has 640 x 480 at 30 fps on both), ``timeout_ms`` (a
    capture must get a frame within this), ``tool_T_camera`` (the hand-eye calibration; it is
    config, not read from the device), ``clock`` (stamps frames on the cell's clock),
    ``open_attempts`` (bounded pipeline starts with back-off; a D435 that was just plugged in
    can refuse the first).
    """

    #: A real camera streams on its own clock: its frames are waited for off the control tick
    #: (``skills.frames``), where the twin's camera renders inside the tick.
    captures_in_background = True

    def __init__(
        self,
        serial: str | None = None,
        width: int = 640,
        height: int = 480,
        fps: int = 30,
        timeout_ms: int = 1000,
        tool_T_camera: Pose | None = None,
        *,
        clock: Clock | None = None,
        open_attempts: int = 3,
    ) -> None:
        if timeout_ms <= 0:
            raise ValueError("timeout_ms must be positive")
        self.serial = serial
        self.width, self.height, self.fps = width, height, fps
        self.timeout_ms = timeout_ms
        self._tool_T_camera = tool_T_camera if tool_T_camera is not None else Pose()
        self._clock: Clock = clock if clock is not None else WallClock()
        self.open_attempts = max(1, open_attempts)
        self._source: _Source | None = None
        self._align: Any = None
        self._depth_scale = 0.0
        self._intrinsics: Intrinsics | None = None
        self._coeffs: list[float] = []
        self._colour_fmt = "rgb8"
        self._feed: _StreamFeed | None = None
        self._device: Any = None
        self.info: dict[str, str] = {}

    @property
    def address(self) -> str:
        """What names this camera in errors: its serial, or "usb" when it is the only one."""
        return self.info.get("serial") or self.serial or "usb (any)"

    # -- life cycle ------------------------------------------------------------------------

    @classmethod
    def from_device(
        cls,
        device: Any,
        width: int = 640,
        height: int = 480,
        fps: int = 30,
        timeout_ms: int = 1000,
        tool_T_camera: Pose | None = None,
        *,
        clock: Clock | None = None,
    ) -> RealSenseD435:
        """A started camera on an already built ``rs.device`` (e.g. a ``rs.software_device``).

        Picks the depth (Z16) and colour (RGB8/BGR8) profiles of ``width`` x ``height`` at
        ``fps``, opens both sensors and starts them into one ``rs.syncer``.
        """
        rs = _rs()
        cam = cls(None, width, height, fps, timeout_ms, tool_T_camera, clock=clock)
        depth = colour = None
        for sensor in device.query_sensors():
            for p in sensor.get_stream_profiles():
                if p.fps() != fps or not p.is_video_stream_profile():
                    continue
                v = p.as_video_stream_profile()
                if (v.width(), v.height()) != (width, height):
                    continue
                if p.stream_type() == rs.stream.depth and p.format() == rs.format.z16:
                    depth = depth or (sensor, v)
                elif p.stream_type() == rs.stream.color and p.format() in (
                    rs.format.rgb8, rs.format.bgr8
                ):
                    colour = colour or (sensor, v)
        if depth is None or colour is None:
            raise DeviceError(DEVICE, cam.address, f"device has no Z16 depth and RGB8/BGR8 "
                              f"colour profile of {width}x{height} at {fps} fps")
        scale = depth[0].as_depth_sensor().get_depth_scale()
        syncer = rs.syncer()
        sensors = [depth[0]] if depth[0] == colour[0] else [depth[0], colour[0]]
        if len(sensors) == 1:
            sensors[0].open([depth[1], colour[1]])
        else:
            depth[0].open(depth[1])
            colour[0].open(colour[1])
        for s in sensors:
            s.start(syncer)
        cam._attach(rs, device, _SyncerSource(sensors, syncer), scale, colour[1], depth[1])
        return cam

    @classmethod
    def from_stream(
        cls,
        host: str,
        port: int,
        timeout_ms: int = 1000,
        tool_T_camera: Pose | None = None,
        *,
        clock: Clock | None = None,
    ) -> RealSenseD435:
        """A started camera whose frames arrive over TCP from ``host``:``port`` (see the module
        doc). Its width, height, fps, intrinsics and identity come from the stream's header.
        Raises :class:`DeviceError` naming the address when nothing answers there or it does
        not speak the stream protocol."""
        rs = _rs()
        address = f"{host}:{port}"
        try:
            sock = socket.create_connection((host, port), timeout=timeout_ms / 1000.0)
            info = read_info(sock)
        except (OSError, ConnectionError, ValueError) as exc:
            raise DeviceError(DEVICE, address, f"no D435 frame stream: {exc}") from exc
        sock.settimeout(None)
        dev, ds, cs, dp, cp = software_d435(rs, info)
        cam = cls.from_device(dev, info.width, info.height, info.fps, timeout_ms, tool_T_camera,
                              clock=clock)
        cam.serial = info.serial
        cam._device = dev  # the software device must outlive its sensors' use
        cam._feed = _StreamFeed(rs, sock, info, (ds, cs), (dp, cp))
        cam.info["stream_from"] = address
        cam._feed.start()
        return cam

    def start(self) -> None:
        """Hardware path: find the camera, start depth + colour, read scale and intrinsics.

        Raises :class:`DeviceError` naming the serial when no camera (or not that one) is
        connected, or when the pipeline refuses to start after ``open_attempts`` tries.
        """
        if self._source is not None:
            return
        rs = _rs()
        ctx = rs.context()
        found = [d.get_info(rs.camera_info.serial_number) for d in ctx.query_devices()]
        if not found:
            raise DeviceError(DEVICE, self.address,
                              "no RealSense camera connected (USB 3 cable? udev rules?)")
        if self.serial is not None and self.serial not in found:
            raise DeviceError(DEVICE, self.address,
                              f"not connected; connected serials: {', '.join(found)}")
        cfg = rs.config()
        if self.serial is not None:
            cfg.enable_device(self.serial)
        cfg.enable_stream(rs.stream.depth, self.width, self.height, rs.format.z16, self.fps)
        cfg.enable_stream(rs.stream.color, self.width, self.height, rs.format.rgb8, self.fps)
        pipe = rs.pipeline(ctx)
        delays = backoff_delays(self.open_attempts)
        last: Exception | None = None
        for attempt in range(self.open_attempts):
            try:
                profile = pipe.start(cfg)
                break
            except RuntimeError as exc:
                last = exc
                if attempt < len(delays):
                    time.sleep(delays[attempt])
        else:
            raise DeviceError(DEVICE, self.address,
                              f"cannot start depth+colour {self.width}x{self.height}@{self.fps} "
                              f"({self.open_attempts} tries): {last}")
        device = profile.get_device()
        scale = device.first_depth_sensor().get_depth_scale()
        colour = profile.get_stream(rs.stream.color).as_video_stream_profile()
        depth = profile.get_stream(rs.stream.depth).as_video_stream_profile()
        self._attach(rs, device, _PipelineSource(pipe), scale, colour, depth)

    def _attach(self, rs: Any, device: Any, source: _Source, scale: float, colour: Any,
                depth: Any) -> None:
        """Shared end of every way in: remember the source, scale, intrinsics and identity.

        Depth is aligned to colour with ``rs.align``, except when the two streams already share
        one geometry (same intrinsics, identity extrinsic: a streamed camera whose depth was
        rendered aligned). Aligning a stream onto itself is the identity, but ``rs.align``
        computes it in floating point and leaves whole rows and columns empty (measured on a
        64 x 48 software device: columns 2 and 5 and row 10 zeroed), so it is skipped there.
        A D435's depth and colour imagers never share a geometry, so on hardware it always runs.
        """
        intr = colour.get_intrinsics()
        self._source = source
        self._align = None if _same_geometry(depth, colour) else rs.align(rs.stream.color)
        self._depth_scale = float(scale)
        self._intrinsics = intrinsics_from_rs(intr)
        self._coeffs = [float(c) for c in intr.coeffs]
        self._colour_fmt = "bgr8" if colour.format() == rs.format.bgr8 else "rgb8"
        self.info = {}
        for key, what in (("serial", rs.camera_info.serial_number),
                          ("firmware", rs.camera_info.firmware_version),
                          ("name", rs.camera_info.name),
                          ("usb", rs.camera_info.usb_type_descriptor)):
            if device.supports(what):
                self.info[key] = device.get_info(what)

    def stop(self) -> None:
        """Stop streaming and release the device (safe to call twice)."""
        feed, self._feed = self._feed, None
        if feed is not None:
            feed.stop()
        source, self._source = self._source, None
        if source is not None:
            try:
                source.stop()
            except RuntimeError:
                pass  # a camera that is already gone cannot be stopped; nothing to release

    def __enter__(self) -> RealSenseD435:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- Camera ------------------------------------------------------------------------------

    def intrinsics(self) -> Intrinsics:
        """Colour intrinsics (pixels); aligned depth shares them."""
        if self._intrinsics is None:
            raise DeviceError(DEVICE, self.address, "not started")
        return self._intrinsics

    def tool_T_camera(self) -> Pose:
        """The configured hand-eye calibration (m, rad)."""
        return self._tool_T_camera

    @property
    def depth_scale(self) -> float:
        """Metres per depth count, from the device."""
        return self._depth_scale

    def capture(self) -> Frame:
        """A depth + colour pair exposed after this call, depth aligned to colour, in metres
        (0 = invalid).

        Why not simply the newest pair: librealsense hands out the frameset it already holds,
        which was exposed up to a frame period (plus the transfer) before the call. A skill
        captures as soon as the arm reports it has arrived, so that frame showed the scene from
        the end of the move while it was paired with the pose at rest: against the emulated
        D435 at 6 fps the rim of a part in the slot came out millimetres off and the descent
        onto it struck the rim. So the pairs queued at the call are dropped, the first pair to
        arrive is dropped too (its exposure may have begun before the call), and the next one
        is returned: one to two frame periods (33-66 ms at 30 fps).

        Raises ``TimeoutError`` when no such pair arrives within ``timeout_ms``, and
        :class:`DeviceError` when not started or the camera fails otherwise.
        """
        if self._source is None:
            raise DeviceError(DEVICE, self.address, "not started")
        deadline = time.monotonic() + self.timeout_ms / 1000.0
        try:
            while self._source.poll()[0]:
                pass  # exposed before the call
        except RuntimeError as exc:
            raise DeviceError(DEVICE, self.address, f"frame wait failed: {exc}") from exc
        skip = 1  # the first pair to arrive may have been exposed (in part) before the call
        while True:
            remaining = int((deadline - time.monotonic()) * 1000.0)
            if remaining <= 0:
                break
            try:
                ok, frames = self._source.try_wait(remaining)
            except RuntimeError as exc:
                raise DeviceError(DEVICE, self.address, f"frame wait failed: {exc}") from exc
            if not ok:
                break
            stamp = self._clock.now()
            if not (frames.get_depth_frame() and frames.get_color_frame()):
                continue  # a lone stream (the other one dropped): wait for a full pair
            if skip:
                skip -= 1
                continue
            aligned = frames if self._align is None else self._align.process(frames)
            depth, colour = aligned.get_depth_frame(), aligned.get_color_frame()
            if not (depth and colour):
                continue
            metres = depth_to_metres(np.asanyarray(depth.get_data()), self._depth_scale)
            rgb = colour_to_rgb(np.asanyarray(colour.get_data()), self._colour_fmt)
            return Frame(rgb=rgb, depth=metres, stamp=stamp)
        if self._feed is not None and self._feed.error is not None:
            raise DeviceError(DEVICE, self.address, f"frame stream lost: {self._feed.error}")
        raise TimeoutError(f"{DEVICE} at {self.address}: no depth+colour frame within "
                           f"{self.timeout_ms} ms")

    def check(self, min_valid_fraction: float = 0.2) -> CheckResult:
        """Start-up check for ``cell check-hardware``; never raises.

        Starts the camera if needed, grabs one frame and reports serial, firmware, USB type
        (a D435 on USB 2 runs but with fewer modes), stream, depth scale, intrinsics and the
        fraction of valid depth pixels; fails when that fraction is below
        ``min_valid_fraction`` (lens covered, projector off, or everything closer than the
        D435's minimum range of about 0.1-0.2 m).
        """
        try:
            self.start()
            t0 = time.monotonic()
            frame = self.capture()
            grab_ms = (time.monotonic() - t0) * 1000.0
        except (DeviceError, TimeoutError) as exc:
            cause = exc.cause if isinstance(exc, DeviceError) else str(exc)
            return CheckResult(DEVICE, self.address, False, dict(self.info), cause)
        intr = self.intrinsics()
        valid = frame.depth > 0
        fraction = float(valid.mean())
        details = dict(self.info)
        details.update({
            "stream": f"{self.width}x{self.height}@{self.fps}",
            "depth_scale_m": f"{self._depth_scale:.6g}",
            "intrinsics": f"fx={intr.fx:.2f} fy={intr.fy:.2f} cx={intr.cx:.2f} cy={intr.cy:.2f}",
            "distortion": " ".join(f"{c:.4g}" for c in self._coeffs),
            "frame_ms": f"{grab_ms:.0f}",
            "depth_valid_fraction": f"{fraction:.3f}",
            "depth_median_m": f"{float(np.median(frame.depth[valid])):.3f}" if fraction else "-",
        })
        ok = fraction >= min_valid_fraction
        error = None if ok else (f"only {fraction:.1%} of depth pixels valid "
                                 f"(< {min_valid_fraction:.0%})")
        return CheckResult(DEVICE, self.address, ok, details, error)
