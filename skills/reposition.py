"""Moving a lying part that no pivot can reach where it lies, so that one can.

A part tipped into a bin often ends with an end a few centimetres from a wall: the Grasp would
put the palm into that wall, and the Tilt from the other end would carry the fingers into it
(see :mod:`skills.pivot.clearance`). :func:`plan_reposition` finds the shortest drag --
along the part's axis or across it, never into a wall or a neighbour -- after which the pivot's
sweep clears; :class:`Reposition` does it: the jaws come straight down on either side of the
part (at its middle, or further along where a wall leaves no room there), pinch it across its
diameter, lift it a few millimetres, carry it over, set it down and let go. The part is then
looked at again and pivoted where it now lies.

A round part the jaws cannot come down beside (along a wall, between neighbours) is rolled
instead (:func:`plan_roll`): the closed fingertips press on its top and push across its axis in
the arm's force mode, a stroke at a time, as a person rolls it under a flat hand.

A part raised off the floor -- leaning on a neighbour or a wall, or lying on one -- has no far
corner on the floor for the pivot to turn it about (G, Sec. II), so it is laid down first
(:func:`plan_lay_down`): pinched across its diameter at the height it was seen at, lifted
clear by as much as it is raised, carried to where a pivot clears and lowered until it touches
the floor; let go, a leaning part falls flat about its low end.

This is not the pivot: it is a preparatory move, counted apart (``repositioned``), and it ends
with the jaws open and the part lying on the floor -- the hole grasp is still reached by the
paper's maneuver, without letting go.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from collections.abc import Sequence as Seq
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.axes import DIM, WRENCH_DIM, XY, X, Y, Z
from skills.force import STILL_SPEED
from skills.motion import Guard, GuardedMotion, Sequence, arm_failure, wait
from skills.params import guard_field, si
from skills.pivot.align import hole_grasp_rotation
from skills.pivot.clearance import Obstacle, Reach, choose_end, tool_points
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.slot import ContactMove, SequenceSkill, check
from skills.status import Failure

#: m from the fingertips' edge the part's top is kept at, rolling: the pads' rounded edge
ROLL_EDGE = 0.002
#: m: the fast move ends this far above the part's top, and the slow descent onto it (at
#: ``roll_speed``) aims as far below it (it ends on the touch, well before)
ROLL_DEPTH = 0.01
#: s a roll stroke may stand still before it ends (the part met something, or slid)
ROLL_STALL = 0.3
#: m: a shift shorter than this has no direction (a roll planned as none)
NO_SHIFT = 1e-9
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
    #: A round part the jaws cannot come down beside (along a wall, between neighbours) is
    #: rolled instead, as a person rolls it under a flat hand: the closed fingertips press on
    #: its top and move across its axis; rolling, the part's centre goes half as far as the
    #: fingertips, and the contact runs back across the tips' width, so the roll is a few
    #: strokes, each as long as that width allows, lifting and coming back between them.
    roll_press: float = si(
        4.0, "N", 0.5, 30.0, "the closed fingertips press down on the part's top while rolling"
    )
    roll_push: float = si(
        8.0, "N", 0.5, 50.0, "the fingertips push across the part at most (force mode)"
    )
    roll_speed: float = si(0.02, "m/s", 0.002, 0.1, "of the fingertips rolling the part")
    roll_max: float = si(0.05, "m", 0.005, 0.2, "the farthest a part is rolled")
    #: the pivot turns a lying part about its far corner on the floor (G): one whose axis is
    #: this much higher than lying on the floor puts it (on a neighbour, on a wall's foot) is
    #: laid down first (:func:`plan_lay_down`), as is one seen leaning
    max_raise: float = si(
        0.006, "m", 0.001, 0.05, "a part's axis above where lying puts it: laid down first"
    )
    guard: Guard = field(default_factory=Guard)
    descent_guard: Guard = guard_field(25.0, 10.0, "the jaws down beside the part")


class MoveKind(StrEnum):
    """How a part is moved to where a pivot clears."""

    DRAG = "drag"  #: pinched across its diameter, lifted, carried, set down
    ROLL = "roll"  #: rolled across its axis under the closed fingertips
    #: raised off the floor (leaning on a neighbour or a wall, or lying on one): pinched
    #: where it is, lifted clear, carried and lowered until it touches the floor
    LAY_DOWN = "lay down"


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
    kind: MoveKind = MoveKind.DRAG
    #: m the part's axis goes down from where it is taken to where it lies on the floor (a
    #: lay down; 0 for a part already on it)
    drop: float = 0.0

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(self.shift))


def pinch_pose(
    frame: PivotFrame, part: Part, params: RepositionParams, grip: Grip | None = None
) -> Pose:
    """The TCP pinching the lying part across its diameter at ``grip`` (its middle by
    default): fingers down, jaws across the axis."""
    g = grip or Grip()
    rot = hole_grasp_rotation(frame.normal)  # fingers down, the jaws across the axis
    height = params.grip_height if g.height is None else g.height
    tips = np.asarray(frame.center, float) + g.along * np.asarray(frame.u, float)
    tips[Z] = frame.floor_z + height
    return Pose(tips - params.tip_offset * rot[:, Z], rot)


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
    return _tool_clear(pose, width, params, obstacles, finger_width, params.lift)


def _tool_clear(pose: Pose, width: float, params: RepositionParams, obstacles: Seq[Obstacle],
                finger_width: float, raised: float) -> bool:
    """The tool at jaw opening ``width`` touches no obstacle at ``pose`` raised by ``raised``
    (m), nor ``approach_height`` above that, where it comes down from and rises to."""
    model = tool_points(width, params.tip_offset, params.finger_thickness, finger_width)
    for lift in (0.0, params.approach_height):
        p = Pose(pose.position + np.array([0.0, 0.0, lift + raised]), pose.rotation)
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
    bin clear of its neighbours; where no drag up to ``max_shift`` does, the shortest roll
    (:func:`plan_roll`); None when neither does."""
    obstacles = [*walls, *neighbours]
    free = [g for g in grips(part, params, finger_width)
            if _pinch_clear(frame, part, params, obstacles, finger_width, g)]
    drag = None if not free else _plan_drag(
        frame, part, pivot, params, obstacles, neighbours, interior, finger_width, base_xy,
        free, reach,
    )
    if drag is not None:
        return drag
    return plan_roll(frame, part, pivot, params, walls, neighbours, interior, finger_width,
                     base_xy, reach=reach)


