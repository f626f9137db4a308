"""The Robotiq FT300 over its serial link: :class:`FT300` implements ``ForceTorqueSensor``.

A background thread reads the stream and keeps the newest valid sample and the monotonic time it
arrived; the tree's tick only copies that under a lock, so a slow or dead line never blocks a
tick. A **stale sample is an error**: :meth:`FT300.wrench` raises :class:`DeviceError` when the
newest sample is older than ``stale_after`` (or there is none yet, or the reader died). A force
guard that keeps comparing an old, quiet reading against its limit would pass while the tool
crushes something, so the guard must see the stream die as a failure, not as "no force".
:meth:`FT300.age` never raises, for code that wants to report the age itself.
"""

from __future__ import annotations

import select
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.ft300.protocol import (
    FRAME_LEN,
    FrameParser,
    start_stream_request,
    stop_stream_bytes,
)
from drivers.health import CheckResult, DeviceError, backoff_delays
from drivers.limit_guard import LimitGuard

DEVICE = "FT300"
READ_WAIT = 0.02  #: s the reader waits for bytes before it looks at its stop flag again
READ_CHUNK = 4096  #: bytes asked of the port per read; it returns what has arrived (timeout 0)

#: Optional hook called with each valid sample and its arrival time (``time.monotonic()``), on
#: the thread that took it; for logging and latency measurements. It must be quick and must not
#: raise (an exception ends the reader, and wrench() then raises DeviceError).
SampleHook = Callable[[NDArray[np.float64], float], None]


