"""The arm interface: Cartesian motion of the tool centre point, started and then polled.

Nothing here blocks. A motion command starts a motion; the control loop advances the backend by
one control step (8 ms at 125 Hz on a CB3 UR5) and the caller polls :meth:`Arm.status`. Poses are
of the tool centre point (TCP) in the robot base frame, metres and radians.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from drivers.pose import Pose


class MotionState(Enum):
    IDLE = "idle"  # no motion commanded since the last one finished or stopped
    MOVING = "moving"
    DONE = "done"  # the last commanded motion reached its goal
    STOPPED = "stopped"  # stopped by stop() or a guard; the arm holds still
    FAULT = "fault"  # protective stop, unreachable target, lost link: needs attention


@dataclass(frozen=True)
class ArmStatus:
    state: MotionState
    message: str = ""
    protective_stop: bool = False
    #: the link to the controller is down (the arm's own controller stops it: its watchdog)
    link_lost: bool = False


@runtime_checkable
class Arm(Protocol):
    def tool_pose(self) -> Pose:
        """Current TCP pose in the base frame (m, rad)."""
        ...

    def move_path(self, waypoints: Sequence[Pose], speed: float, acceleration: float) -> None:
        """Start a Cartesian straight-line path through ``waypoints``.

        ``speed`` is the TCP speed limit (m/s), ``acceleration`` its limit (m/s^2); rotations are
        interpolated with the translation. Replaces any motion in progress.
        """
        ...

    def move_to(self, pose: Pose, speed: float, acceleration: float) -> None:
        """Start a straight-line Cartesian move to ``pose`` (m/s, m/s^2)."""
        ...

    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None:
        """Start a joint-space move to ``q`` (rad; UR ``moveJ``), ``speed`` rad/s and
        ``acceleration`` rad/s^2 for the joint that moves most.

        For going home: unlike a Cartesian move it also unwinds the wrist, and it needs no IK.
        """
        ...

    def servo(self, target: Pose) -> None:
        """Set the TCP target for the next control step (streaming; the caller interpolates)."""
        ...

    def servo_lag(self) -> float:
        """Seconds the arm trails a steady stream of :meth:`servo` targets (a UR's servoj:
        its lookahead time; 0 where each target is reached within the step). A skill whose
        stream must keep pace with something else (the jaws closing) leads it by this."""
        ...

    def force_mode(
        self,
        selection: Sequence[bool],
        wrench: Sequence[float],
        speed_limits: Sequence[float],
    ) -> None:
        """Hybrid force-position control in the base frame until :meth:`stop`.

        For each of the six axes (x, y, z, rx, ry, rz) ``selection`` chooses force control (True:
        push with ``wrench`` in N or N*m, moving at most ``speed_limits`` in m/s or rad/s) or
        position control (False: hold).
        """
        ...

    def stop(self) -> None:
        """Decelerate to standstill now and drop the motion. Idempotent."""
        ...

    def status(self) -> ArmStatus:
        """State of the last commanded motion."""
        ...

    def joint_positions(self) -> NDArray[np.float64]:
        """Joint angles (rad), base to wrist 3."""
        ...
