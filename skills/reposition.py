"""Moving a lying part that no pivot can reach where it lies, so that one can.

A part tipped into a bin often ends with an end a few centimetres from a wall: the Grasp would
put the palm into that wall, and the Tilt from the other end would carry the fingers into it
(see :mod:`skills.pivot.clearance`). :func:`plan_reposition` finds the shortest drag --
along the part's axis or across it, never into a wall or a neighbour -- after which the pivot's
sweep clears; :class:`Reposition` does it: the jaws come straight down on either side of the
part (at its middle, or further along where a wall leaves no room there), pinch it across its
diameter, lift it a few millimetres, carry it over, set it down and let go. The part is then
looked at again and pivoted where it now lies.

This is not the pivot: it is a preparatory move, counted apart (``repositioned``), and it ends
with the jaws open and the part lying on the floor -- the hole grasp is still reached by the
paper's maneuver, without letting go.
"""

from __future__ import annotations

import math
from collections.abc import Sequence as Seq
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.axes import XY, Z
from skills.motion import Guard, Sequence, wait
from skills.params import guard_field, si
from skills.pivot.clearance import Obstacle, Reach, choose_end, tool_points
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.slot import ContactMove, SequenceSkill, check
from skills.status import Failure

#: m added to ``max_shift`` as the end of the range of drags tried: floating-point room, far
#: below a step, so a ``max_shift`` that is a whole number of steps is itself tried
SHIFT_ROUNDING = 1e-9


@dataclass(frozen=True)
class RepositionParams:
    """Parameters of :class:`Reposition` (SI units); the fields declared with
    :func:`~skills.params.si` are the ``skills.reposition`` section of a cell's configuration."""

    tip_offset: float = 0.005  #: m from the TCP to the fingertips along the tool z axis (gripper)
    finger_thickness: float = 0.008  #: m from a pad's face to its back (the gripper model's)
    side_gap: float = si(0.008, "m", 0.002, 0.03, "between each pad and the part, jaws open")
    grip_height: float = si(
        0.006, "m", 0.0, 0.05, "above the floor the fingertips pinch the lying part at"
    )
    #: where the jaws cannot come down at the middle (the 2F-85's body over a wall's top), the
    #: pinch is tried further along the axis (its pads kept on the part) and higher (the pads'
    #: tips kept ``grip_below_axis`` below the part's axis, so they still close across its
    #: diameter): what a person does, taking a part by whatever of it is free
    grip_step: float = si(0.01, "m", 0.002, 0.05, "between the pinch places tried along the axis")
    grip_below_axis: float = si(
        0.006, "m", 0.0, 0.05, "the fingertips reach below the part's axis, at the highest pinch"
    )
    approach_height: float = si(0.08, "m", 0.0, 0.3, "above the part the jaws come down from")
    lift: float = si(0.003, "m", 0.0, 0.02, "the part is lifted off the floor to be carried")
    grip_force: float = si(
        20.0, "N", 0.1, 235.0, "per finger of the pinch", actuator="grip_force"
    )
    close_speed: float = si(
        0.05, "m/s", 0.001, 0.15, "of each finger closing on the part", actuator="finger_speed"
    )
    speed: float = si(0.08, "m/s", 0.005, 0.5, "of the TCP over and down to the part")
    drag_speed: float = si(0.03, "m/s", 0.005, 0.2, "of the TCP carrying the part")
    acceleration: float = si(0.5, "m/s^2", 0.01, 3.0, "of the TCP")
    contact_force: float = si(5.0, "N", 0.5, 50.0, "against the descent that means contact")
    max_shift: float = si(0.15, "m", 0.01, 0.5, "the farthest a part is carried")
    shift_step: float = si(0.01, "m", 0.002, 0.05, "between the drags tried, shortest first")
    wall_margin: float = si(0.01, "m", 0.0, 0.05, "kept between the part's new place and a wall")
    #: the drag lands a few millimetres off its plan (the part slips in the pinch, the look
    #: after it errs): the pivot's sweep from the new place is planned with this margin
    plan_margin: float = si(
        0.012, "m", 0.0, 0.05, "the pivot's sweep keeps from walls, planned from the new place"
    )
    #: the jaws open, held still this long before they rise, so the part let go comes to rest
    #: before the fingers leave it
    release_settle: float = si(0.1, "s", 0.0, 2.0, "held still after letting go, before rising")
    guard: Guard = field(default_factory=Guard)
    descent_guard: Guard = guard_field(25.0, 10.0, "the jaws down beside the part")


