"""Align (Fig. 2(iv)): turn the gripper parallel to the now upright part and take the hole grasp,
one finger inside the hole and the other on the outer wall; then lift.

After the Tilt the part stands on its far end with the inner finger hooked on the rim. Align lets
go of the pinch, swings the gripper about that rim contact until the fingers point down the hole
(a rotation by ``pi/2 - alpha``), centres the jaws on the wall under the inner finger, reaches
``wall_depth`` below the rim and pinches the wall, then lifts. Every target is computed from the
tool's measured pose when its motion starts, not from the part's nominal pose, so drift of the
part during the Tilt does not matter; the paper requires the part to stand on its own here.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.pose import Pose
from skills.mechanics.part import Part
from skills.motion import Devices, Sequence
from skills.pivot.frame import PivotFrame, rotate_about_point
from skills.pivot.params import PivotParams
from skills.status import Status, StepResult


def wall_offset(part: Part, finger_width: float) -> float:
    """Distance (m) from the inner finger's face at the rim to the mid-plane of the wall."""
    thickness = 0.5 * (part.outer - part.hole)
    if part.hole_shape == "circle":
        chord = 0.5 * math.sqrt(part.hole**2 - finger_width**2)  # Eq. 2's x
        return 0.5 * part.hole - chord + 0.5 * thickness
    return 0.5 * thickness


class Align:
    def __init__(
        self,
        frame: PivotFrame,
        part: Part,
        params: PivotParams,
        dev: Devices,
    ) -> None:
        arm, gripper = dev.arm, dev.gripper
        self.frame, self.part, self.params = frame, part, params
        self.arm, self.gripper = arm, gripper
        p = params
        g = p.guard
        thickness = 0.5 * (part.outer - part.hole)
        self._rim: np.ndarray | None = None  # the rim contact H, measured at the start
        self._wall: np.ndarray | None = None
        e_h = frame.hook_depth(p.l_a, p.alpha)

        def release() -> None:
            tool = arm.tool_pose()
            width = gripper.width()
            x, z = tool.rotation[:, 0], tool.rotation[:, 2]
            self._rim = tool.position - 0.5 * width * x + (p.tip_offset - max(e_h, 0.0)) * z
            gripper.open(width + p.release)

        def swing() -> None:
            assert self._rim is not None
            tool = arm.tool_pose()
            target = rotate_about_point(tool, self._rim, frame.normal, 0.5 * math.pi - p.alpha)
            n = 12
            path = [
                rotate_about_point(tool, self._rim, frame.normal, (0.5 * math.pi - p.alpha) * k / n)
                for k in range(1, n + 1)
            ]
            path[-1] = target
            arm.move_path(path, p.approach_speed, p.acceleration)

        def out_of_hole() -> None:
            assert self._rim is not None
            tool = arm.tool_pose()
            x = tool.rotation[:, 0]
            face = self._rim.copy()
            self._wall = face + wall_offset(part, gripper.finger_width) * x
            above = Pose(tool.position + np.array([0, 0, 0.03]), tool.rotation)
            arm.move_to(above, p.approach_speed, p.acceleration)

        def narrow() -> None:
            gripper.open(thickness + 2 * p.wall_gap)

        def over_wall() -> None:
            assert self._wall is not None and self._rim is not None
            tool = arm.tool_pose()
            target = np.array([self._wall[0], self._wall[1], tool.position[2]])
            arm.move_to(Pose(target, tool.rotation), p.approach_speed, p.acceleration)

        def down() -> None:
            assert self._rim is not None
            tool = arm.tool_pose()
            z_tcp = self._rim[2] - p.wall_depth + p.tip_offset
            target = np.array([tool.position[0], tool.position[1], z_tcp])
            arm.move_to(Pose(target, tool.rotation), 0.5 * p.approach_speed, p.acceleration)

        def lift() -> None:
            tool = arm.tool_pose()
            up = Pose(tool.position + np.array([0, 0, p.lift_height]), tool.rotation)
            arm.move_to(up, p.approach_speed, p.acceleration)

        self.sequence = Sequence(
            "align",
            [
                dev.grip("release the pinch", g, release),
                dev.move("swing about the rim", g, swing),
                dev.move("out of the hole", g, out_of_hole),
                dev.grip("narrow the jaws", g, narrow),
                dev.move("over the wall", g, over_wall),
                dev.move("into the hole", g, down),
                dev.grip(
                    "pinch the wall",
                    g,
                    lambda: gripper.close(p.grip_force),
                    settle=0.2,
                ),
                dev.move("lift", g, lift),
            ],
        )
        self._checked_pinch = False

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if (
            not self._checked_pinch
            and self.sequence.index >= 7
            and result.status is not Status.FAILURE
        ):
            self._checked_pinch = True
            if not self.gripper.object_detected():
                self.sequence.halt()
                return StepResult(Status.FAILURE, "align: the hole grasp closed on nothing")
        return result

    def halt(self) -> None:
        self.sequence.halt()
