"""A Robotiq FT300 on a pseudo-terminal: the driver opens a real tty and talks the real protocol.

The peer holds the master side of an ``os.openpty()`` pair; :attr:`FT300Peer.port` is the slave's
path, which the driver opens with pyserial like a USB serial adapter. Like the sensor it:

* stays silent until it receives the Modbus "start stream" request (function 16, ``0x0200`` into
  register 410) with a valid CRC **for its own unit id**; it answers that request with the Modbus
  response, then streams 16-byte frames at ``rate_hz``; a request to another unit id is ignored,
  as on a shared RS-485 line;
* stops streaming when it sees a run of ``0xFF`` bytes.

Fault injection (each applied between two frames): :meth:`inject_corrupt` (a frame with a wrong
CRC), :meth:`inject_partial` (the first bytes of a frame only), :meth:`inject_garbage` (bytes
that contain no header), :meth:`go_silent` / :meth:`resume`. Every valid frame's write time is
logged with its sequence number, so tests can measure latency; the frame values come from
``wrench_of(seq)``.
"""

from __future__ import annotations

import os
import select
import struct
import threading
import time
import tty
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np

# The sensor's side of the protocol comes from the FT300 emulator (sim/emulate, written from the
# manual, with its own CRC), never from the driver under test: a peer built on the driver's own
# frames and CRC would check the driver against itself.
from sim.emulate.ft300_stream import HEADER, STREAM_REGISTER, STREAM_START, stream_frame
from sim.emulate.rtu import crc16, with_crc

FRAME_LEN = 16  #: the manual's stream frame: header, six int16 values, CRC


def encode_frame(wrench: Sequence[float]) -> bytes:
    return stream_frame(np.asarray(wrench, float))


def start_request(unit_id: int) -> bytes:
    """The manual's "start stream": write 0x0200 into register 410 (function 16, one
    register, two bytes)."""
    return with_crc(struct.pack(">BBHHBH", unit_id, 0x10, STREAM_REGISTER, 1, 2, STREAM_START))

Wrench = Sequence[float]


def _default_wrench(seq: int) -> Wrench:
    return [1.0, -2.0, 3.5, 0.1, -0.2, 0.3]


class FT300Peer:
    """The FT300 side of a pseudo-terminal pair (start it, point the driver at :attr:`port`)."""

    def __init__(self, unit_id: int = 9, rate_hz: float = 100.0,
                 wrench_of: Callable[[int], Wrench] = _default_wrench) -> None:
        self.unit_id = unit_id
        self.rate_hz = rate_hz
        self.wrench_of = wrench_of
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no CR/LF translation: bytes pass unchanged
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._faults: deque[bytes] = deque()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._silent = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ft300-peer", daemon=True)
        self.streaming = threading.Event()
        self.requests: list[bytes] = []  #: every valid Modbus request received
        self.ignored_requests: list[bytes] = []  #: valid requests for another unit id
        self.stop_bytes_seen = 0
        self.sent: list[tuple[int, float]] = []  #: (seq, time.monotonic() just before the write)
        self.injected_bytes = 0  #: bytes of damaged frames and garbage written
        self.response_bytes = 0  #: bytes of Modbus responses written

    # -- control -------------------------------------------------------------------------------

    def start(self) -> FT300Peer:
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread (joined) and close both ends of the pty."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> FT300Peer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def inject_corrupt(self, seq: int = 0) -> None:
        """Queue a full frame whose CRC is wrong (one payload byte flipped after the CRC)."""
        frame = bytearray(encode_frame(list(self.wrench_of(seq))))
        frame[5] ^= 0x01
        assert HEADER not in frame[1:], "the damaged frame must not hide a second header"
        self._queue(bytes(frame))

    def inject_partial(self, n: int = 7, seq: int = 0) -> None:
        """Queue the first ``n`` bytes of a frame (a frame cut short, as when a byte is lost)."""
        assert 2 <= n < FRAME_LEN
        self._queue(encode_frame(list(self.wrench_of(seq)))[:n])

    def inject_garbage(self, data: bytes = b"\x00\x13\x37\xaa\x55") -> None:
        """Queue bytes between frames (line noise); they must not contain the header."""
        assert HEADER not in data
        self._queue(data)

    def go_silent(self) -> None:
        """Stop writing (the cable pulled, the sensor unpowered) until :meth:`resume`."""
        self._silent.set()

    def resume(self) -> None:
        self._silent.clear()

    def _queue(self, data: bytes) -> None:
        with self._lock:
            self._faults.append(data)

    # -- the device ----------------------------------------------------------------------------

    def _write(self, data: bytes) -> bool:
        """Write all of ``data`` unless the reader side is full or gone (then drop the rest)."""
        view = memoryview(data)
        deadline = time.monotonic() + 0.5
        while view:
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.001)
                continue
            except OSError:
                return False
            view = view[n:]
        return True

    def _read(self, rx: bytearray) -> None:
        """Take pending bytes from the host; act on start requests and runs of 0xFF."""
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, OSError):
            return
        rx += data
        ff = data.count(0xFF)
        if ff:
            self.stop_bytes_seen += ff
            if self.stop_bytes_seen >= 10:
                self.streaming.clear()
        # The start request is 11 bytes: find any complete one with a valid CRC.
        while len(rx) >= 11:
            frame = bytes(rx[:11])
            if crc16(frame[:9]) == int.from_bytes(frame[9:], "little") and frame[1] == 0x10:
                del rx[:11]
                self._on_request(frame)
            else:
                del rx[:1]

    def _on_request(self, frame: bytes) -> None:
        expected = start_request(frame[0])
        if frame[0] != self.unit_id:
            self.ignored_requests.append(frame)
            return
        self.requests.append(frame)
        if frame == expected:
            response = with_crc(frame[:6])  # echo of unit, function, register, count
            self._write(response)
            self.response_bytes += len(response)
            self.stop_bytes_seen = 0
            self.streaming.set()

    def _run(self) -> None:
        rx = bytearray()
        period = 1.0 / self.rate_hz
        seq = 0
        next_t = time.monotonic()
        while not self._stop.is_set():
            timeout = max(0.0, next_t - time.monotonic()) if self.streaming.is_set() else 0.01
            ready, _, _ = select.select([self._master], [], [], timeout)
            if ready:
                self._read(rx)
            if not self.streaming.is_set():
                next_t = time.monotonic()
                continue
            now = time.monotonic()
            if now < next_t:
                continue
            next_t = max(next_t + period, now - period)  # no burst after a stall
            if self._silent.is_set():
                continue
            with self._lock:
                faults = list(self._faults)
                self._faults.clear()
            for f in faults:
                if self._write(f):
                    self.injected_bytes += len(f)
            seq += 1
            frame = encode_frame(list(self.wrench_of(seq)))
            # Recorded before the write: a reader fast enough can hold the frame before this
            # thread runs again, and a test comparing what it read with `sent` then saw one
            # frame more than was sent.
            self.sent.append((seq, time.monotonic()))
            if not self._write(frame):
                self.sent.pop()
