"""The recovery when the in-hand Align failed: let go, look, and pick the standing part from
above -- a regrasp, not the paper's method. A part it saves is reported as ``recovered``, never
as a pivot success; the regrasp baseline (:mod:`skills.regrasp`) ends with it too.

The part stands where the Tilt (or the baseline) left it, known only roughly, so this looks, as
the paper's cell does with its wrist camera:

1. let go and draw the fingers back along their axis;
2. move the wrist camera ``view_height`` above the predicted rim, find the rim's ring in the
   depth image (:func:`skills.perception.locate_upright_part`); fail if no standing part is seen;
3. fingers straight down over the wall nearest the robot, the jaws open by ``wall_gap`` on each
   side of the span a hole grasp pinches (for a round hole the inner pad touches at the chord of
   Eq. 2); go down ``wall_depth`` below the rim -- a pad landing on the rim stops the arm under a
   low force limit and fails the skill -- close and lift.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.motion import GuardedMotion, Sequence
from skills.perception import UprightPart, locate_upright_part
from skills.pivot.align import HoleGraspSkill, hole_grasp_rotation, pinched_span
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams


class PickFromAbove(HoleGraspSkill):
    """Release, look with the wrist camera, take the hole grasp from above (a regrasp)."""

    name = "pick from above"

    def __init__(
        self,
        frame: PivotFrame | Callable[[], PivotFrame],
        part: Part,
        params: PivotParams,
        dev: Devices,
    ) -> None:
        super().__init__(frame, part, params, dev)
        arm, gripper, camera = dev.arm, dev.gripper, dev.camera
        p, g = params, params.guard
        outer, inner = pinched_span(part, gripper.finger_width)
        self.predicted_axis: NDArray[np.float64] | None = None  #: from the pivot (m, x y)
        self.seen: UprightPart | None = None  #: what the camera found
        st: dict[str, PivotFrame] = {}

        def frame_now() -> PivotFrame:
            if "frame" not in st:
                st["frame"] = self._frame_source()
            return st["frame"]

        def rotation() -> NDArray[np.float64]:
            return hole_grasp_rotation(-frame_now().u)  # outer finger on the robot's side

        def rim_z() -> float:
            return frame_now().floor_z + part.length

        def release() -> None:
            frame = frame_now()
            self.predicted_axis = (frame.pivot - 0.5 * part.outer * frame.u)[:2].copy()
            gripper.open(gripper.width() + p.release)

        def withdraw() -> None:
            tool = arm.tool_pose()
            back = tool.position - p.approach_distance * tool.rotation[:, 2]
            arm.move_to(Pose(back, tool.rotation), p.approach_speed, p.acceleration)

        def view() -> None:
            if camera is None:
                return
            assert self.predicted_axis is not None
            rot = rotation()
            cam = camera.tool_T_camera().position
            # Optical centre straight above the predicted axis, view_height above the rim.
            target = np.array([*self.predicted_axis, rim_z() + p.view_height]) - rot @ cam
            arm.move_to(Pose(target, rot), 2 * p.approach_speed, p.acceleration)

        def look() -> None:
            if camera is None:
                return
            assert self.predicted_axis is not None
            frame = camera.capture()
            world_T_camera = arm.tool_pose() @ camera.tool_T_camera()
            self.seen = locate_upright_part(
                frame,
                camera.intrinsics(),
                world_T_camera,
                part,
                self.predicted_axis,
                frame_now().floor_z,
                search=p.view_search,
            )

        def not_seen() -> str | None:
            if camera is None:
                return "no wrist camera to find the standing part"
            if self.seen is None:
                return "no standing part seen near where the Tilt left it"
            return None

        def wall_xy() -> NDArray[np.float64]:
            assert self.seen is not None
            toward_robot = -frame_now().u[:2]
            return self.seen.center + 0.5 * (outer + inner) * toward_robot

        def over_wall() -> None:
            target = np.array([*wall_xy(), rim_z() + p.clear_height + p.tip_offset])
            arm.move_to(Pose(target, rotation()), 2 * p.approach_speed, p.acceleration)

        def narrow() -> None:
            gripper.open(outer - inner + 2.0 * p.wall_gap)

        def into_hole() -> None:
            depth = min(p.wall_depth, part.length - p.floor_clearance)
            target = np.array([*wall_xy(), rim_z() - depth + p.tip_offset])
            arm.move_to(Pose(target, rotation()), 0.5 * p.approach_speed, p.acceleration)

        def lift() -> None:
            tool = arm.tool_pose()
            up_pose = Pose(tool.position + np.array([0, 0, p.lift_height]), tool.rotation)
            arm.move_to(up_pose, p.approach_speed, p.acceleration)

        pinch = dev.grip(
            "pinch the wall", g, lambda: gripper.close(p.hold_force), settle=0.3
        )
        self.sequence = Sequence(
            "pick from above",
            [
                dev.grip("let go", g, release),
                dev.move("draw the fingers back", g, withdraw),
                dev.move("camera over the part", g, view),
                GuardedMotion(
                    "find the standing part",
                    look,
                    lambda: True,
                    arm,
                    dev.ft,
                    dev.clock,
                    g,
                    not_seen,
                ),
                dev.move("over the wall", g, over_wall),
                dev.grip("open over the wall", g, narrow),
                dev.move("into the hole", p.descent_guard, into_hole),
                pinch,
                dev.move("lift", g, lift),
            ],
        )
        self._pinch_step = self.sequence.steps.index(pinch) + 1
