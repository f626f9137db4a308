"""Align (Fig. 2(iv)): turn the gripper about the rim into the hole grasp, one finger inside the
hole and the other on the outer wall, then lift.

When the Tilt ends the part stands (or leans) on its end with the inner finger's pad on the rim
from inside the hole and the outer finger low on the outer wall: the wall is already pinched, but
along a line far from horizontal. Align keeps that pinch and rotates the gripper about the inner
finger's rim contact until the fingers point straight down, the jaws closing under force all the
way so the outer finger slides up the outer wall; the part stays caught between the pads and the
floor the whole time, so nothing has to be re-found. Then the jaws ease by ``wall_gap``, the
fingers slide ``wall_depth`` below the rim, close again and lift.

The rim contact is computed from the tool's *measured* pose when Align starts: where the inner
pad's face plane crosses the rim height (floor plus the part's length, since the part stands on
its end).
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


class Align:
    def __init__(self, frame: PivotFrame, part: Part, params: PivotParams, dev: Devices) -> None:
        arm, gripper = dev.arm, dev.gripper
        self.frame, self.part, self.params, self.dev = frame, part, params, dev
        p, g = params, params.guard
        rim_z = frame.floor_z + part.length
        self.contact: np.ndarray | None = None
        self.path: list[Pose] = []

        def rotate() -> None:
            tool = arm.tool_pose()
            x, z = tool.rotation[:, 0], tool.rotation[:, 2]
            # The inner (-x) pad's face plane where it crosses the rim height: the rim contact.
            face = tool.position - 0.5 * gripper.width() * x
            if abs(z[2]) > 1e-3:
                face = face + ((rim_z - face[2]) / z[2]) * z
            self.contact = face
            down = np.array([0.0, 0.0, -1.0])
            axis = np.cross(z, down)
            angle = math.asin(min(1.0, float(np.linalg.norm(axis))))
            if float(np.dot(z, down)) < 0.0:
                angle = math.pi - angle
            if np.linalg.norm(axis) < 1e-9:
                self.path = [tool]
            else:
                axis = axis / np.linalg.norm(axis)
                n = max(2, int(math.ceil(angle / math.radians(3.0))))
                self.path = [
                    rotate_about_point(tool, face, axis, angle * k / n) for k in range(1, n + 1)
                ]
            gripper.close(p.grip_force)
            arm.move_path(self.path, p.align_speed, p.acceleration)

        def ease() -> None:
            gripper.open(gripper.width() + 2 * p.wall_gap)

        def down() -> None:
            tool = arm.tool_pose()
            target = np.array([tool.position[0], tool.position[1], rim_z - p.wall_depth])
            target[2] += p.tip_offset
            if target[2] < tool.position[2]:
                arm.move_to(Pose(target, tool.rotation), 0.5 * p.approach_speed, p.acceleration)
            else:
                arm.move_to(tool, 0.5 * p.approach_speed, p.acceleration)

        def lift() -> None:
            tool = arm.tool_pose()
            up = Pose(tool.position + np.array([0, 0, p.lift_height]), tool.rotation)
            arm.move_to(up, p.approach_speed, p.acceleration)

        self.sequence = Sequence(
            "align",
            [
                dev.move("turn about the rim", g, rotate),
                dev.grip("ease the jaws", g, ease),
                dev.move("slide below the rim", g, down),
                dev.grip("pinch the wall", g, lambda: gripper.close(p.grip_force), settle=0.2),
                dev.move("lift", g, lift),
            ],
        )
        self._pinch_step = 4  # index after "pinch the wall" succeeded
        self._checked = False

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if (
            not self._checked
            and self.sequence.index >= self._pinch_step
            and result.status is not Status.FAILURE
        ):
            self._checked = True
            if not self.dev.gripper.object_detected():
                self.sequence.halt()
                return StepResult(Status.FAILURE, "align: the hole grasp closed on nothing")
        return result

    def halt(self) -> None:
        self.sequence.halt()
