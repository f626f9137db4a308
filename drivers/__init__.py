"""Device interfaces (arm, gripper, force-torque sensor, camera, clock) and the real drivers.

The interfaces are small ``typing.Protocol`` classes with units in every docstring; the PyBullet
twin in ``sim/`` and the real drivers implement them, and nothing above this layer knows which.
"""

from drivers.arm import Arm, ArmStatus, MotionState
from drivers.camera import Camera, Frame, Intrinsics
from drivers.clock import Clock, WallClock
from drivers.ft_sensor import ForceTorqueSensor
from drivers.gripper import Gripper
from drivers.pose import Pose

__all__ = [
    "Arm",
    "ArmStatus",
    "Camera",
    "Clock",
    "ForceTorqueSensor",
    "Frame",
    "Gripper",
    "Intrinsics",
    "MotionState",
    "Pose",
    "WallClock",
]
