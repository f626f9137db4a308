"""A Robotiq FT300 on a pseudo-terminal, its readings the twin's wrist load.

Written from Robotiq's FT 300 instruction manual ("Serial communication": Modbus RTU at
19200 bit/s 8N1, slave id 9; the data stream), not from this project's driver:

* after power-up the sensor is a Modbus RTU slave: function 3 or 4 on registers 180..185 reads
  Fx, Fy, Fz (x100, N) and Mx, My, Mz (x1000, N*m) as signed 16-bit values; other addresses get
  exception 02, other functions exception 01, other unit ids nothing;
* writing ``0x0200`` into register 410 (function 16) is answered as Modbus does and starts the
  **stream**: 16-byte frames ``0x20 0x4E``, the six values little-endian, then the Modbus
  CRC-16 of those 14 bytes low byte first, at 100 Hz. While streaming the sensor answers no
  request; a run of ``0xFF`` bytes (the manual: send them for about 0.5 s, 50 times, to be sure)
  ends the stream and the sensor is a Modbus slave again.

Readings: the backend's noiseless load, plus a power-up offset (constant until the next power-up,
which is why a driver biases it away) and Gaussian noise per axis, rounded to the frame's
resolution and saturated at the int16 range. The noise defaults are the signal noise Robotiq's
FT 300 specifications quote, 0.1 N per force axis and 0.005 N*m per moment axis; the offset
magnitude is not specified and is a parameter (a few newtons, as the twin's sensor has).

Backend interface (:class:`WrenchBackend`)::

    wrench() -> array of 6 floats   # the load on the sensor now: Fx, Fy, Fz (N), Mx, My, Mz
                                    #   (N*m) in the sensor frame, noiseless, offset-free

:class:`TwinWrist` implements it on the twin's :class:`sim.ft_sensor.SimForceTorqueSensor` (its
noiseless sample of the last control step; the twin's own noise and offset are not used, so they
are not counted twice). It is read from the stream's thread; it touches no PyBullet state.

The line: a pseudo-terminal (the default; point the driver at :attr:`FT300Emulator.port`), or,
with ``listen=(host, port)``, the raw TCP port of a serial device server (an RS-485/USB-to-Ethernet
gateway in TCP-server mode: the line's bytes both ways, one client at a time; with no client the
sensor streams into the void). :attr:`FT300Emulator.port` is then ``socket://host:port``, which
pyserial's ``serial_for_url`` opens. Why both: on a loaded host the kernel hands pty bytes to the
reader through a work queue, and on this project's shared 2-core machine that hop alone held
frames back 0.1-3 s while loopback TCP delivered them in under 2 ms at the 99th percentile
(docs/emulator.md, "FT300 stale").

Wire faults: :meth:`FT300Emulator.pull_cable` takes the sensor off the line (its cable carries
power: nothing is sent, what arrives is lost); :meth:`FT300Emulator.restore` plugs it back, and
it comes up as after power-up: a Modbus slave with a new offset, silent until a start request.
:meth:`FT300Emulator.go_silent` / :meth:`FT300Emulator.resume` break only what the sensor sends
(it stays powered and streaming, its bytes are lost). Line noise between two stream frames:
:meth:`FT300Emulator.inject` (any bytes), :meth:`FT300Emulator.inject_damaged_frame` (a frame
whose CRC fails), :meth:`FT300Emulator.inject_partial_frame` (a frame cut short).

What it received and sent, for tests: :attr:`FT300Emulator.received` (every valid request for
its unit), :attr:`FT300Emulator.ignored` (those for another unit), :attr:`FT300Emulator.ff_bytes`
(the ``0xFF`` bytes that end a stream), byte counts of its replies and of the injected noise,
and with ``log_frames=True`` every stream frame's six values and write time
(:attr:`FT300Emulator.sent`).
"""

from __future__ import annotations

import os
import select
import socket
import struct
import threading
import time
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from sim.emulate.rtu import LineDevice, close_fds, crc_ok, open_pty, with_crc

HEADER = b"\x20\x4e"
DEFAULT_UNIT_ID = 9
BAUDRATE = 19200  #: the FT300's fixed line rate (8N1)
RATE_HZ = 100.0  #: the manual's stream rate
FORCE_REGISTER = 180  #: Fx; 181 Fy, 182 Fz, 183 Mx, 184 My, 185 Mz
STREAM_REGISTER = 410
STREAM_START = 0x0200
STOP_RUN = 20  #: 0xFF bytes in a row that end the stream here (the manual sends about 50)
FORCE_NOISE = 0.1  #: N, signal noise per force axis (FT 300 specifications)
MOMENT_NOISE = 0.005  #: N*m, signal noise per moment axis (FT 300 specifications)
SCALE = np.array([100.0] * 3 + [1000.0] * 3)  #: counts per N and per N*m