class FT300:
    """A Robotiq FT300 streaming over ``port`` (implements ``drivers.ft_sensor.ForceTorqueSensor``).

    Configuration: ``port`` (e.g. ``/dev/ttyUSB1``), ``baudrate`` (19200 on the FT300),
    ``unit_id`` (the Modbus address the start request goes to, 9 by default), ``timeout`` (s: the
    first valid frame must arrive this soon after the start request), ``stale_after`` (s: a
    sample older than this is an error), ``bias_samples`` (samples averaged by :meth:`bias`),
    ``open_attempts`` (bounded tries to open the port, with back-off), ``on_sample`` (called with
    each sample and its arrival time on the thread that took it: the reader, or a caller of
    :meth:`wrench` that found the newest sample stale).

    :attr:`limits` is the running motion's force-torque limit, compared with every sample on
    the thread that took it (:class:`drivers.limit_guard.LimitGuard`; connect the arm's stop to
    it). Use :meth:`start` / :meth:`stop` or ``with FT300(...) as ft:``.
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 19200,
        unit_id: int = 9,
        timeout: float = 1.0,
        stale_after: float = 0.05,
        bias_samples: int = 20,
        open_attempts: int = 3,
        on_sample: SampleHook | None = None,
    ) -> None:
        if stale_after <= 0.0 or timeout <= 0.0:
            raise ValueError("timeout and stale_after must be positive")
        self.port, self.baudrate, self.unit_id = port, baudrate, unit_id
        self.timeout, self.stale_after = timeout, stale_after
        self.open_attempts = max(1, open_attempts)
        self._on_sample = on_sample
        self._lock = threading.Lock()  #: the newest sample and its statistics
        self._io = threading.Lock()  #: the line and the parser: one reader at a time
        self._recent: deque[NDArray[np.float64]] = deque(maxlen=max(1, bias_samples))
        self._stamps: deque[float] = deque(maxlen=101)  #: for the rate over the last 100 gaps
        self._newest: NDArray[np.float64] | None = None
        self._stamp = -np.inf
        self._zero = np.zeros(6)
        self._max_gap = 0.0
        self._parser = FrameParser()
        self._serial: Any = None
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._first = threading.Event()
        self._reader_error: str | None = None
        #: the running motion's limits, checked against every sample as it arrives
        self.limits = LimitGuard()

    # -- life cycle ------------------------------------------------------------------------

    def __enter__(self) -> FT300:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        """True while the reader thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Open the port, send the start request, start the reader, wait for the first frame.

        Raises :class:`DeviceError` naming the port when it cannot be opened (after
        ``open_attempts`` tries with back-off) or no valid frame arrives within ``timeout``
        (sensor unpowered, wrong unit id, wrong baud rate): either way the cell must not run.
        """
        if self.running:
            return
        ser = self._open()
        self._serial = ser
        self._stopping.clear()
        self._first.clear()
        self._reader_error = None
        try:
            ser.reset_input_buffer()
            ser.write(start_stream_request(self.unit_id))
            ser.flush()
        except Exception as exc:  # serial.SerialException, OSError
            self._close_port()
            raise DeviceError(DEVICE, self.port, f"cannot send the start request: {exc}") from exc
        self._thread = threading.Thread(target=self._read_loop, name=f"ft300-{self.port}",
                                        daemon=True)
        self._thread.start()
        if not self._first.wait(self.timeout):
            cause = self._reader_error or (
                f"no valid stream frame within {self.timeout:g} s of the start request to unit "
                f"{self.unit_id} at {self.baudrate} baud (powered? right unit id and baud rate?)"
            )
            self.stop()
            raise DeviceError(DEVICE, self.port, cause)

    def stop(self) -> None:
        """Stop the reader (joined), tell the sensor to stop streaming, close the port.

        Safe to call twice and after a failed start.
        """
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        # Not while a caller of wrench() is taking bytes from the line (bounded: a drain
        # never waits for the line).
        held = self._io.acquire(timeout=1.0)
        try:
            ser = self._serial
            if ser is not None:
                try:
                    ser.write(stop_stream_bytes())
                    ser.flush()
                except Exception:  # the line may already be gone; closing is what matters
                    pass
            self._close_port()
        finally:
            if held:
                self._io.release()

    def _open(self) -> Any:
        import serial  # the hardware path only: the twin never needs pyserial

        delays = backoff_delays(self.open_attempts)
        last: Exception | None = None
        for attempt in range(self.open_attempts):
            try:
                # serial_for_url: a device path, or a serial device server's raw TCP port
                # (``socket://host:port``, an RS-485/USB-to-Ethernet gateway) -- same bytes.
                # timeout 0: a read returns what has arrived; the reader waits in select().
                return serial.serial_for_url(self.port, self.baudrate, bytesize=8, parity="N",
                                             stopbits=1, timeout=0, write_timeout=0.5)
            except (serial.SerialException, OSError, ValueError) as exc:
                last = exc
                if attempt < len(delays):
                    time.sleep(delays[attempt])
        raise DeviceError(DEVICE, self.port,
                          f"cannot open the serial port ({self.open_attempts} tries): {last}")

    def _close_port(self) -> None:
        ser, self._serial = self._serial, None
        if ser is None:
            return
        if str(self.port).startswith("socket://"):
            # pyserial's TCP port sleeps 0.3 s after closing its socket (room for a quick
            # reconnect to the same server); nothing here waits for that, and a cell stopping
            # after a lost arm link must be gone within 0.5 s.
            threading.Thread(target=_close_quietly, args=(ser,), name="ft300-close",
                             daemon=True).start()
        else:
            _close_quietly(ser)

    def _read_loop(self) -> None:
        """Reader thread: wait for bytes, then take them under the line's lock (never blocking
        there); records why the line died, if it does.

        The wait is outside the lock, so a caller of :meth:`wrench` that finds the newest sample
        stale can take what has arrived itself while this thread is not scheduled."""
        ser = self._serial
        assert ser is not None
        try:
            fd = ser.fileno()
            while not self._stopping.is_set():
                ready, _, _ = select.select([fd], [], [], READ_WAIT)
                if not ready:
                    continue
                with self._io:
                    self._drain(ser)
                # A frame under way: sleep until its last byte is due (10 bits a byte), so a
                # frame costs one wake-up, not one per byte.
                missing = self._parser.missing()
                if missing < FRAME_LEN:
                    self._stopping.wait(missing * 10.0 / self.baudrate)
        except Exception as exc:  # any failure of the line ends the stream
            if not self._stopping.is_set():
                self._reader_error = f"serial read failed: {exc}"

    def _drain(self, ser: Any) -> None:
        """Take every byte already received and store the samples it completes; never waits
        (the port's timeout is 0). Call with ``_io``.

        A line that is gone raises here: a serial device that was unplugged and a TCP port
        whose server closed both report "readable" and then read nothing, which pyserial
        raises as an error."""
        while True:
            data = ser.read(READ_CHUNK)
            if not data:
                return
            samples = self._parser.feed(data)
            if samples:
                self._store(samples, time.monotonic())

    def _store(self, samples: list[NDArray[np.float64]], now: float) -> None:
        with self._lock:
            for s in samples:
                self._recent.append(s)
            if self._stamps:
                self._max_gap = max(self._max_gap, now - self._stamps[-1])
            self._stamps.append(now)
            self._newest = samples[-1]
            self._stamp = now
            zero = self._zero
        self._first.set()
        for s in samples:  # outside the lock: a trip stops the arm, which takes a while
            self.limits.feed(s - zero, now)
        if self._on_sample is not None:
            for s in samples:
                self._on_sample(s, now)

    # -- ForceTorqueSensor -------------------------------------------------------------------

    def _fresh_newest(self) -> NDArray[np.float64]:
        """The newest raw sample, or :class:`DeviceError` saying why it cannot be trusted.

        A sample that looks stale is checked against the line first: frames that arrived while
        the reader thread was not scheduled are taken here (if the reader holds the line right
        now, it is taking them itself and the sample stays stale for this call)."""
        with self._lock:
            newest, stamp = self._newest, self._stamp
        if self._reader_error is not None:
            raise DeviceError(DEVICE, self.port, self._reader_error)
        if newest is None:
            raise DeviceError(DEVICE, self.port, "no sample yet (start() not called or failed)")
        age = time.monotonic() - stamp
        ser = self._serial
        if age > self.stale_after and ser is not None and self._io.acquire(blocking=False):
            try:
                self._drain(ser)
            except Exception:  # noqa: BLE001 -- the line's failure is the reader's to report
                pass
            finally:
                self._io.release()
            with self._lock:
                newest, stamp = self._newest, self._stamp
            age = time.monotonic() - stamp
        if age > self.stale_after:
            raise DeviceError(
                DEVICE, self.port,
                f"stale stream: newest sample is {age * 1000:.0f} ms old "
                f"(limit {self.stale_after * 1000:.0f} ms)",
            )
        return newest

    def wrench(self) -> NDArray[np.float64]:
        """Newest ``[Fx, Fy, Fz, Tx, Ty, Tz]`` (N, N*m), bias removed.

        Raises :class:`DeviceError` when the sample is stale, missing, or the reader died.
        """
        return self._fresh_newest() - self._zero

    def bias(self) -> None:
        """Zero on the mean of the last ``bias_samples`` samples (raises on a stale stream)."""
        self._fresh_newest()
        with self._lock:
            self._zero = np.mean(np.asarray(self._recent), axis=0)

    def age(self) -> float:
        """Seconds since the newest sample arrived; ``inf`` before the first. Never raises."""
        with self._lock:
            stamp = self._stamp
        return float(time.monotonic() - stamp)

    # -- diagnostics ------------------------------------------------------------------------

    def stats(self) -> dict[str, float]:
        """Stream health: rate over the last 100 gaps (Hz), frames, CRC errors, skipped bytes,
        the longest gap between samples (s) and the current age (s)."""
        with self._lock:
            stamps = list(self._stamps)
            max_gap = self._max_gap
        p = self._parser.stats
        rate = (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 and \
            stamps[-1] > stamps[0] else 0.0
        return {
            "rate_hz": rate,
            "frames": float(p.frames),
            "crc_errors": float(p.crc_errors),
            "skipped_bytes": float(p.skipped_bytes),
            "max_gap_s": max_gap,
            "age_s": self.age(),
        }

    def raw_mean(self) -> NDArray[np.float64]:
        """Mean of the last ``bias_samples`` raw samples (no bias removed)."""
        with self._lock:
            if not self._recent:
                return np.full(6, np.nan)
            return np.mean(np.asarray(self._recent), axis=0)

    def check(self, window_s: float = 0.5, min_rate_hz: float = 80.0,
              max_force_n: float = 60.0) -> CheckResult:
        """Start-up check for ``cell check-hardware``; never raises.

        Starts the stream if needed, watches it for ``window_s`` and reports the rate, the
        frames lost to CRC errors, the raw offset (what :meth:`bias` would remove; a puck reading
        more than ``max_force_n`` at rest is overloaded or damaged) and the noise. The stream
        protocol carries no serial number or firmware version, so neither is reported.
        """
        try:
            self.start()
            before = self._parser.stats.frames
            errors_before = self._parser.stats.crc_errors
            t0 = time.monotonic()
            time.sleep(window_s)
            frames = self._parser.stats.frames - before
            rate = frames / (time.monotonic() - t0)
            with self._lock:
                recent = np.asarray(self._recent)
            mean = recent.mean(axis=0)
            std = recent.std(axis=0)
            self._fresh_newest()
        except DeviceError as exc:
            return CheckResult(DEVICE, self.port, False, error=exc.cause)
        details = {
            "stream_rate_hz": f"{rate:.1f}",
            "frames_in_window": str(frames),
            "crc_errors": str(self._parser.stats.crc_errors - errors_before),
            "skipped_bytes_total": str(self._parser.stats.skipped_bytes),
            "raw_force_n": " ".join(f"{v:+.2f}" for v in mean[:3]),
            "raw_torque_nm": " ".join(f"{v:+.3f}" for v in mean[3:]),
            "noise_force_n": f"{float(std[:3].max()):.3f}",
            "noise_torque_nm": f"{float(std[3:].max()):.4f}",
            "serial_firmware": "not in the stream protocol",
        }
        problems = []
        if rate < min_rate_hz:
            problems.append(f"stream rate {rate:.1f} Hz < {min_rate_hz:g} Hz")
        if float(np.linalg.norm(mean[:3])) > max_force_n:
            force = float(np.linalg.norm(mean[:3]))
            problems.append(f"raw force {force:.1f} N at rest > {max_force_n:g} N")
        return CheckResult(DEVICE, self.port, not problems, details,
                           "; ".join(problems) or None)


def _close_quietly(ser: Any) -> None:
    try:
        ser.close()
    except Exception:  # closing a broken port must not mask the cause
        pass
