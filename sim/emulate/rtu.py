"""What the emulated serial devices share: the Modbus RTU CRC, a raw pseudo-terminal, and the
thread that serves the device's end of the line with a cable that can be pulled.

The 2F-85 (:mod:`sim.emulate.gripper_server`) and the FT300 (:mod:`sim.emulate.ft300_stream`)
both speak Modbus RTU on an RS-485 line; here the line is the master side of an
``os.openpty()`` pair, whose slave path a driver opens like a USB RS-485 adapter. The CRC is the
Modbus over Serial Line specification's (reflected polynomial 0xA001, initial 0xFFFF, sent low
byte first). The tests check the emulators against an independent CRC, not against this one.
"""

from __future__ import annotations

import os
import threading
import tty
from typing import Self


def crc16(data: bytes) -> int:
    """CRC-16 of Modbus RTU (reflected polynomial 0xA001, initial 0xFFFF)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def with_crc(body: bytes) -> bytes:
    """``body`` as a frame on the wire: its CRC appended, low byte first."""
    return body + crc16(body).to_bytes(2, "little")


def crc_ok(frame: bytes | bytearray) -> bool:
    """Whether the last two bytes of ``frame`` are the CRC of the rest."""
    return crc16(bytes(frame[:-2])) == int.from_bytes(frame[-2:], "little")


def open_pty() -> tuple[int, int, str]:
    """A pseudo-terminal for a device: ``(master, slave, path)``. The slave is raw (bytes pass
    unchanged: no echo, no newline translation), the master (the device's end) non-blocking;
    ``path`` is what a driver opens."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


def close_fds(*fds: int) -> None:
    """Close each open descriptor (``-1``: none), ignoring one already closed."""
    for fd in fds:
        if fd >= 0:
            try:
                os.close(fd)
            except OSError:
                pass


class LineDevice:
    """A device on a serial line, served by its own thread (:meth:`_run`, until ``_stop`` is
    set) from :meth:`start` to :meth:`close`; usable as a context manager. Its cable
    (``_cut``): :meth:`pull_cable` / :meth:`restore`, each device deciding in :meth:`_run` what
    an unplugged line does to it."""

    def __init__(self, thread_name: str) -> None:
        self._stop = threading.Event()
        self._cut = threading.Event()
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)

    def _run(self) -> None:
        raise NotImplementedError

    def _close_line(self) -> None:
        """Release the line's ends (after the thread has stopped)."""
        raise NotImplementedError

    def start(self) -> Self:
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread (joined) and close the line."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._close_line()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def pull_cable(self) -> None:
        """Unplug the device: nothing reaches it and nothing comes back until :meth:`restore`."""
        self._cut.set()

    def restore(self) -> None:
        """Plug it back."""
        self._cut.clear()

    @property
    def cable_pulled(self) -> bool:
        return self._cut.is_set()


__all__ = ["LineDevice", "close_fds", "crc16", "crc_ok", "open_pty", "with_crc"]
