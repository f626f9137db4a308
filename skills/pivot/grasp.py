"""Grasp (Sec. III-C, Fig. 2(i)): tilt the gripper by alpha over the lying part's open end, so
that one finger drops into the hole and the other lands on the top surface at l, then close."""

from __future__ import annotations

from drivers.arm import Arm
from drivers.clock import Clock
from drivers.ft_sensor import ForceTorqueSensor
from drivers.gripper import Gripper
from drivers.pose import Pose
from skills.motion import Sequence, arm_motion, gripper_motion
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import Status, StepResult


class Grasp:
    """Open, approach along the fingers, close with the grip force; fail if nothing is held."""

    def __init__(
        self,
        frame: PivotFrame,
        params: PivotParams,
        arm: Arm,
        gripper: Gripper,
        ft: ForceTorqueSensor,
        clock: Clock,
    ) -> None:
        self.frame, self.params = frame, params
        self.gripper = gripper
        p = params
        self.target: Pose = frame.grasp_pose(p.l_a, p.alpha, p.tip_offset)
        opening = frame.opening(p.l_a, p.alpha)
        if opening + p.approach_clearance > gripper.stroke:
            raise ValueError(
                f"grasp needs a jaw opening of {(opening + p.approach_clearance) * 1e3:.1f} mm, "
                f"the gripper has {gripper.stroke * 1e3:.1f} mm"
            )
        z = self.target.rotation[:, 2]
        pre = Pose(self.target.position - p.approach_distance * z, self.target.rotation)
        g = p.guard
        self.sequence = Sequence(
            "grasp",
            [
                gripper_motion(
                    "open",
                    gripper,
                    arm,
                    ft,
                    clock,
                    g,
                    lambda: gripper.open(opening + p.approach_clearance),
                ),
                arm_motion(
                    "above the open end",
                    arm,
                    ft,
                    clock,
                    g,
                    lambda: arm.move_to(pre, 2 * p.approach_speed, p.acceleration),
                ),
                arm_motion(
                    "approach at alpha",
                    arm,
                    ft,
                    clock,
                    g,
                    lambda: arm.move_to(self.target, p.approach_speed, p.acceleration),
                ),
                gripper_motion(
                    "close",
                    gripper,
                    arm,
                    ft,
                    clock,
                    g,
                    lambda: gripper.close(p.grip_force),
                    settle=0.2,
                ),
            ],
        )

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if result.status is Status.SUCCESS and not self.gripper.object_detected():
            return StepResult(Status.FAILURE, "grasp: missed, the fingers closed on nothing")
        return result

    def halt(self) -> None:
        self.sequence.halt()
