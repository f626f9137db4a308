"""The FT300's serial protocol, pure: no port, no thread, no clock (so it is tested byte by byte).

Two things travel on the line (Robotiq FT300 manual, "Modbus RTU" and "data stream"):

* The **start request** the host sends once: a Modbus RTU "write multiple registers" (function
  16) of ``0x0200`` into register 410 (``0x019A``) of unit 9. The sensor answers with the usual
  8-byte Modbus response and then streams until it sees a run of ``0xFF`` bytes (about 50).
* The **stream frames**, 16 bytes each at about 100 Hz: the header ``0x20 0x4E``, six int16
  little-endian values (Fx, Fy, Fz in 1/100 N; Tx, Ty, Tz in 1/1000 N*m), and the CRC-16/MODBUS
  of those 14 bytes, low byte first (the Modbus convention).

:class:`FrameParser` turns any chunking of that byte stream (partial reads, garbage, corrupted
frames) into samples that passed the CRC, and counts what it had to throw away. It never emits a
frame whose CRC failed, so a corrupted frame cannot become a wrong force; the residual risk is a
CRC collision (about 1 in 65536 per corrupted frame) that also happens to start with the header.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

HEADER = b"\x20\x4e"
FRAME_LEN = 16
STREAM_REGISTER = 410  #: 0x019A
STREAM_START_VALUE = 0x0200
STOP_BYTE = 0xFF
STOP_BYTES = 50  #: the manual's "about 50" 0xFF bytes end the stream
FORCE_LSB = 0.01  #: N per count
TORQUE_LSB = 0.001  #: N*m per count
SCALE = np.array([FORCE_LSB] * 3 + [TORQUE_LSB] * 3)
_VALUES = struct.Struct("<6h")


def crc16_modbus(data: bytes) -> int:
    """CRC-16/MODBUS (poly 0xA001 reflected, init 0xFFFF): the check of requests and frames."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def with_crc(body: bytes) -> bytes:
    """``body`` followed by its CRC, low byte first, as Modbus RTU puts it on the line."""
    return body + crc16_modbus(body).to_bytes(2, "little")


def write_registers_request(unit_id: int, register: int, values: list[int]) -> bytes:
    """A Modbus RTU function-16 request (write multiple holding registers), CRC included."""
    if not 1 <= unit_id <= 247:
        raise ValueError(f"Modbus unit id must be 1..247, got {unit_id}")
    body = struct.pack(">BBHHB", unit_id, 0x10, register, len(values), 2 * len(values))
    body += b"".join(struct.pack(">H", v) for v in values)
    return with_crc(body)


def start_stream_request(unit_id: int = 9) -> bytes:
    """The request that starts the stream: ``0x0200`` into register 410 of ``unit_id``."""
    return write_registers_request(unit_id, STREAM_REGISTER, [STREAM_START_VALUE])


def stop_stream_bytes() -> bytes:
    """What ends the stream: a run of ``0xFF`` bytes, which no Modbus frame can parse as valid."""
    return bytes([STOP_BYTE]) * STOP_BYTES


def encode_frame(wrench: NDArray[np.float64] | list[float]) -> bytes:
    """A valid stream frame for ``[Fx, Fy, Fz, Tx, Ty, Tz]`` (N, N*m); for peers and tests.

    Values are rounded to the sensor's resolution; out-of-range values raise (int16 counts:
    +-327.67 N, +-32.767 N*m), as the device itself cannot send them.
    """
    counts = np.rint(np.asarray(wrench, float) / SCALE).astype(np.int64)
    if np.any(np.abs(counts) > 32767):
        raise ValueError(f"wrench {wrench} is outside the FT300's int16 range")
    return with_crc(HEADER + _VALUES.pack(*(int(c) for c in counts)))


def decode_frame(frame: bytes) -> NDArray[np.float64]:
    """``[Fx, Fy, Fz, Tx, Ty, Tz]`` (N, N*m) of one 16-byte frame; raises if it is not valid."""
    if len(frame) != FRAME_LEN or frame[:2] != HEADER:
        raise ValueError(f"not an FT300 frame: {frame.hex(' ')}")
    if crc16_modbus(frame[:14]) != int.from_bytes(frame[14:16], "little"):
        raise ValueError(f"FT300 frame CRC mismatch: {frame.hex(' ')}")
    return np.asarray(_VALUES.unpack(frame[2:14]), float) * SCALE


@dataclass
class ParserStats:
    """What the parser kept and threw away since it was made."""

    frames: int = 0  #: valid frames emitted
    crc_errors: int = 0  #: damaged frames: a header whose 16 bytes failed the CRC
    skipped_bytes: int = 0  #: bytes thrown away while looking for a valid frame


class FrameParser:
    """Finds valid frames in a byte stream fed in arbitrary chunks.

    Sync rule: look for the header; once 16 bytes from it are in, the frame is accepted only if
    its CRC matches. On a mismatch (a corrupted frame, or a partial frame followed by the next
    one) it drops the first header byte and searches again, so the next real header is found
    even when it lies inside the rejected 16 bytes. A mismatch counts as a CRC error unless it
    starts inside the 16 bytes of the previous counted one (a false header in a damaged
    frame's payload), so the count is the number of damaged frames on the line; two damaged
    frames closer than 16 bytes (a cut frame right after another) count once.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._pos = 0  #: stream offset of _buf[0]
        self._error_span_end = -1  #: stream offset where the last counted damaged frame ends
        self.stats = ParserStats()

    def missing(self) -> int:
        """Bytes still needed to complete the frame buffered so far (a whole frame when
        nothing is): what a reader can block for without delaying a sample."""
        return FRAME_LEN - len(self._buf) if len(self._buf) < FRAME_LEN else 1

    def feed(self, data: bytes) -> list[NDArray[np.float64]]:
        """Add bytes; return the samples of the valid frames they completed, oldest first."""
        self._buf += data
        out: list[NDArray[np.float64]] = []
        buf = self._buf
        while True:
            start = buf.find(HEADER)
            if start < 0:
                # Keep a trailing first header byte: the next chunk may complete the header.
                drop = len(buf) - (1 if buf[-1:] == HEADER[:1] else 0)
                self._drop(drop)
                break
            if start:
                self._drop(start)
            if len(buf) < FRAME_LEN:
                break
            frame = bytes(buf[:FRAME_LEN])
            if crc16_modbus(frame[:14]) == int.from_bytes(frame[14:16], "little"):
                out.append(np.asarray(_VALUES.unpack(frame[2:14]), float) * SCALE)
                del buf[:FRAME_LEN]
                self._pos += FRAME_LEN
                self.stats.frames += 1
            else:
                if self._pos >= self._error_span_end:
                    self.stats.crc_errors += 1
                    self._error_span_end = self._pos + FRAME_LEN
                self._drop(1)
        return out

    def _drop(self, n: int) -> None:
        """Throw away the first ``n`` buffered bytes (counted as skipped)."""
        del self._buf[:n]
        self._pos += n
        self.stats.skipped_bytes += n
