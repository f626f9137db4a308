"""The D435 as the twin renders it, streamed over a loopback socket to the cell process.

A USB camera has no network protocol to emulate, so the cut is made where the hardware path
starts to be shared: the emulator sends what the camera's USB stream carries (Z16 depth in
depth units, RGB8 colour, frame number, timestamp) and, once per connection, what librealsense
reads from the device (identity, mode, intrinsics, depth units), in the format of
:mod:`drivers.realsense.stream`. The D435 driver's stream mode
(``RealSenseD435.from_stream(host, port)``) pushes each pair into a pyrealsense2 software device,
so from "a frameset arrived" on (syncer, align, depth scale, intrinsics, the driver's checks) the
cell runs the hardware code.

Backend interface (:class:`FrameSource`)::

    intrinsics() -> drivers.camera.Intrinsics   # pixels; depth is aligned to colour
    frame() -> (rgb, depth)                     # rgb (H, W, 3) uint8; depth (H, W) m, float,
                                                #   0 = no depth; rendered now

:class:`TwinCameraSource` implements it on the twin's :class:`sim.camera.SimCamera` (its noise
model included). Rendering calls PyBullet from the streaming thread: pass the ``lock`` the loop
that steps the twin holds while stepping, so a render never runs inside a step.

Depth is quantised to ``depth_units`` (1 mm, the D435's default) and saturates at 65535 counts.
Frames go out at ``fps`` (a render slower than the period drops the slots it overran; the
frame numbers stay consecutive, the timestamps are the slots' starts on the camera's own clock,
exact multiples of the period as a hardware clock gives them).

Wire faults: :meth:`CameraStreamServer.pull_cable` freezes the camera (connections stay open,
no frame is sent: the driver's capture times out); :meth:`CameraStreamServer.drop_clients`
closes the connections (the driver reports the stream lost). :meth:`restore` resumes frames.
"""

from __future__ import annotations

import socket
import threading
import time
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from drivers.camera import Intrinsics
from drivers.realsense.stream import StreamInfo, encode_frame, encode_info

DEPTH_UNITS = 0.001  #: m per Z16 count (the D435's default)


@runtime_checkable
class FrameSource(Protocol):
    """What the emulated camera sees (see the module doc)."""

    def intrinsics(self) -> Intrinsics: ...

    def frame(self) -> tuple[NDArray[np.uint8], NDArray[np.floating]]: ...


class TwinCameraSource:
    """:class:`FrameSource` on the twin's camera; ``lock``: held while rendering (see the
    module doc), or None when nothing else drives PyBullet meanwhile."""

    def __init__(self, camera, lock: threading.Lock | None = None) -> None:  # type: ignore[no-untyped-def]
        self._camera = camera
        self._lock = lock

    def intrinsics(self) -> Intrinsics:
        return self._camera.intrinsics()

    def frame(self) -> tuple[NDArray[np.uint8], NDArray[np.floating]]:
        if self._lock is None:
            f = self._camera.capture()
        else:
            with self._lock:
                f = self._camera.capture()
        return f.rgb, f.depth


def to_z16(depth: NDArray[np.floating], depth_units: float = DEPTH_UNITS) -> NDArray[np.uint16]:
    """Metres -> Z16 counts (0 stays 0 = no depth; beyond the range saturates at 65535)."""
    d = np.asarray(depth, dtype=np.float64)
    counts = np.rint(np.where(np.isfinite(d) & (d > 0.0), d, 0.0) / depth_units)
    return np.clip(counts, 0, 65535).astype(np.uint16)


