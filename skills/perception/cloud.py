"""Depth image to points: the pinhole model of :class:`drivers.camera.Intrinsics`."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from drivers.camera import Intrinsics
from drivers.pose import Pose


def back_project(
    depth: NDArray[np.floating], intr: Intrinsics, world_T_camera: Pose
) -> NDArray[np.float64]:
    """World points (N, 3), m, of the valid pixels of ``depth`` (m along the optical axis, 0 =
    invalid); optical frame z forward, x right, y down."""
    v, u = np.nonzero(depth > 0.0)
    z = depth[v, u].astype(np.float64)
    x = (u - intr.cx) * z / intr.fx
    y = (v - intr.cy) * z / intr.fy
    return world_T_camera.transform(np.column_stack([x, y, z]))
