"""The wire of a streamed D435: frame pairs over a TCP socket, pure (no pyrealsense2, no sim).

There is no network protocol for a USB camera, so this one is the project's own, kept minimal:
what librealsense would get from the USB device (a Z16 depth image in depth units, an RGB8
colour image, a frame number and a timestamp) and, once per connection, what it would read from
the device (identity, stream modes, intrinsics, depth units). The D435 driver's stream mode
(:meth:`drivers.realsense.RealSenseD435.from_stream`) feeds the frames into a pyrealsense2
software device, so everything after "a frameset arrived" runs on librealsense as on hardware.

On connecting, the sender (the camera side) writes::

    b"D435STR1"  uint32 n  n bytes of JSON: serial, firmware, name, width, height, fps,
                           depth_units (m per count), fx, fy, cx, cy (the colour intrinsics;
                           depth is sent aligned to colour, so it shares them)

then one message per frame pair, all integers big-endian::

    b"FRAM"  uint64 frame_number  float64 timestamp_ms  uint32 depth_bytes  uint32 colour_bytes
    depth: height x width uint16 little-endian (Z16)   colour: height x width x 3 uint8 (RGB8)
"""

from __future__ import annotations

import json
import socket
import struct
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

MAGIC = b"D435STR1"
FRAME_TAG = b"FRAM"
_FRAME_HEAD = struct.Struct(">QdII")


@dataclass(frozen=True)
class StreamInfo:
    """What the camera tells about itself once per connection."""

    width: int
    height: int
    fps: int
    depth_units: float  #: m per Z16 count
    fx: float
    fy: float
    cx: float
    cy: float
    serial: str = "stream"
    firmware: str = ""
    name: str = "D435 (streamed)"


def encode_info(info: StreamInfo) -> bytes:
    body = json.dumps(asdict(info)).encode()
    return MAGIC + struct.pack(">I", len(body)) + body


def encode_frame(frame_number: int, timestamp_ms: float, depth: NDArray[np.uint16],
                 rgb: NDArray[np.uint8]) -> bytes:
    """One frame-pair message: Z16 depth (H, W) and RGB8 colour (H, W, 3)."""
    d = np.ascontiguousarray(depth, dtype="<u2").tobytes()
    c = np.ascontiguousarray(rgb, dtype=np.uint8).tobytes()
    return FRAME_TAG + _FRAME_HEAD.pack(frame_number, timestamp_ms, len(d), len(c)) + d + c


def _exact(sock: socket.socket, n: int) -> bytes:
    """``n`` bytes from ``sock``; ConnectionError when it closes first."""
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(min(n - len(buf), 1 << 20))
        if not chunk:
            raise ConnectionError("the camera stream closed")
        buf += chunk
    return bytes(buf)


def read_info(sock: socket.socket) -> StreamInfo:
    """The connection's header; ValueError when the peer does not speak this protocol."""
    if _exact(sock, len(MAGIC)) != MAGIC:
        raise ValueError("not a D435 frame stream (bad greeting)")
    (n,) = struct.unpack(">I", _exact(sock, 4))
    if n > 1 << 16:
        raise ValueError(f"D435 stream header of {n} bytes is implausible")
    fields = json.loads(_exact(sock, n))
    return StreamInfo(**{k: fields[k] for k in StreamInfo.__dataclass_fields__ if k in fields})


def read_frame(sock: socket.socket, info: StreamInfo
               ) -> tuple[int, float, NDArray[np.uint16], NDArray[np.uint8]]:
    """The next frame pair: (frame number, timestamp ms, Z16 depth, RGB8 colour)."""
    if _exact(sock, len(FRAME_TAG)) != FRAME_TAG:
        raise ValueError("D435 stream out of step (no frame tag)")
    number, ts, nd, nc = _FRAME_HEAD.unpack(_exact(sock, _FRAME_HEAD.size))
    h, w = info.height, info.width
    if nd != h * w * 2 or nc != h * w * 3:
        raise ValueError(f"D435 stream frame sizes {nd}, {nc} do not fit {w}x{h}")
    depth = np.frombuffer(_exact(sock, nd), dtype="<u2").reshape(h, w).astype(np.uint16)
    rgb = np.frombuffer(_exact(sock, nc), dtype=np.uint8).reshape(h, w, 3).copy()
    return number, ts, depth, rgb