@runtime_checkable
class WrenchBackend(Protocol):
    """The load the emulated sensor measures (see the module doc)."""

    def wrench(self) -> NDArray[np.float64]: ...


class TwinWrist:
    """:class:`WrenchBackend` on the twin's wrist sensor (its noiseless sample, sensor frame),
    plus a load step while one is injected (``emulate.faults``' ``force_step``: a collision as
    the sensor reads it, so that the cell's limits can be timed on the whole emulated cell)."""

    def __init__(self, ft) -> None:  # type: ignore[no-untyped-def]
        """``ft``: the twin's ``SimForceTorqueSensor``."""
        self._ft = ft
        self._lock = threading.Lock()
        self._step: NDArray[np.float64] | None = None
        #: time.monotonic() when the first reading with the step was taken for the stream
        self.first_stepped: float | None = None

    def inject(self, wrench: NDArray[np.float64]) -> None:
        """Add ``wrench`` (N, N*m; sensor frame) to every reading until :meth:`clear`."""
        with self._lock:
            self._step, self.first_stepped = np.asarray(wrench, float), None

    def clear(self) -> None:
        with self._lock:
            self._step = None

    def wrench(self) -> NDArray[np.float64]:
        load = np.array(self._ft.sampled_true_load(), dtype=float)
        with self._lock:
            if self._step is None:
                return load
            if self.first_stepped is None:
                self.first_stepped = time.monotonic()
            return load + self._step


def counts(reading: NDArray[np.float64]) -> list[int]:
    """The six int16 values of a reading (N, N*m), rounded and saturated."""
    c = np.clip(np.rint(np.asarray(reading, float) * SCALE), -32768, 32767)
    return [int(v) for v in c]


FRAME_LEN = 16  #: bytes of a stream frame: the header, six int16 values, the CRC


def frame_of(values: list[int]) -> bytes:
    """The 16-byte stream frame carrying six int16 ``values`` (counts)."""
    return with_crc(HEADER + struct.pack("<6h", *values))


def stream_frame(reading: NDArray[np.float64]) -> bytes:
    """One 16-byte stream frame for ``reading`` (N, N*m)."""
    return frame_of(counts(reading))


