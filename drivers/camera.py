"""The eye-in-hand RGB-D camera interface (a RealSense D435 or its twin)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from drivers.pose import Pose


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels; ``width`` x ``height`` image."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def matrix(self) -> NDArray[np.float64]:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])


@dataclass(frozen=True)
class Frame:
    """One aligned capture: ``rgb`` (H, W, 3) uint8 and ``depth`` (H, W) float32 in metres.

    A depth of 0 marks an invalid pixel.
    """

    rgb: NDArray[np.uint8]
    depth: NDArray[np.float32]
    stamp: float  #: capture time (s) on the cell's clock


@runtime_checkable
class Camera(Protocol):
    def intrinsics(self) -> Intrinsics:
        """Colour-aligned intrinsics (pixels)."""
        ...

    def tool_T_camera(self) -> Pose:
        """Pose of the optical frame (z forward, x right, y down) in the tool frame (m, rad)."""
        ...

    def capture(self) -> Frame:
        """An aligned frame exposed after the call. Raises ``TimeoutError`` when none arrives
        in time. A camera that streams on its own clock may block here for a frame period or
        two; it says so with a class attribute ``captures_in_background = True`` (optional,
        not part of the protocol's check), and the skills then wait for it off the tick."""
        ...