@dataclass(frozen=True)
class Grip:
    """Where the pinch takes the lying part: along its axis from its middle (m, + towards
    ``frame.u``) and its fingertips' height above the floor (m; None: ``grip_height``)."""

    along: float = 0.0
    height: float | None = None


@dataclass(frozen=True)
class RepositionPlan:
    """Where the part goes: its frame now and after the drag, the drag (m, world xy)."""

    frame: PivotFrame
    target: PivotFrame
    shift: NDArray[np.float64]
    grip: Grip = field(default_factory=lambda: Grip())  #: where the jaws take the part

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(self.shift))


def pinch_pose(
    frame: PivotFrame, part: Part, params: RepositionParams, grip: Grip | None = None
) -> Pose:
    """The TCP pinching the lying part across its diameter at ``grip`` (its middle by
    default): fingers down, jaws across the axis."""
    g = grip or Grip()
    z = np.array([0.0, 0.0, -1.0])
    x = frame.normal
    rot = np.column_stack([x, np.cross(z, x), z])
    height = params.grip_height if g.height is None else g.height
    tips = np.asarray(frame.center, float) + g.along * np.asarray(frame.u, float)
    tips[Z] = frame.floor_z + height
    return Pose(tips - params.tip_offset * z, rot)


def grips(part: Part, params: RepositionParams, finger_width: float) -> list[Grip]:
    """The pinches a drag may use, the middle first, then further out along the axis (the
    pads kept wholly on the part), each low first, then as high as still closes across the
    diameter."""
    reach = max(0.0, 0.5 * (part.length - finger_width))  # exact: the pads' centre's travel
    steps = np.arange(0.0, reach + SHIFT_ROUNDING, params.grip_step)
    along = [0.0] + [float(s * k) for s in steps[1:] for k in (1.0, -1.0)]
    high = 0.5 * part.outer - params.grip_below_axis  # exact: the part's axis height
    heights: list[float | None] = [None]
    if high > params.grip_height:
        heights.append(high)
    return [Grip(a, h) for a in along for h in heights]


def _footprint_inside(frame: PivotFrame, part: Part, interior: Seq[float], margin: float) -> bool:
    x0, x1, y0, y1 = interior
    u, n = frame.u[XY], frame.normal[XY]
    c = np.asarray(frame.center[XY], float)
    half, radius = 0.5 * part.length, 0.5 * part.outer  # exact: the footprint's half sizes
    for su in (-1.0, 1.0):
        for sn in (-1.0, 1.0):
            px, py = c + su * half * u + sn * radius * n
            if not (x0 + margin <= px <= x1 - margin and y0 + margin <= py <= y1 - margin):
                return False
    return True


def _pinch_clear(
    frame: PivotFrame, part: Part, params: RepositionParams, obstacles: Seq[Obstacle],
    finger_width: float, grip: Grip | None = None,
) -> bool:
    """The open jaws come down beside the part at ``grip`` without touching a wall or a
    neighbour."""
    pose = pinch_pose(frame, part, params, grip)
    width = part.outer + 2.0 * params.side_gap  # exact: a side gap each side of the part
    model = tool_points(width, params.tip_offset, params.finger_thickness, finger_width)
    for lift in (0.0, params.approach_height):
        p = Pose(pose.position + np.array([0.0, 0.0, lift + params.lift]), pose.rotation)
        for pts in model.values():
            world = pts @ p.rotation.T + p.position
            if any(float(np.min(ob.distance(world))) < 0.0 for ob in obstacles):
                return False
    return True