def _fits(moved: PivotFrame, part: Part, params: RepositionParams, interior: Seq[float],
          neighbours: Seq[Obstacle]) -> bool:
    """The part's footprint at ``moved`` lies inside the bin and clear of the neighbours."""
    if not _footprint_inside(moved, part, interior, params.wall_margin):
        return False
    half = 0.5 * np.array([part.length, part.outer, part.outer])  # exact: half sizes
    c, s = math.cos(moved.yaw), math.sin(moved.yaw)
    corners = np.asarray(moved.center, float) + np.array(
        [[a * half[0] * c - b * half[1] * s, a * half[0] * s + b * half[1] * c, 0.0]
         for a in (-1, 0, 1) for b in (-1, 0, 1)]
    )
    return not any(float(np.min(nb.distance(corners))) < params.wall_margin for nb in neighbours)


def _plan_drag(
    frame: PivotFrame, part: Part, pivot: PivotParams, params: RepositionParams,
    obstacles: Seq[Obstacle], neighbours: Seq[Obstacle], interior: Seq[float],
    finger_width: float, base_xy: Seq[float], free: list[Grip], reach: Reach,
    drop: float = 0.0,
) -> RepositionPlan | None:
    """The shortest drag with one of the ``free`` pinches (:func:`plan_reposition`); the part
    comes to lie ``drop`` (m) lower than it is taken (a lay down), its pinch with it."""
    steps = np.arange(params.shift_step, params.max_shift + SHIFT_ROUNDING, params.shift_step)
    directions = [frame.u[XY], -frame.u[XY], frame.normal[XY], -frame.normal[XY]]
    for s in steps:
        for d in directions:
            shift = float(s) * np.asarray(d, float)
            center = np.asarray(frame.center, float).copy()
            center[XY] += shift
            center[Z] -= drop
            moved = replace(frame, center=center)
            if not _fits(moved, part, params, interior, neighbours):
                continue
            # the same pinch must clear where the part is set down
            grip = next((g for g in free if _pinch_clear(moved, part, params, obstacles,
                                                          finger_width, _lowered(g, drop, params))),
                        None)
            if grip is None:
                continue
            choice = choose_end(moved, pivot, obstacles, finger_width, part.open_ends,
                                margin=params.plan_margin, base_xy=base_xy, reach=reach)
            if choice.clearance.clear:
                kind = MoveKind.LAY_DOWN if drop > 0.0 else MoveKind.DRAG
                return RepositionPlan(frame, moved, shift, grip, kind, drop)
    return None