class FT300Emulator(LineDevice):
    """The FT300 side of a pseudo-terminal (start it; point a driver at :attr:`port`).

    ``backend``: the load; ``unit_id``: its Modbus id; ``rate_hz``: stream frames a second;
    ``force_noise`` / ``moment_noise``: standard deviations (N, N*m) per axis;
    ``force_offset`` / ``moment_offset``: the power-up offset is uniform within +-these per axis;
    ``seed``: the noise and offsets' generator; ``log_frames``: keep :attr:`sent`, every stream
    frame's values and write time (it grows by the stream rate: for tests, not for a long run).
    """

    def __init__(
        self,
        backend: WrenchBackend,
        unit_id: int = DEFAULT_UNIT_ID,
        rate_hz: float = RATE_HZ,
        force_noise: float = FORCE_NOISE,
        moment_noise: float = MOMENT_NOISE,
        force_offset: float = 3.0,
        moment_offset: float = 0.1,
        seed: int = 0,
        listen: tuple[str, int] | None = None,
        log_frames: bool = False,
    ) -> None:
        if rate_hz <= 0:
            raise ValueError("rate_hz must be > 0")
        super().__init__("emu-ft300")
        self.backend, self.unit_id, self.rate_hz = backend, unit_id, rate_hz
        self._sigma = np.array([force_noise] * 3 + [moment_noise] * 3)
        self._offset_range = np.array([force_offset] * 3 + [moment_offset] * 3)
        self._rng = np.random.default_rng(seed)
        self.offset = self._power_up_offset()
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        if listen is None:
            self._master, self._slave, self.port = open_pty()
        else:
            self._master = self._slave = -1
            self._listener = socket.create_server(listen)
            self._listener.setblocking(False)
            host, port = self._listener.getsockname()[:2]
            self.port = f"socket://{host}:{port}"
        self.clients = 0  #: TCP clients accepted (the pty has none)
        self.streaming = threading.Event()
        self.frames_sent = 0
        self.max_gap = 0.0  #: s, the longest time between two frames sent in one stream
        self.late_frames = 0  #: frames sent more than two periods after the one before
        self.requests = 0  #: valid Modbus requests for this unit, answered
        self.power_ups = 1
        self.received: list[bytes] = []  #: every valid request for this unit, in order
        self.ignored: list[bytes] = []  #: valid requests for another unit (left unanswered)
        self.ff_bytes = 0  #: 0xFF bytes received (a run of them ends the stream)
        self.reply_bytes = 0  #: bytes of Modbus replies written to the line
        self.injected_bytes = 0  #: bytes of injected noise written to the line
        #: with ``log_frames``: (the six values, time.monotonic() just before the write) of each
        #: stream frame written, in order
        self.sent: list[tuple[list[int], float]] | None = [] if log_frames else None
        self._silent = threading.Event()
        self._noise: list[bytes] = []
        self._noise_lock = threading.Lock()

    def _power_up_offset(self) -> NDArray[np.float64]:
        return self._rng.uniform(-self._offset_range, self._offset_range)

    # --- control ----------------------------------------------------------------------------

    def _close_line(self) -> None:
        """Both ends of the pseudo-terminal, or the gateway's client and listening sockets."""
        close_fds(self._master, self._slave)
        for sock in (self._client, self._listener):
            if sock is not None:
                sock.close()

    def pull_cable(self) -> None:
        """Unplug the sensor: no power, nothing sent, everything arriving lost."""
        super().pull_cable()
        self.streaming.clear()

    def restore(self) -> None:
        """Plug it back: it powers up as a Modbus slave (not streaming) with a new offset."""
        if self._cut.is_set():
            self.offset = self._power_up_offset()
            self.power_ups += 1
        super().restore()

    def go_silent(self) -> None:
        """Break what the sensor sends (a broken transmit wire): it stays powered, keeps its
        state and keeps streaming, and every byte it sends is lost until :meth:`resume`."""
        self._silent.set()

    def resume(self) -> None:
        self._silent.clear()

    def inject(self, data: bytes) -> None:
        """Line noise: ``data`` goes on the line before the next stream frame (while streaming)."""
        with self._noise_lock:
            self._noise.append(bytes(data))

    def inject_damaged_frame(self, reading: NDArray[np.float64]) -> None:
        """A whole frame for ``reading`` with one payload bit flipped: its CRC fails."""
        frame = bytearray(stream_frame(np.asarray(reading, float)))
        frame[5] ^= 0x01
        if HEADER in frame[1:]:
            raise ValueError("the damaged frame would hide a second header; pick other values")
        self.inject(bytes(frame))

    def inject_partial_frame(self, reading: NDArray[np.float64], n: int) -> None:
        """The first ``n`` bytes (2 <= n < 16) of the frame for ``reading``: a frame cut short."""
        if not 2 <= n < FRAME_LEN:
            raise ValueError(f"a partial frame has 2..{FRAME_LEN - 1} bytes, not {n}")
        self.inject(stream_frame(np.asarray(reading, float))[:n])

    def reading(self) -> NDArray[np.float64]:
        """What the sensor measures now: the load, its offset and a draw of noise (N, N*m)."""
        load = np.asarray(self.backend.wrench(), float)
        return load + self.offset + self._sigma * self._rng.standard_normal(6)

    # --- the line ---------------------------------------------------------------------------

    def _line(self) -> int:
        """The line's file descriptor now: the pty's master, the TCP client's socket, or -1
        (a gateway with no client: what the sensor sends is lost)."""
        if self._listener is None:
            return self._master
        return self._client.fileno() if self._client is not None else -1

    def _accept(self) -> None:
        """Take a waiting TCP client; it replaces the one before (a gateway serves one)."""
        assert self._listener is not None
        try:
            conn, _ = self._listener.accept()
        except (BlockingIOError, OSError):
            return
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if self._client is not None:
            self._client.close()
        self._client = conn
        self.clients += 1

    def _hang_up(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def _write(self, data: bytes) -> bool:
        fd = self._line()
        if fd < 0 or self._silent.is_set():
            return False  # no client on the gateway, or a broken wire: the bytes go nowhere
        view = memoryview(data)
        deadline = time.monotonic() + 0.2
        while view:
            try:
                n = os.write(fd, view)
            except BlockingIOError:
                if time.monotonic() > deadline:
                    return False  # nobody reads: the frame is lost, as on a real line
                time.sleep(0.001)
                continue
            except OSError:
                if self._listener is not None:
                    self._hang_up()
                return False
            view = view[n:]
        return True

    def _run(self) -> None:
        rx = bytearray()
        ff_run = 0
        period = 1.0 / self.rate_hz
        next_t = time.monotonic()
        last_sent: float | None = None
        while not self._stop.is_set():
            streaming = self.streaming.is_set()
            wait = max(0.0, next_t - time.monotonic()) if streaming else 0.01
            fd = self._line()
            watch = [fd] if fd >= 0 else []
            if self._listener is not None:
                watch.append(self._listener.fileno())
            ready, _, _ = select.select(watch, [], [], wait)
            if self._listener is not None and self._listener.fileno() in ready:
                self._accept()
            if fd >= 0 and fd in ready and fd == self._line():  # (not a client just replaced)
                try:
                    data = os.read(fd, 4096)
                except (BlockingIOError, OSError):
                    data = b""
                if not data and self._listener is not None:
                    self._hang_up()  # the client left (EOF); the sensor itself is unaffected
                if self._cut.is_set():
                    data = b""
                self.ff_bytes += data.count(0xFF)
                for byte in data:
                    ff_run = ff_run + 1 if byte == 0xFF else 0
                    if ff_run >= STOP_RUN and self.streaming.is_set():
                        self.streaming.clear()
                        rx.clear()
                if not self.streaming.is_set():
                    rx += data.lstrip(b"\xff") if not rx else data
                    self._requests(rx)
            if not self.streaming.is_set():
                next_t = time.monotonic()
                last_sent = None
                continue
            now = time.monotonic()
            if now < next_t:
                continue
            next_t = max(next_t + period, now - period)  # late: no burst to catch up
            with self._noise_lock:
                noise, self._noise = self._noise, []
            for data in noise:
                if self._write(data):
                    self.injected_bytes += len(data)
            values = counts(self.reading())
            if self.sent is not None:
                # Logged before the write: a reader fast enough holds the frame before this
                # thread runs again, and would otherwise find it not yet sent.
                self.sent.append((values, time.monotonic()))
            if not self._write(frame_of(values)):
                if self.sent is not None:
                    self.sent.pop()
            else:
                self.frames_sent += 1
                sent = time.monotonic()
                if last_sent is not None:
                    gap = sent - last_sent
                    self.max_gap = max(self.max_gap, gap)
                    self.late_frames += gap > 2 * period
                last_sent = sent

    def _requests(self, rx: bytearray) -> None:
        """Serve complete Modbus requests at the start of ``rx`` (slave mode)."""
        while len(rx) >= 8:
            fc = rx[1]
            n = 8 if fc in (3, 4) else (9 + rx[6] if fc == 16 else 8)
            if len(rx) < n:
                return
            frame = bytes(rx[:n])
            if not crc_ok(frame):
                del rx[:1]
                continue
            del rx[:n]
            if frame[0] != self.unit_id:
                self.ignored.append(frame)
                continue
            self.requests += 1
            self.received.append(frame)
            reply, start = self._reply(frame)
            time.sleep(len(reply) * 10 / BAUDRATE)  # the reply's time on the line
            if self._write(reply):
                self.reply_bytes += len(reply)
            if start:
                self.streaming.set()

    def _reply(self, frame: bytes) -> tuple[bytes, bool]:
        unit, fc = frame[0], frame[1]

        def error(code: int) -> bytes:
            return with_crc(bytes([unit, fc | 0x80, code]))

        addr, count = struct.unpack(">HH", frame[2:6])
        if fc in (3, 4):
            if not (FORCE_REGISTER <= addr and addr + count <= FORCE_REGISTER + 6 and count):
                return error(0x02), False
            values = counts(self.reading())[addr - FORCE_REGISTER:addr - FORCE_REGISTER + count]
            body = bytes([unit, fc, 2 * count]) + struct.pack(f">{count}h", *values)
            return with_crc(body), False
        if fc == 16:
            if addr != STREAM_REGISTER or count != 1:
                return error(0x02), False
            value = int.from_bytes(frame[7:9], "big")
            if value != STREAM_START:
                return error(0x03), False
            return with_crc(frame[:6]), True
        return error(0x01), False
