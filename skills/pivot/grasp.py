"""Grasp (Sec. III-C, Fig. 2(i)): tilt the gripper by alpha over the lying part's open end, so
that one finger drops into the hole and the other lands on the top surface at l, then close."""

from __future__ import annotations

from drivers.pose import Pose
from skills.motion import Devices, Sequence
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import Status, StepResult


class Grasp:
    """Open, approach along the fingers, close gently, press S down; fail if nothing is held."""

    def __init__(self, frame: PivotFrame, params: PivotParams, dev: Devices) -> None:
        self.frame, self.params, self.dev = frame, params, dev
        p, arm, gripper = params, dev.arm, dev.gripper
        self.target: Pose = frame.grasp_pose(p.l_a, p.alpha, p.tip_offset)
        opening = frame.opening(p.l_a, p.alpha)
        if opening + p.approach_clearance > gripper.stroke:
            raise ValueError(
                f"grasp needs a jaw opening of {(opening + p.approach_clearance) * 1e3:.1f} mm, "
                f"the gripper has {gripper.stroke * 1e3:.1f} mm"
            )
        z = self.target.rotation[:, 2]
        pre = Pose(self.target.position - p.approach_distance * z, self.target.rotation)
        # The arm, not the jaw, must hold S on the part: the closing line is only alpha off the
        # top surface, so the squeeze alone would slide S towards the open end.
        self.pressed = Pose(self.target.position - p.press_depth * frame.up, self.target.rotation)
        g = p.guard
        self.sequence = Sequence(
            "grasp",
            [
                dev.grip("open", g, lambda: gripper.open(opening + p.approach_clearance)),
                dev.move(
                    "above the open end",
                    g,
                    lambda: arm.move_to(pre, 2 * p.approach_speed, p.acceleration),
                ),
                dev.move(
                    "approach at alpha",
                    g,
                    lambda: arm.move_to(self.target, p.approach_speed, p.acceleration),
                ),
                dev.grip("close", g, lambda: gripper.close(p.grip_force), settle=0.2),
                dev.move(
                    "press S down",
                    g,
                    lambda: arm.move_to(self.pressed, 0.2 * p.approach_speed, p.acceleration),
                ),
            ],
        )

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if result.status is Status.SUCCESS and not self.dev.gripper.object_detected():
            return StepResult(Status.FAILURE, "grasp: missed, the fingers closed on nothing")
        return result

    def halt(self) -> None:
        self.sequence.halt()