def _lowered(grip: Grip, drop: float, params: RepositionParams) -> Grip:
    """``grip`` on the part lowered by ``drop`` (m)."""
    if drop <= 0.0:
        return grip
    height = params.grip_height if grip.height is None else grip.height
    return replace(grip, height=height - drop)


def plan_lay_down(
    frame: PivotFrame,
    axis_height: float,
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
    leaning: bool = False,
) -> RepositionPlan | None:
    """A part whose axis is ``axis_height`` (m) above the floor at its middle, more than
    lying on it puts it: leaning on a neighbour or a wall, or lying on one. The pivot turns a
    part about its far corner on the floor (G), so this one is laid down first: pinched
    across its diameter where it is (the fingertips ``grip_below_axis`` under its axis), lifted
    clear, carried to the nearest place where a pivot clears (as a drag, :func:`_plan_drag`)
    and lowered until it touches the floor. ``frame``: the part's pivot frame as if it lay on
    the floor where it is; ``leaning``: seen sloping (taken at its middle only). None when no
    pinch clears or no place does. A part no higher than lying is a plain drag."""
    lying = 0.5 * part.outer  # exact: a lying part's axis is half its size up
    drop = max(0.0, axis_height - lying)
    height = axis_height - params.grip_below_axis
    raised = np.asarray(frame.center, float).copy()
    raised[Z] = frame.floor_z + axis_height
    here = replace(frame, center=raised)
    obstacles = [*walls, *neighbours]
    # level on something, the axis is at that height all along it; leaning, only at its
    # middle (its lean is not known here), so a leaning part is taken at its middle only
    along = {g.along for g in grips(part, params, finger_width)} if not leaning else {0.0}
    free = [Grip(a, height) for a in sorted(along, key=abs)
            if _pinch_clear(here, part, params, obstacles, finger_width, Grip(a, height))]
    if not free:
        return None
    return _plan_drag(here, part, pivot, params, obstacles, neighbours, interior, finger_width,
                      base_xy, free, reach, drop)


def is_round(part: Part) -> bool:
    """Whether the part rolls: the catalogue gives a round hole's part a round outside (its
    ``outer`` is a diameter); a rectangular hole's is a box, which does not roll."""
    return part.hole_shape == "circle"


def roll_pose(centre: ArrayLike, frame: PivotFrame, part: Part, params: RepositionParams,
              direction: NDArray[np.float64], finger_width: float, ended: bool = False) -> Pose:
    """The TCP with the closed fingertips on the part's top (lying at ``centre``), side by
    side along its axis, the top under their leading edge (towards ``direction``): rolling,
    the contact runs back across the tips' width. ``ended``: where a full stroke leaves them,
    the top under their trailing edge."""
    rot = hole_grasp_rotation(frame.u)  # fingers down, the tips side by side along the axis
    back = 0.5 * roll_stroke(finger_width)  # exact: the contact's run is centred on the tips
    tips = np.asarray(centre, float) + (back if ended else -back) * direction
    tips[Z] = frame.floor_z + part.outer
    return Pose(tips - params.tip_offset * rot[:, Z], rot)


def roll_stroke(finger_width: float) -> float:
    """m the part's centre goes per stroke: half the fingertips' travel, which is twice the
    width the contact may run back across."""
    return finger_width - 2.0 * ROLL_EDGE  # exact: the width less an edge at each side


def _roll_clear(pose: Pose, params: RepositionParams, obstacles: Seq[Obstacle],
                finger_width: float) -> bool:
    """The closed jaws on the part's top at ``pose``, and above it, touch nothing."""
    return _tool_clear(pose, 0.0, params, obstacles, finger_width, 0.0)


