"""Tilt (Fig. 2(ii)-(iii), Fig. 10): carry the grasp along the arc of radius r about the pivot
corner P_c by theta, so the part turns about G while the fingers keep S and H."""

from __future__ import annotations

from drivers.arm import Arm
from drivers.clock import Clock
from drivers.ft_sensor import ForceTorqueSensor
from drivers.gripper import Gripper
from drivers.pose import Pose
from skills.motion import Sequence, arm_motion
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import StepResult


class Tilt:
    """One guarded Cartesian path through the arc; the FT guard is the paper's emergency stop."""

    def __init__(
        self,
        frame: PivotFrame,
        params: PivotParams,
        grasp: Pose,
        arm: Arm,
        gripper: Gripper,
        ft: ForceTorqueSensor,
        clock: Clock,
    ) -> None:
        self.path = frame.tilt_path(grasp, params.tilt_angle)
        self.radius = frame.radius(grasp)
        p = params
        self.sequence = Sequence(
            "tilt",
            [
                arm_motion(
                    f"arc r={self.radius * 1e3:.0f} mm",
                    arm,
                    ft,
                    clock,
                    p.tilt_guard,
                    lambda: arm.move_path(self.path, p.tilt_speed, p.acceleration),
                )
            ],
        )

    def tick(self) -> StepResult:
        return self.sequence.tick()

    def halt(self) -> None:
        self.sequence.halt()
