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

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from drivers.camera import Frame
from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.axes import XY, Z
from skills.frames import frame_step
from skills.motion import GuardedMotion, Sequence
from skills.perception import UprightPart, locate_upright_part
from skills.pivot.align import HoleGraspSkill, hole_grasp_rotation, pinched_span
from skills.pivot.clearance import Obstacle, Reach, nearest, tool_points
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams


class PickFromAbove(HoleGraspSkill):
    """Release, look with the wrist camera, take the hole grasp from above (a regrasp).

    Three phases of named steps (module doc): let go and draw back, find the standing part,
    take the hole grasp over the wall nearest the robot."""

    name = "pick from above"

    def __init__(
        self,
        frame: PivotFrame | Callable[[], PivotFrame],
        part: Part,
        params: PivotParams,
        dev: Devices,
        center_xy: NDArray[np.float64] | None = None,
    ) -> None:
        """``center_xy``: where a part found standing was seen (m): nothing is held, so no
        let-go; without it, the axis is predicted from the pivot's frame as the jaws let go."""
        super().__init__(frame, part, params, dev)
        self._outer, self._inner = pinched_span(part, dev.gripper.finger_width)
        self._frame: PivotFrame | None = None  #: read from the source when the skill starts
        #: m, x y: from the pivot (set at the let-go), or where the part was seen standing
        self.predicted_axis: NDArray[np.float64] | None = None
        self.seen: UprightPart | None = None  #: what the camera found
        let_go = self._let_go_steps()
        if center_xy is not None:
            self.predicted_axis, let_go = np.asarray(center_xy, float)[XY].copy(), []
        self.sequence = Sequence(
            self.name, [*let_go, *self._find_steps(), *self._grasp_steps()]
        )

    # --- the phases --------------------------------------------------------------------------
    def _let_go_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            dev.grip("let go", g, self._release),
            dev.move("draw the fingers back", g, self._withdraw),
        ]

    def _find_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            dev.move("camera over the part", g, self._view),
            frame_step("find the standing part", dev, g, self._locate, self._use_seen,
                       self._not_seen)
            if dev.camera is not None
            else GuardedMotion("find the standing part", lambda: None, lambda: True, dev.arm,
                               dev.ft, dev.clock, g, self._not_seen),
        ]

    def _grasp_steps(self) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        return [
            dev.move("over the wall", g, self._over_wall),
            dev.grip("open over the wall", g, self._narrow),
            dev.move("into the hole", p.descent_guard, self._into_hole),
            dev.grip(self.pinch_step, g, lambda: dev.gripper.close(p.hold_force),
                     settle=p.pinch_settle),
            dev.move("lift", g, self._lift),
        ]

    # --- where things are --------------------------------------------------------------------
    def _frame_now(self) -> PivotFrame:
        """The frame, read from its source once, at the first step that needs it."""
        if self._frame is None:
            self._frame = self._frame_source()
        return self._frame

    def _rotation(self) -> NDArray[np.float64]:
        return hole_grasp_rotation(-self._frame_now().u)  # outer finger on the robot's side

    def _rim_z(self) -> float:
        return self._frame_now().floor_z + self.part.length

    def _wall_xy(self) -> NDArray[np.float64]:
        assert self.seen is not None
        toward_robot = -self._frame_now().u[XY]
        middle = 0.5 * (self._outer + self._inner)  # exact: the wall's middle, between its faces
        return self.seen.center + middle * toward_robot

    # --- the steps' commands and checks ------------------------------------------------------
    def _release(self) -> None:
        frame, gripper = self._frame_now(), self.dev.gripper
        radius = 0.5 * self.part.outer  # exact: a radius is half the diameter
        self.predicted_axis = (frame.pivot - radius * frame.u)[XY].copy()
        gripper.open(gripper.width() + self.params.release)

    def _withdraw(self) -> None:
        arm, p = self.dev.arm, self.params
        tool = arm.tool_pose()
        back = tool.position - p.approach_distance * tool.rotation[:, Z]
        arm.move_to(Pose(back, tool.rotation), p.approach_speed, p.acceleration)

    def _view(self) -> None:
        camera, p = self.dev.camera, self.params
        if camera is None:
            return
        assert self.predicted_axis is not None
        rot = self._rotation()
        cam = camera.tool_T_camera().position
        # Optical centre straight above the predicted axis, view_height above the rim.
        target = np.array([*self.predicted_axis, self._rim_z() + p.view_height]) - rot @ cam
        speed = p.transfer_speed_factor * p.approach_speed
        self.dev.arm.move_to(Pose(target, rot), speed, p.acceleration)

    def _locate(self, frame: Frame, world_T_camera: Pose) -> UprightPart | None:
        camera = self.dev.camera
        assert camera is not None and self.predicted_axis is not None
        return locate_upright_part(
            frame,
            camera.intrinsics(),
            world_T_camera,
            self.part,
            self.predicted_axis,
            self._frame_now().floor_z,
            search=self.params.view_search,
        )

    def _use_seen(self, seen: UprightPart | None) -> None:
        self.seen = seen

    def _not_seen(self) -> str | None:
        if self.dev.camera is None:
            return "no wrist camera to find the standing part"
        if self.seen is None:
            return "no standing part seen near where the Tilt left it"
        return None

    def _over_wall(self) -> None:
        p = self.params
        target = np.array([*self._wall_xy(), self._rim_z() + p.clear_height + p.tip_offset])
        speed = p.transfer_speed_factor * p.approach_speed
        self.dev.arm.move_to(Pose(target, self._rotation()), speed, p.acceleration)

    def _narrow(self) -> None:
        gaps = 2.0 * self.params.wall_gap  # exact: a wall gap at each pad
        self.dev.gripper.open(self._outer - self._inner + gaps)

    def _into_hole(self) -> None:
        p = self.params
        depth = min(p.wall_depth, self.part.length - p.floor_clearance)
        target = np.array([*self._wall_xy(), self._rim_z() - depth + p.tip_offset])
        speed = p.descent_speed_factor * p.approach_speed
        self.dev.arm.move_to(Pose(target, self._rotation()), speed, p.acceleration)

    def _lift(self) -> None:
        p, arm = self.params, self.dev.arm
        tool = arm.tool_pose()
        up_pose = Pose(tool.position + np.array([0, 0, p.lift_height]), tool.rotation)
        arm.move_to(up_pose, p.approach_speed, p.acceleration)