def plan_roll(
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
    """The shortest roll of a round part across its axis (up to ``roll_max``) after which a
    pivot clears, the closed fingertips reaching its top at the start and the end of it without
    touching a wall or a neighbour; None for a part that does not roll or when none does."""
    if not is_round(part):
        return None
    obstacles = [*walls, *neighbours]
    steps = np.arange(params.shift_step, params.roll_max + SHIFT_ROUNDING, params.shift_step)
    for s in steps:
        for sign in (1.0, -1.0):
            direction = sign * frame.normal
            centre = np.asarray(frame.center, float) + float(s) * direction
            moved = replace(frame, center=centre)
            if not _fits(moved, part, params, interior, neighbours):
                continue
            start = roll_pose(frame.center, frame, part, params, direction, finger_width)
            # where the last stroke leaves the tips (ahead of the centre) and they rise from
            end = roll_pose(centre, frame, part, params, direction, finger_width, ended=True)
            if not (_roll_clear(start, params, obstacles, finger_width)
                    and _roll_clear(end, params, obstacles, finger_width)):
                continue
            choice = choose_end(moved, pivot, obstacles, finger_width, part.open_ends,
                                margin=params.plan_margin, base_xy=base_xy, reach=reach)
            if choice.clearance.clear:
                return RepositionPlan(frame, moved, float(s) * direction[XY], kind=MoveKind.ROLL)
    return None


class RollStroke:
    """One stroke: in the arm's force mode the closed fingertips press ``roll_press`` down on
    the part's top and push ``roll_push`` along ``direction`` at ``roll_speed``, until they
    have gone ``travel`` -- or stand still (the part met something), which ends the stroke
    too; ``travelled`` says how far they went."""

    def __init__(self, name: str, dev: Devices, guard: Guard, params: RepositionParams,
                 direction: NDArray[np.float64], travel: Callable[[], float],
                 reference: Callable[[], NDArray[np.float64]]) -> None:
        """``reference``: the force on the tool (N, base frame) with nothing touched, read
        before the fingertips came down on the part: the stroke begins pressing on it, and
        measured from there it would press ``roll_press`` on top of that touch."""
        self.dev, self.params, self.direction, self._travel = dev, params, direction, travel
        self._reference = reference
        self.travelled = 0.0
        self._start_pos = np.zeros(3)
        self._limit = 0.0
        self._last: tuple[float, float] | None = None
        self._still_since: float | None = None
        self.motion = GuardedMotion(
            name, self._start, self._finished, dev.arm, dev.ft, dev.clock, guard,
            lambda: arm_failure(dev.arm),
        )

    def _start(self) -> None:
        p, arm = self.params, self.dev.arm
        ref = np.asarray(self._reference(), float)
        self._start_pos = arm.tool_pose().position.copy()
        self._limit, self.travelled = float(self._travel()), 0.0
        self._last, self._still_since = None, None
        d = self.direction
        selection = [True, True, True] + [False] * (WRENCH_DIM - DIM)
        wrench = [0.0] * WRENCH_DIM
        limits = [0.0] * WRENCH_DIM
        for axis in (X, Y):
            wrench[axis] = float(-ref[axis] + p.roll_push * d[axis])
            limits[axis] = p.roll_speed * abs(float(d[axis]))
        wrench[Z] = float(-ref[Z] - p.roll_press)  # the tool presses down on the top
        limits[Z] = p.roll_speed
        arm.force_mode(selection, wrench, limits)

    def _finished(self) -> bool:
        arm, now = self.dev.arm, self.dev.clock.now()
        self.travelled = float((arm.tool_pose().position - self._start_pos) @ self.direction)
        if self.travelled >= self._limit:
            arm.stop()
            return True
        if self._last is not None and now > self._last[0]:
            speed = (self.travelled - self._last[1]) / (now - self._last[0])
            if speed < STILL_SPEED:
                if self._still_since is None:
                    self._still_since = now
                if now - self._still_since >= ROLL_STALL:
                    arm.stop()
                    return True
            else:
                self._still_since = None
        self._last = (now, self.travelled)
        return False


class Reposition(SequenceSkill):
    """Move a lying part by ``plan.shift``: a drag (pinch it at ``plan.grip``, lift, carry,
    set down); ``plan.kind`` LAY_DOWN, the same from where it is raised, lifted by its raise
    too and lowered until it touches the floor; or, ROLL, a roll under the closed fingertips
    in strokes.

    Before: the part lies where ``plan.frame`` says, the jaws anywhere. After SUCCESS: the part
    lies about ``plan.shift`` further, the jaws ``approach_height`` above it (open after a
    drag, closed after a roll). A descent that meets something before the floor fails
    (``blocked``); a pinch that closes on nothing, or fingertips that find no top, fail
    (``missed``).
    """

    def __init__(
        self, plan: RepositionPlan, part: Part, dev: Devices,
        params: RepositionParams | None = None, **overrides: Any,
    ) -> None:
        p = replace(params or RepositionParams(), **overrides)
        self.plan, self.part, self.dev, self.params = plan, part, dev, p
        if plan.kind is MoveKind.ROLL:
            self.sequence = self._roll()
            return
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
        # a raised part is lifted by its raise as well: what it rests on may be as high as
        # its raise under its low side, so that clears it by ``lift``
        lift = p.lift + plan.drop
        if plan.drop > 0.0:
            # lowered until the part touches the floor, however it hangs in the pinch: aimed
            # ``lift`` below where it would lie, ended by the touch
            lying = pinch_pose(plan.target, part, p, _lowered(plan.grip, plan.drop + p.lift, p))
            set_down = ContactMove(
                "lay it down", dev, p.descent_guard, lambda: lying, p.drag_speed,
                p.acceleration, p.contact_force,
            ).motion
        else:
            set_down = dev.move("set it down", g, lambda: self._move_by(-up * p.lift, p.speed))
        self.sequence = Sequence(
            "reposition",
            [
                dev.grip("open", g, lambda: gripper.open(opening)),
                dev.move("over the part", g, self._over),
                self.descend.motion,
                check("down to the part" if plan.drop > 0.0 else "down to the floor", dev, g,
                      self._down, Failure.BLOCKED),
                dev.grip("pinch", g, lambda: gripper.close(p.grip_force, p.close_speed)),
                check("holding it", dev, g, self._holding, Failure.MISSED),
                dev.move("lift it", g, lambda: self._move_by(up * lift, p.speed)),
                dev.move("carry it", g, lambda: self._move_by(shift, p.drag_speed)),
                set_down,
                dev.grip("let go", g, lambda: gripper.open(opening)),
                wait("settle", dev, g, p.release_settle),
                dev.move("up", g, lambda: self._move_by(up * (part.outer + p.approach_height),
                                                        p.speed)),
            ],
        )

    def _roll(self) -> Sequence:
        """The roll as strokes (:class:`RollStroke`), each from where the last left the part:
        its centre went half as far as the fingertips did."""
        p, dev, plan = self.params, self.dev, self.plan
        g, width = p.guard, dev.gripper.finger_width
        shift = np.array([plan.shift[0], plan.shift[1], 0.0])
        total = float(np.linalg.norm(shift))
        direction = shift / max(total, NO_SHIFT)
        per = roll_stroke(width)
        strokes = max(1, math.ceil(total / per - SHIFT_ROUNDING))
        centre = np.asarray(plan.frame.center, float).copy()
        rolled = [0.0]
        up = np.array([0.0, 0.0, p.approach_height])

        def top() -> Pose:
            return roll_pose(centre, plan.frame, self.part, p, direction, width)

        def over() -> None:
            pose = top()
            above = Pose(pose.position + up, pose.rotation)
            near = Pose(pose.position + np.array([0.0, 0.0, ROLL_DEPTH]), pose.rotation)
            dev.arm.move_path([above, near], p.speed, p.acceleration)

        def into_top() -> Pose:
            pose = top()
            return Pose(pose.position - np.array([0.0, 0.0, ROLL_DEPTH]), pose.rotation)

        steps = [dev.grip("close the jaws", g,
                          lambda: dev.gripper.close(p.grip_force, p.close_speed))]
        for k in range(strokes):
            descend = ContactMove(f"down onto its top ({k + 1} of {strokes})", dev,
                                  p.descent_guard, into_top, p.roll_speed, p.acceleration,
                                  p.contact_force)
            def travel() -> float:
                left = max(0.0, min(per, total - rolled[0]))
                return 2.0 * left  # exact: rolling, the tips go twice as far as the centre

            stroke = RollStroke(f"roll it ({k + 1} of {strokes})", dev, g, p, direction, travel,
                                lambda d=descend: d.reference)

            def found(d: ContactMove = descend) -> str | None:
                return None if d.contact else "the closed fingertips did not meet the part's top"

            def rise(s: RollStroke = stroke) -> None:
                moved = 0.5 * max(0.0, s.travelled)  # exact: rolling, the centre goes half
                rolled[0] += moved
                centre[:] = centre + moved * direction
                here = dev.arm.tool_pose()
                dev.arm.move_to(Pose(here.position + up, here.rotation), p.speed,
                                p.acceleration)

            steps += [
                dev.move(f"over the part ({k + 1} of {strokes})", g, over),
                descend.motion,
                check(f"on its top ({k + 1} of {strokes})", dev, g, found, Failure.MISSED),
                stroke.motion,
                dev.move(f"up ({k + 1} of {strokes})", g, rise),
            ]
        return Sequence("roll", steps)

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
