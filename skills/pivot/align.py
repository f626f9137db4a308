"""Align (Fig. 2(iv)): take the hole grasp of the now upright part, one finger inside the hole and
the other on the outer wall, then lift.

The Tilt stops once the part's centre of mass is past the pivot (Sec. III-B: from there gravity
turns it upright and the finger in the hole keeps it from escaping; the part then stands on its
own, which the paper requires between Tilt and Align). Align then lets go, draws the fingers back
along their axis out of the hole, turns them to point straight down over the wall that the inner
finger was hooked behind, reaches ``wall_depth`` below the rim with the jaws ``wall_gap`` clear of
each side of the wall, pinches it and lifts.

The wall is located from the tool's *measured* pose when Align starts (the inner finger's face
lies against it from inside the hole), so the part's drift during the Tilt does not matter; the
rim height is the floor plus the part's length, since the part stands on its end.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.pose import Pose
from skills.mechanics.part import Part
from skills.motion import Devices, Sequence
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import Status, StepResult


def pinched_thickness(part: Part, finger_width: float) -> float:
    """Thickness (m) of the wall between the two pads of a hole grasp.

    For a round hole a pad of width ``w`` inside the hole touches the inner surface with its two
    edges, on the chord of Eq. 2, while the outer pad touches the outer surface at its middle: the
    jaws span ``D/2 - sqrt((d/2)^2 - (w/2)^2)``, more than the wall itself.
    """
    if part.hole_shape == "circle":
        return 0.5 * part.outer - 0.5 * math.sqrt(part.hole**2 - finger_width**2)
    return 0.5 * (part.outer - part.hole)


def hole_grasp_rotation(x_horizontal: np.ndarray) -> np.ndarray:
    """Fingers straight down (tool z = -up), closing line along ``x_horizontal``."""
    z = np.array([0.0, 0.0, -1.0])
    x = np.array([x_horizontal[0], x_horizontal[1], 0.0])
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


class Align:
    def __init__(self, frame: PivotFrame, part: Part, params: PivotParams, dev: Devices) -> None:
        arm, gripper = dev.arm, dev.gripper
        self.frame, self.part, self.params, self.dev = frame, part, params, dev
        p, g = params, params.guard
        thickness = pinched_thickness(part, gripper.finger_width)
        rim_z = frame.floor_z + part.length
        self.wall: np.ndarray | None = None
        self._rotation: np.ndarray | None = None

        def release() -> None:
            tool = arm.tool_pose()
            x, z = tool.rotation[:, 0], tool.rotation[:, 2]
            # The inner finger's pad lies on the rim from inside the hole: where its face plane
            # crosses the rim's height is the rim contact (the chord of Eq. 2), one side of the
            # pinched span.
            face = tool.position - 0.5 * gripper.width() * x
            if abs(z[2]) > 1e-3:
                face = face + ((rim_z - face[2]) / z[2]) * z
            x_h = np.array([x[0], x[1], 0.0])
            if np.linalg.norm(x_h) < 1e-6:  # closing line vertical: fall back to the plan's
                x_h = -frame.u
            x_h /= np.linalg.norm(x_h)
            self.wall = face + 0.5 * thickness * x_h
            self._rotation = hole_grasp_rotation(x_h)
            gripper.open(gripper.width() + p.release)

        def withdraw() -> None:
            tool = arm.tool_pose()
            back = tool.position - p.approach_distance * tool.rotation[:, 2]
            arm.move_to(Pose(back, tool.rotation), p.approach_speed, p.acceleration)

        def above() -> None:
            assert self.wall is not None and self._rotation is not None
            target = np.array([self.wall[0], self.wall[1], rim_z + 0.03 + p.tip_offset])
            arm.move_to(Pose(target, self._rotation), 2 * p.approach_speed, p.acceleration)

        def narrow() -> None:
            gripper.open(thickness + 2 * p.wall_gap)

        def down() -> None:
            tool = arm.tool_pose()
            target = np.array([tool.position[0], tool.position[1], rim_z - p.wall_depth])
            target[2] += p.tip_offset
            arm.move_to(Pose(target, tool.rotation), 0.5 * p.approach_speed, p.acceleration)

        def lift() -> None:
            tool = arm.tool_pose()
            up = Pose(tool.position + np.array([0, 0, p.lift_height]), tool.rotation)
            arm.move_to(up, p.approach_speed, p.acceleration)

        self.sequence = Sequence(
            "align",
            [
                dev.grip("release the pinch", g, release),
                dev.move("draw the fingers back", g, withdraw),
                dev.grip("narrow the jaws", g, narrow),
                dev.move("over the wall", g, above),
                dev.move("into the hole", g, down),
                dev.grip("pinch the wall", g, lambda: gripper.close(p.grip_force), settle=0.2),
                dev.move("lift", g, lift),
            ],
        )
        self._pinch_step = 6  # index after "pinch the wall" succeeded
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
