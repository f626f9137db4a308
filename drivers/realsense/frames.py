"""Frame conversions of the D435 driver, pure numpy: no ``pyrealsense2`` here.

Kept apart from the device code so the conversions are tested without any camera and so the
twin and the tests import nothing from librealsense.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.camera import Intrinsics


def depth_to_metres(raw: NDArray[np.uint16], depth_scale: float) -> NDArray[np.float32]:
    """Z16 depth counts -> metres (float32). A count of 0 (no stereo match) stays 0 (invalid).

    ``depth_scale`` is metres per count, read from the device (0.001 by default on a D435, but
    it is a setting: never assume it).
    """
    if not depth_scale > 0.0:
        raise ValueError(f"depth scale must be positive, got {depth_scale}")
    return (np.asarray(raw, dtype=np.float32) * np.float32(depth_scale)).astype(np.float32)


def colour_to_rgb(data: NDArray[np.uint8], fmt: str) -> NDArray[np.uint8]:
    """An (H, W, 3|4) colour image in ``fmt`` (``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``) -> a
    contiguous RGB copy (the frame's buffer belongs to librealsense and is reused)."""
    img = np.asarray(data, dtype=np.uint8)
    fmt = fmt.lower()
    if fmt not in ("rgb8", "bgr8", "rgba8", "bgra8"):
        raise ValueError(f"unsupported colour format {fmt!r}")
    img = img[..., :3]
    if fmt.startswith("bgr"):
        img = img[..., ::-1]
    return np.ascontiguousarray(img, dtype=np.uint8).copy()


def intrinsics_from_rs(intr: Any) -> Intrinsics:
    """``drivers.camera.Intrinsics`` from an ``rs.intrinsics`` (duck-typed: width, height, fx,
    fy, ppx, ppy). Distortion is dropped: a D435 colour stream typically reports zero
    coefficients, and ``RealSenseD435.check()`` prints them so a unit that does not is seen."""
    return Intrinsics(
        width=int(intr.width),
        height=int(intr.height),
        fx=float(intr.fx),
        fy=float(intr.fy),
        cx=float(intr.ppx),
        cy=float(intr.ppy),
    )
