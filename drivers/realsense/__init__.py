"""RealSense D435 driver; ``pyrealsense2`` is imported only when a camera is started."""

from drivers.realsense.d435 import RealSenseD435
from drivers.realsense.frames import colour_to_rgb, depth_to_metres, intrinsics_from_rs

__all__ = ["RealSenseD435", "colour_to_rgb", "depth_to_metres", "intrinsics_from_rs"]