class CameraStreamServer:
    """Serves frames of ``source`` to every client on ``(host, port)`` (0: a free port; see
    :attr:`port`). ``fps``: frame pairs a second; ``serial``/``firmware``: the identity the
    driver reports. :meth:`start` renders and sends on a thread; :meth:`stop` joins."""

    def __init__(self, source: FrameSource, host: str = "127.0.0.1", port: int = 0,
                 fps: int = 30, depth_units: float = DEPTH_UNITS, serial: str = "EMU0435",
                 firmware: str = "emulated") -> None:
        if fps <= 0:
            raise ValueError("fps must be > 0")
        intr = source.intrinsics()
        self.source, self.fps, self.depth_units = source, fps, depth_units
        self.info = StreamInfo(width=intr.width, height=intr.height, fps=fps,
                               depth_units=depth_units, fx=intr.fx, fy=intr.fy, cx=intr.cx,
                               cy=intr.cy, serial=serial, firmware=firmware,
                               name="Intel RealSense D435 (emulated)")
        self._listen = socket.create_server((host, port))
        self._listen.settimeout(0.05)
        self.host, self.port = self._listen.getsockname()[:2]
        self._clients: list[socket.socket] = []
        self._started: dict[socket.socket, float] = {}  # each client's stream start (monotonic)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._frozen = threading.Event()
        self.frames_sent = 0  #: frame pairs sent (to any client)
        self._threads = [threading.Thread(target=self._accept, name="emu-d435-accept",
                                          daemon=True),
                         threading.Thread(target=self._stream, name="emu-d435-stream",
                                          daemon=True)]

    def start(self) -> CameraStreamServer:
        for t in self._threads:
            t.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            if t.is_alive():
                t.join(timeout=5.0)
        self.drop_clients()
        self._listen.close()

    def __enter__(self) -> CameraStreamServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def pull_cable(self) -> None:
        """Freeze the camera: connections stay, no frame is sent until :meth:`restore`."""
        self._frozen.set()

    def restore(self) -> None:
        self._frozen.clear()

    def drop_clients(self) -> None:
        """Close every connection (the driver sees the stream end)."""
        with self._lock:
            clients, self._clients = self._clients, []
            self._started.clear()
        for c in clients:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()

    @property
    def clients(self) -> int:
        with self._lock:
            return len(self._clients)

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._listen.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            try:
                conn.sendall(encode_info(self.info))
            except OSError:
                conn.close()
                continue
            with self._lock:
                self._clients.append(conn)
                self._started[conn] = time.monotonic()

    def _stream(self) -> None:
        """Frames at the camera's own clock: exposure slot ``k`` starts at ``t0 + k / fps`` and
        its frame carries exactly that timestamp, as a camera's hardware clock does. A render
        that overruns its slot drops the slots it covered (the next frame takes the next slot
        not yet begun), so the stamps stay on the fps grid: librealsense's syncer expects
        frames every 1000 / fps ms. Each client's clock and frame counter start with its stream
        (its connection), as a camera's start when the host starts it: stamped with this
        machine's monotonic time (hours, in ms) the syncer paired 1 capture in 8 at 30 fps; with
        stamps 12 s into the stream it paired none for the first 9 s; and with the stamps
        restarted but the frame numbers carried on from an earlier client (the 223rd frame
        first) it paired 1 in 5 s at 6 fps, against the first pair after one period when the
        numbers start at 1 (librealsense 2.5x, measured)."""
        period = 1.0 / self.fps
        t0 = time.monotonic()
        k = 0
        while not self._stop.is_set():
            now = time.monotonic()
            slot = t0 + k * period
            if now < slot:
                self._stop.wait(slot - now)
                continue
            k = max(k, int((now - t0) / period))  # slots already past are dropped
            slot = t0 + k * period
            k += 1
            if self._frozen.is_set() or not self.clients:
                continue
            rgb, depth = self.source.frame()
            z16 = to_z16(depth, self.depth_units)
            with self._lock:
                clients = [(c, self._started.get(c, slot)) for c in self._clients]
            for c, started in clients:
                # This client's stream clock: on the slot grid, from about one period at its start,
                # and its frame counter with it (slot 1, 2, ...; dropped slots skip numbers).
                n = max(1, round((slot - started) / period) + 1)
                stamp_ms = n * period * 1000.0
                try:
                    c.sendall(encode_frame(n, stamp_ms, z16, rgb))
                except OSError:
                    with self._lock:
                        if c in self._clients:
                            self._clients.remove(c)
                        self._started.pop(c, None)
                    c.close()
            self.frames_sent += 1