#: rad between the sides of a standing part tried for its hole grasp from above: the robot's
#: side first, then turning away from it both ways (eight sides in all)
STANDING_SIDE_STEP = math.pi / 4.0


class PickStanding(PickFromAbove):
    """A part found standing, its open end up: the hole grasp from above, without the let-go
    (nothing is held; pass ``center_xy``, where the wide view saw its axis). Not the paper's
    maneuver -- the part needs no pivot -- so its picks are counted apart (``standing``). The
    close look over it measures the rim before the fingers go down."""

    name = "pick standing"


def plan_standing_pick(
    center_xy: NDArray[np.float64],
    part: Part,
    params: PivotParams,
    obstacles: list[Obstacle],
    finger_width: float,
    floor_z: float,
    base_xy: tuple[float, float] = (0.0, 0.0),
    *,
    reach: Reach | None = None,
) -> PivotFrame | None:
    """The frame for :class:`PickStanding` (its ``u`` points from the outer finger's side
    across the part) whose jaws, over the wall and down in the hole, clear ``obstacles`` by
    ``clearance_margin`` and stay in ``reach``; the robot's side first. None: no side does."""
    c = np.asarray(center_xy, float)[XY]
    toward = math.atan2(c[1] - base_xy[1], c[0] - base_xy[0])
    outer, inner = pinched_span(part, finger_width)
    middle = 0.5 * (outer + inner)  # exact: the wall's middle, between its faces
    width = outer - inner + 2.0 * params.wall_gap  # exact: a wall gap at each pad
    model = tool_points(width, params.tip_offset, params.finger_thickness, finger_width)
    rim = floor_z + part.length
    depth = min(params.wall_depth, part.length - params.floor_clearance)
    section = part.section(finger_width)
    radius = 0.5 * part.outer  # exact: the frame's centre height, as a lying part's
    sides = int(round(math.tau / STANDING_SIDE_STEP))
    half = sides // 2  # exact: as many steps one way round as the other
    order = [0] + [s * k for k in range(1, half + 1) for s in (1, -1)]
    for k in order[:sides]:
        yaw = toward + k * STANDING_SIDE_STEP
        u = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        rotation = hole_grasp_rotation(-u)
        wall = c - middle * u[XY]
        poses = [
            Pose(np.array([*wall, z + params.tip_offset]), rotation)
            for z in (rim + params.clear_height, rim - depth)
        ]
        clear = all(
            nearest(pts @ pose.rotation.T + pose.position, obstacles)[0]
            > params.clearance_margin
            for pose in poses
            for pts in model.values()
        )
        if not clear or (reach is not None and reach(poses) is not None):
            continue
        return PivotFrame(section, np.array([*c, floor_z + radius]), yaw, floor_z)
    return None