def plan_reposition(
    frame: PivotFrame,
    part: Part,
    pivot: PivotParams,
    params: RepositionParams,
    walls: Seq[Obstacle],
    neighbours: Seq[Obstacle],
    interior: Seq[float],
    finger_width: float,
    base_xy: Seq[float] = (0.0, 0.0),
    *,
    reach: Reach,
) -> RepositionPlan | None:
    """The shortest drag (along the axis, then across it) after which a pivot clears (within
    the arm's ``reach``), the pinch clears both here and there, and the part lies inside the
    bin clear of its neighbours; None when no drag up to ``max_shift`` does."""
    obstacles = [*walls, *neighbours]
    free = [g for g in grips(part, params, finger_width)
            if _pinch_clear(frame, part, params, obstacles, finger_width, g)]
    if not free:
        return None
    steps = np.arange(params.shift_step, params.max_shift + SHIFT_ROUNDING, params.shift_step)
    directions = [frame.u[XY], -frame.u[XY], frame.normal[XY], -frame.normal[XY]]
    for s in steps:
        for d in directions:
            shift = float(s) * np.asarray(d, float)
            center = np.asarray(frame.center, float).copy()
            center[XY] += shift
            moved = replace(frame, center=center)
            if not _footprint_inside(moved, part, interior, params.wall_margin):
                continue
            half = 0.5 * np.array([part.length, part.outer, part.outer])  # exact: half sizes
            body = Obstacle("the part", center, half, moved.yaw)
            corners = body.center + np.array(
                [[a * body.half[0] * math.cos(moved.yaw) - b * body.half[1] * math.sin(moved.yaw),
                  a * body.half[0] * math.sin(moved.yaw) + b * body.half[1] * math.cos(moved.yaw),
                  0.0] for a in (-1, 0, 1) for b in (-1, 0, 1)]
            )
            if any(float(np.min(nb.distance(corners))) < params.wall_margin for nb in neighbours):
                continue
            # the same pinch must clear where the part is set down
            grip = next((g for g in free if _pinch_clear(moved, part, params, obstacles,
                                                          finger_width, g)), None)
            if grip is None:
                continue
            choice = choose_end(moved, pivot, obstacles, finger_width, part.open_ends,
                                margin=params.plan_margin, base_xy=base_xy, reach=reach)
            if choice.clearance.clear:
                return RepositionPlan(frame, moved, shift, grip)
    return None


class Reposition(SequenceSkill):
    """Carry a lying part by ``plan.shift``: pinch it across its middle, lift, carry, set down.

    Before: the part lies where ``plan.frame`` says, the jaws anywhere. After SUCCESS: the part
    lies about ``plan.shift`` further, the jaws open ``approach_height`` above it. A descent
    that meets something before the floor fails (``blocked``); a pinch that closes on nothing
    fails (``missed``).
    """

    def __init__(
        self, plan: RepositionPlan, part: Part, dev: Devices,
        params: RepositionParams | None = None, **overrides: Any,
    ) -> None:
        p = replace(params or RepositionParams(), **overrides)
        self.plan, self.part, self.dev, self.params = plan, part, dev, p
        self._pinch = pinch_pose(plan.frame, part, p, plan.grip)
        up = np.array([0.0, 0.0, 1.0])
        self._above = Pose(self._pinch.position + (part.outer + p.approach_height) * up,
                           self._pinch.rotation)
        self.descend = ContactMove(
            "down beside the part", dev, p.descent_guard, lambda: self._pinch, p.speed,
            p.acceleration, p.contact_force,
        )
        g = p.guard
        gripper = dev.gripper
        shift = np.array([plan.shift[0], plan.shift[1], 0.0])
        opening = part.outer + 2.0 * p.side_gap  # exact: a side gap each side of the part
        self.sequence = Sequence(
            "reposition",
            [
                dev.grip("open", g, lambda: gripper.open(opening)),
                dev.move("over the part", g, self._over),
                self.descend.motion,
                check("down to the floor", dev, g, self._down, Failure.BLOCKED),
                dev.grip("pinch", g, lambda: gripper.close(p.grip_force, p.close_speed)),
                check("holding it", dev, g, self._holding, Failure.MISSED),
                dev.move("lift it", g, lambda: self._move_by(up * p.lift, p.speed)),
                dev.move("carry it", g, lambda: self._move_by(shift, p.drag_speed)),
                dev.move("set it down", g, lambda: self._move_by(-up * p.lift, p.speed)),
                dev.grip("let go", g, lambda: gripper.open(opening)),
                wait("settle", dev, g, p.release_settle),
                dev.move("up", g, lambda: self._move_by(up * (part.outer + p.approach_height),
                                                        p.speed)),
            ],
        )

    def _over(self) -> None:
        arm, p = self.dev.arm, self.params
        tool = arm.tool_pose()
        high = self._above.position.copy()
        high[Z] = max(high[Z], float(tool.position[Z]))
        arm.move_path([Pose(high, self._above.rotation), self._above], p.speed, p.acceleration)

    def _move_by(self, d: NDArray[np.float64], speed: float) -> None:
        arm = self.dev.arm
        tool = arm.tool_pose()
        arm.move_to(Pose(tool.position + d, tool.rotation), speed, self.params.acceleration)

    def _down(self) -> str | None:
        if self.descend.contact:
            return (
                f"the jaws met something ({self.descend.resisting:.1f} N) on the way down "
                "beside the part"
            )
        return None

    def _holding(self) -> str | None:
        if not self.dev.gripper.object_detected():
            return "the pinch closed on nothing"
        return None
