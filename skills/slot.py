"""Feeding a part held in the hole grasp into the machine's slot, and picking it out again.

The application of Sec. IV-C of the paper (Fig. 16): the slot is a square pocket only 5 mm wider
than the part (2.5 mm a side), so a finger on the part's outer wall cannot enter it; in the hole
grasp the outer finger stays above the machine while the part and the finger inside its hole go
in. :class:`FeedSlot`:

1. lift to the travel height and carry the part over the slot (the slot's place comes from the
   cell's configuration, never from the simulator), fingers down, so the part's axis is over the
   pocket's centre;
2. hold still and read the wrench with the part hanging (the reference for contact and weight);
3. lower the part into the pocket slowly (with ``pocket_speed`` set: slowly only near the
   pocket's edge and its floor) until the slot floor pushes back (the force along the motion
   rises by ``contact_force`` over the reference), or until the outer finger would come
   within ``finger_clearance`` of the machine's top (a deep grasp: the part is then let go a few
   millimetres above the floor, guided by the pocket);
4. ease the jaws (release) and drag the gripper up: the finger in the hole slides out while the
   pocket keeps the part; the wrench then must have lost the part's weight.

:class:`PickFromSlot` takes the same hole grasp on the part standing in the slot -- found by the
wrist camera's view of its rim as in Align, or assumed at the slot's centre -- and lifts it out.

Geometry of the hole grasp (see :mod:`skills.pivot.align`): fingers straight down, tool ``x``
(towards ``finger_a``, the outer finger) horizontal; the pads pinch the wall nearest ``finger_a``,
so the part's axis is ``offset = (outer + inner) / 2`` from the TCP along ``-x`` (``inner``: where
a pad in a round hole touches, the chord of Eq. 2). ``grip_depth`` is how far the fingertips reach
below the rim; the TCP is ``tip_offset`` above the fingertips.

Every motion runs under a guard (:mod:`skills.motion`). The helpers here (:func:`contact_move`,
:func:`travel_path`, :func:`hold_pose`) are shared with :mod:`skills.packing`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.arm import Arm, MotionState
from drivers.camera import Camera, Frame
from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.axes import FZ, XY, Z
from skills.force import nothing_pressed, world_force
from skills.frames import frame_step
from skills.motion import Failed, Guard, GuardedMotion, Sequence, arm_failure
from skills.params import guard_field, si
from skills.perception import UprightPart, locate_upright_part
from skills.pivot.align import hole_grasp_rotation, pinched_span
from skills.status import Failure, StepResult
from skills.travel import ArmModel, joint_goal

GRAVITY = 9.81  #: m/s^2
#: the length below which a vector is taken to have no direction (a direction's horizontal
#: part, a move's displacement in m): numerical, far below any distance the arm resolves
NO_DIRECTION = 1e-9
#: m^2, the least squared length of a travel path's horizontal leg the closest-point formula
#: divides by: numerical, so a leg of zero length (start over the target) is no division by 0
MIN_LEG_SQUARED = 1e-12
#: rad, the largest turn about the base axis between two waypoints of a travel path's arc:
#: the straight line between two of them dips at most 1 - cos(20 deg), 6 %, of the arc's
#: radius inside it, so it stays well away from the base axis
ARC_STEP = math.radians(40.0)
#: m, the rise or descent to the travel height is left out when shorter than this: the start
#: is already at that height, a tenth of a millimetre is no move to make
SAME_HEIGHT = 1e-4

#: The travel by joint move (:mod:`skills.travel`): default, unit, range and sentence of the
#: joint speed (0: straight travel paths only) and acceleration, shared with the packing's
JOINT_TRAVEL_SPEED = (
    math.radians(60.0), "rad/s", 0.0, math.radians(180.0),
    "of the joint moving most in a travel by joint move; 0: straight travel paths only",
)
#: (the TCP's own limit in a joint move: at 120 deg/s the cell's travels peaked at 1.0-1.35 m/s
#: with the part held, where the straight paths ran at 0.2-0.3 m/s)
JOINT_TRAVEL_TCP_SPEED = (
    1.0, "m/s", 0.05, 3.0,
    "the fastest the TCP may go in a travel by joint move (the joints slow to keep it)",
)
#: (its acceleration; the shipped cell's way home runs at 120 deg/s and 300 deg/s^2)
JOINT_TRAVEL_ACCELERATION = (
    math.radians(120.0), "rad/s^2", math.radians(6.0), math.radians(600.0),
    "of the joint moving most in a travel by joint move",
)


@dataclass(frozen=True)
class SlotParams:
    """Parameters of :class:`FeedSlot` and :class:`PickFromSlot` (SI units); the fields declared
    with :func:`~skills.params.si` are the ``skills.slot`` section of a cell's configuration."""

    #: It must leave the outer finger above the machine when the part stands on the slot floor:
    #: ``grip_depth < length - slot_depth`` (28 mm for the bushing in the 40 mm pocket). The cell
    #: gives Align and the packing this same depth, so every hole grasp is the one the slot expects.
    grip_depth: float = si(
        0.020, "m", 0.005, 0.2, "the fingertips reach below the rim in the hole grasp"
    )
    #: m, the pocket's depth: the machine's top is this above its floor (in the cell: the
    #: layout's ``slot_depth``, the pocket the twin builds, so not a key of its own)
    slot_depth: float = 0.040
    tip_offset: float = 0.005  #: m from the TCP to the fingertips along the tool z axis (gripper)
    #: Direction (x, y) of tool x -- the outer finger's side of the part -- over the slot;
    #: None keeps the held grasp's (FeedSlot) or points it at the robot base (PickFromSlot).
    finger_dir: tuple[float, float] | None = None
    clear_height: float = si(
        0.02, "m", 0.0, 0.2, "between the part (or fingertips) and the machine's top"
    )
    travel_z: float = si(
        0.13, "m", 0.0, 0.5,
        "the lowest the part's bottom (or the fingertips) travels at; it must clear every "
        "fixture the arm travels over (a joint move sweeps an arc about the base, off the "
        "straight line)"
    )
    min_radius: float = si(0.30, "m", 0.0, 0.8, "from the base axis a travel path keeps")
    travel_speed: float = si(0.15, "m/s", 0.01, 1.0, "of the TCP travelling")
    joint_speed: float = si(*JOINT_TRAVEL_SPEED)
    joint_acceleration: float = si(*JOINT_TRAVEL_ACCELERATION)
    joint_tcp_speed: float = si(*JOINT_TRAVEL_TCP_SPEED)
    approach_speed: float = si(0.05, "m/s", 0.001, 0.5, "of the TCP approaching")
    insert_speed: float = si(0.01, "m/s", 0.001, 0.1, "into the pocket and onto its floor")
    #: The insertion need be slow only where the part can meet something: at the pocket's edge
    #: and near its floor. Between them the pocket's walls guide it, and above the machine
    #: nothing is nearer than the edge. The whole 60 mm at ``insert_speed`` (0.02 m/s in the
    #: shipped example) took about 3 s of each feed. A contact in a fast leg ends the insertion
    #: as a failure: only the last, slow leg may find the floor.
    pocket_speed: float = si(
        0.0, "m/s", 0.0, 0.5,
        "of the feed's insertion away from the pocket's edge and floor (0: insert_speed the "
        "whole way)",
    )
    slow_margin: float = si(
        0.005, "m", 0.001, 0.05,
        "above and below the pocket's edge, and above depth_tolerance over its floor, the "
        "insertion keeps to insert_speed (with pocket_speed set)",
    )
    acceleration: float = si(0.3, "m/s^2", 0.01, 3.0, "of the TCP")
    settle: float = si(0.2, "s", 0.0, 5.0, "held still before the reference wrench is read")
    contact_force: float = si(4.0, "N", 0.5, 50.0, "against the motion that means contact")
    overshoot: float = si(
        0.004, "m", 0.0, 0.02, "the insertion aims below the slot floor (contact stops it)"
    )
    depth_tolerance: float = si(
        0.006, "m", 0.0, 0.03, "above the floor a contact may be and still be on it"
    )
    finger_clearance: float = si(
        0.003, "m", 0.0, 0.02, "the outer fingertip keeps above the machine's top"
    )
    max_drop: float = si(0.020, "m", 0.0, 0.1, "the highest a part may be let go above the floor")
    release: float = si(0.006, "m", 0.0, 0.03, "the jaws open to let go")
    wall_gap: float = si(
        0.004, "m", 0.0, 0.02, "between each pad and the wall before the pinch (pick)"
    )
    hold_force: float = si(
        20.0, "N", 0.1, 235.0, "per finger of the hole grasp (pick)", actuator="grip_force"
    )
    pinch_settle: float = si(
        0.3, "s", 0.0, 2.0, "the pinch's fingers stand still this long before the check (pick)"
    )
    #: The pads go down beside the wall at this fraction of ``approach_speed``: slower, so a pad
    #: landing on the rim meets ``descent_guard`` before it presses hard.
    beside_wall_speed_factor: float = si(
        0.5, "1", 0.01, 1.0, "times approach_speed for the pads going down beside the wall (pick)"
    )
    view_height: float = si(
        0.20, "m", 0.05, 1.0, "of the camera above the rim when looking (pick)"
    )
    view_search: float = si(0.03, "m", 0.0, 0.2, "the part may stand off the slot's centre")
    use_camera: bool = True  #: PickFromSlot finds the rim with the camera (if there is one)
    #: A part that came out with the gripper loses nothing, one left in the slot all of its
    #: weight; half tells them apart with the FT300's noise far below a part's weight.
    weight_check: float = si(
        0.5, "1", 0.0, 1.0,
        "fraction of the part's weight the wrench must lose (feed) or gain (pick); 0: no check",
    )
    guard: Guard = field(default_factory=Guard)
    insert_guard: Guard = guard_field(
        30.0, 15.0, "into the pocket and onto its floor (a part on the edge must stop the arm)"
    )
    descent_guard: Guard = guard_field(
        25.0, 10.0, "pads down beside the wall (a pad landing on the rim must stop the arm)"
    )


# ------------------------------------------------------------------------ shared helpers
def grasp_offset(part: Part, finger_width: float) -> float:
    """Distance (m) from the part's axis to the TCP in the hole grasp, along tool ``x``."""
    outer, inner = pinched_span(part, finger_width)
    return 0.5 * (outer + inner)  # exact: the axis is midway between the two pad contacts


def horizontal(v: ArrayLike) -> NDArray[np.float64]:
    """Unit vector of the horizontal part of ``v`` (x, y, 0)."""
    a = np.asarray(v, float)
    h = np.array([a[0], a[1], 0.0])
    n = float(np.linalg.norm(h))
    if n < NO_DIRECTION:
        raise ValueError(f"direction {a!r} has no horizontal part")
    return h / n


def hold_pose(
    axis_xy: ArrayLike, bottom_z: float, part: Part, x_dir: ArrayLike, offset: float,
    grip_depth: float, tip_offset: float,
) -> Pose:
    """TCP pose that holds ``part`` in the hole grasp with its axis at ``axis_xy`` and its bottom
    at ``bottom_z`` (m), the outer finger towards ``x_dir``."""
    x = horizontal(x_dir)
    xy = np.asarray(axis_xy, float)[XY]
    z = bottom_z + part.length - grip_depth + tip_offset
    return Pose(np.array([*(xy + offset * x[XY]), z]), hole_grasp_rotation(x))


def travel_path(start: Pose, target: Pose, min_radius: float) -> list[Pose]:
    """Waypoints from ``start`` to ``target``: up (or down) to the target's height first, then
    across; when the straight line across would pass within ``min_radius`` (m) of the base axis
    (where a UR5's wrist cannot follow a Cartesian line), through a point on an arc around it."""
    up = Pose(np.array([*start.position[XY], target.position[Z]]), start.rotation)
    a, b = up.position[XY], target.position[XY]
    d = b - a
    s = float(np.clip(-(a @ d) / max(float(d @ d), MIN_LEG_SQUARED), 0.0, 1.0))
    closest = float(np.linalg.norm(a + s * d))
    points = [up]
    if closest < min_radius:
        ang_a, ang_b = math.atan2(a[1], a[0]), math.atan2(b[1], b[0])
        turn = (ang_b - ang_a + math.pi) % math.tau - math.pi
        radius = max(min_radius, float(np.linalg.norm(a)), float(np.linalg.norm(b)))
        steps = max(1, int(abs(turn) // ARC_STEP))
        for k in range(1, steps + 1):
            frac = k / (steps + 1)
            ang = ang_a + turn * frac
            pos = np.array([radius * math.cos(ang), radius * math.sin(ang), target.position[Z]])
            points.append(Pose(pos, up.interpolate(target, frac).rotation))
    points.append(target)
    if up.distance(start)[0] < SAME_HEIGHT:
        points = points[1:]
    return points


@dataclass(frozen=True)
class Travel:
    """How a skill travels between fixtures: by a joint move where :mod:`skills.travel` finds
    its swept path clear (``model`` given, ``joint_speed`` above 0), else along
    :func:`travel_path`."""

    model: ArmModel | None
    speed: float  #: m/s, the TCP along a travel path
    acceleration: float  #: m/s^2
    joint_speed: float  #: rad/s, the joint moving most in a joint move; 0: never one
    joint_acceleration: float  #: rad/s^2
    joint_tcp_speed: float  #: m/s, the TCP's limit in a joint move (the joints slow to it)
    min_radius: float  #: m from the base axis a travel path keeps

    @classmethod
    def of(cls, model: ArmModel | None, p: Any) -> Travel:
        """From a skill's parameters (:class:`SlotParams`, the packing's: the same fields)."""
        return cls(model, p.travel_speed, p.acceleration, p.joint_speed, p.joint_acceleration,
                   p.joint_tcp_speed, p.min_radius)

    def start(self, arm: Arm, target: Pose) -> bool:
        """Start the travel to ``target``; True when it is a joint move."""
        move = None
        if self.joint_speed > 0:
            move = joint_goal(self.model, arm.joint_positions(), target, self.min_radius)
        if move is None:
            path = travel_path(arm.tool_pose(), target, self.min_radius)
            arm.move_path(path, self.speed, self.acceleration)
            return False
        speed = move.joint_speed(self.joint_speed, self.joint_tcp_speed)
        arm.move_joints(move.goal, speed, self.joint_acceleration)
        return True


def rise_to(arm: Arm, z: float, speed: float, acceleration: float) -> None:
    """Start a straight vertical move of the TCP up to height ``z`` (m); one already at or
    above it stays where it is (the move ends at once)."""
    tool = arm.tool_pose()
    arm.move_to(
        Pose(np.array([*tool.position[XY], max(z, tool.position[Z])]), tool.rotation),
        speed, acceleration,
    )


#: Share of a weight check's hold not averaged: the motion before it is still stopping there
#: (a force mode's stop, an arm trailing its stream), its braking read as weight.
HOLD_UNSETTLED = 0.5


class WrenchReference:
    """The force on the tool read holding still, before a part is let go or taken (the part
    hanging, or the empty gripper): the weight check afterwards compares with it, so the
    sensor's offset and the tool's own weight cancel out.

    Both sides of the comparison are means over a hold (:meth:`hold`), not single readings: a
    part that rocks on a pad's corner after a lift swings the wrist's reading by a newton and
    more from one sample to the next (the twin read 1.44-1.67 N for a held 1.53 N bushing and
    then, one sample, 0.57 N: a held part called left behind). A reading with no hold before it
    is the sample then."""

    def __init__(self, dev: Devices) -> None:
        self.dev = dev
        self.force: NDArray[np.float64] | None = None  #: N, base frame; None until read
        self._sum = np.zeros(3)
        self._count = 0

    def hold(self, name: str, guard: Guard, seconds: float) -> GuardedMotion:
        """Hold still for ``seconds`` under ``guard``, averaging the wrist's force over the
        hold's second half (the first still carries the stop of the motion before it: a force
        mode's stop, an arm trailing its stream): the reading the next :meth:`read`,
        :meth:`lost` or :meth:`gained` uses. At least the last sample counts."""
        clock = self.dev.clock
        began = [0.0]

        def start() -> None:
            self._sum, self._count = np.zeros(3), 0
            began[0] = clock.now()

        def done() -> bool:
            held = clock.now() - began[0]
            finished = held >= seconds
            if held >= HOLD_UNSETTLED * seconds or finished:
                self._sum = self._sum + world_force(self.dev)
                self._count += 1
            return finished

        return GuardedMotion(name, start, done, self.dev.arm, self.dev.ft, clock, guard)

    def _now(self) -> NDArray[np.float64]:
        """The mean over the last hold, or the reading now when there was none since the
        reference was read."""
        if self._count:
            return self._sum / self._count
        return world_force(self.dev)

    def read(self) -> str | None:
        """Take the reference now (a :func:`check`'s test: it never fails)."""
        self.force = self._now()
        self._sum, self._count = np.zeros(3), 0
        return None

    def lost(self) -> float:
        """N of downward pull the tool lost since the reference (a part let go: its weight)."""
        assert self.force is not None
        return float(self._now()[FZ] - self.force[FZ])

    def gained(self) -> float:
        """N of downward pull the tool gained since the reference (a part taken: its weight)."""
        assert self.force is not None
        return float(self.force[FZ] - self._now()[FZ])


class ContactMove:
    """A guarded straight move that ends at its target or as soon as the force *against* the
    motion rises ``threshold`` (N) above its value when the move started; ``contact`` says which.

    The reference is taken at the start, so a held part's weight and the sensor's drift do not
    count as contact. Arriving without contact is success too; the caller decides what it means.
    """

    def __init__(
        self,
        name: str,
        dev: Devices,
        guard: Guard,
        target: Callable[[], Pose | None],
        speed: float,
        acceleration: float,
        threshold: float,
        reference: Callable[[], ArrayLike | None] | None = None,
    ) -> None:
        """``target``: read when the move starts; None: the move is not made (it ends at once,
        without contact). ``reference``: the force on the tool (N, base frame) that counts as
        nothing touched (default, or when it gives None: the reading at the start)."""
        self.dev, self._target, self.threshold = dev, target, threshold
        self._speed, self._acc = speed, acceleration
        self._reference = reference
        self._skipped = False
        self.contact = False
        self.contact_pose: Pose | None = None
        self.resisting = 0.0  #: N, the newest force against the motion (above the reference)
        #: N, base frame: the force on the tool when the move started (nothing touched yet)
        self.reference = np.zeros(3)
        self._dir = np.zeros(3)
        self.motion = GuardedMotion(
            name, self._start, self._finished, dev.arm, dev.ft, dev.clock, guard, self._failed
        )

    def _start(self) -> None:
        target = self._target()
        self.contact, self.contact_pose = False, None
        self._skipped = target is None
        if target is None:
            return
        start = self.dev.arm.tool_pose().position
        d = target.position - start
        self._dir = d / max(float(np.linalg.norm(d)), NO_DIRECTION)
        self.reference = nothing_pressed(self.dev, self._reference)
        self.dev.arm.move_to(target, self._speed, self._acc)

    def _finished(self) -> bool:
        if self._skipped:
            return True
        self.resisting = -float((world_force(self.dev) - self.reference) @ self._dir)
        if self.resisting > self.threshold:
            self.dev.arm.stop()
            self.contact, self.contact_pose = True, self.dev.arm.tool_pose()
            return True
        return self.dev.arm.status().state is MotionState.DONE

    def _failed(self) -> Failed | None:
        if self._skipped:  # the arm stands where a contact before stopped it
            return None
        return arm_failure(self.dev.arm, self.contact)


def check(
    name: str,
    dev: Devices,
    guard: Guard,
    test: Callable[[], str | None],
    failure: Failure = Failure.CHECK_FAILED,
) -> GuardedMotion:
    """A step that moves nothing and fails with ``test()``'s reason (a sensed condition)."""
    return GuardedMotion(
        name, lambda: None, lambda: True, dev.arm, dev.ft, dev.clock, guard, test, failure
    )


class SequenceSkill:
    """Ticks a :class:`Sequence`; ``halt()`` stops the step in progress (idempotent)."""

    sequence: Sequence

    def tick(self) -> StepResult:
        return self.sequence.tick()

    def halt(self) -> None:
        self.sequence.halt()

    @property
    def step(self) -> str:
        """Name of the step in progress (or ``done``)."""
        return self.sequence.current


class StepsSkill(SequenceSkill):
    """A :class:`SequenceSkill` over steps another skill built: the rest of that skill's work
    after it stopped (``leave()`` of :class:`FeedSlot` and of the packing)."""

    def __init__(self, sequence: Sequence) -> None:
        self.sequence = sequence


class _SlotSkill(SequenceSkill):
    """The start FeedSlot and PickFromSlot share: their parameters (with overrides), where the
    slot's floor and the machine's top are, and the wrench reference of the weight check."""

    def __init__(
        self,
        slot_center: ArrayLike,
        part: Part,
        dev: Devices,
        params: SlotParams | None,
        overrides: dict[str, Any],
    ) -> None:
        p = replace(params or SlotParams(), **overrides)
        self.part, self.dev, self.params = part, dev, p
        slot = np.asarray(slot_center, float)
        self.slot_xy, self.slot_floor_z = slot[XY].copy(), float(slot[Z])
        self.machine_top_z = self.slot_floor_z + p.slot_depth
        self.reference = WrenchReference(dev)

    def _hold_still_and_read(self, what: str) -> list[GuardedMotion]:
        """Hold still ``settle`` s, then read the reference wrench with ``what`` on the tool."""
        dev, p = self.dev, self.params
        return [
            self.reference.hold("hold still", p.guard, p.settle),
            check(f"read the {what}", dev, p.guard, self.reference.read),
        ]

    def _settle_and_check(
        self, name: str, test: Callable[[], str | None], failure: Failure
    ) -> list[GuardedMotion]:
        """Let the part settle ``settle`` s, then check ``test`` (the weight check)."""
        dev, p = self.dev, self.params
        return [
            self.reference.hold("settle", p.guard, p.settle),
            check(name, dev, p.guard, test, failure),
        ]

    def _weight_checked(self) -> bool:
        return self.params.weight_check > 0 and self.reference.force is not None

    def _weight(self) -> float:
        """N, the part's weight."""
        return self.part.mass * GRAVITY


# ------------------------------------------------------------------------------ FeedSlot
class FeedSlot(_SlotSkill):
    """Put the part held in the hole grasp into the slot, let go, drag the gripper out.

    Before: the part hangs in the hole grasp (Align's, or :class:`PickFromSlot`'s), fingers down,
    ``params.grip_depth`` below its rim. After SUCCESS: the part stands in the pocket, the jaws
    are open by ``release`` more than they held it, the fingertips are ``clear_height`` above the
    machine's top, over the slot. ``on_floor`` says whether the floor was felt (else the part was
    let go ``drop`` metres above it).

    Steps: over the slot, down to it, read the hanging part; into the slot until the floor
    pushes back, check where it landed; let go, drag the gripper out, check the weight is gone.
    """

    def __init__(
        self,
        slot_center: ArrayLike,
        part: Part,
        dev: Devices,
        params: SlotParams | None = None,
        arm_model: ArmModel | None = None,
        **overrides: Any,
    ) -> None:
        """``slot_center``: (x, y, z) of the centre of the pocket's floor (m, base frame);
        ``arm_model``: the arm's kinematics, for travelling by a joint move (None: straight
        travel paths only); ``overrides``: fields of :class:`SlotParams` to change
        (``grip_depth=0.02``)."""
        super().__init__(slot_center, part, dev, params, overrides)
        p = self.params
        self.travel = Travel.of(arm_model, p)
        self.joint_travel = False  #: the travel over the slot was a joint move
        self._offset = grasp_offset(part, dev.gripper.finger_width)
        # Lowest the part's bottom may go: the outer fingertip stays above the machine.
        lowest = self.machine_top_z + p.finger_clearance - part.length + p.grip_depth
        self.drop = max(0.0, lowest - self.slot_floor_z)  #: m above the floor it is let go
        self._bottom_goal = max(self.slot_floor_z - p.overshoot, lowest)
        self._above = self.machine_top_z + p.clear_height  #: m, the part's bottom over the slot
        self._x: NDArray[np.float64] | None = None  #: tool x over the slot, fixed at the start
        self.on_floor = False
        self.reason: str | None = None
        self._open_to: float | None = None  #: m, the let go's opening (None: not begun)
        self._drag_from = Pose()  #: the TCP's pose when the let go began
        #: the insertion's legs, in order: one, unless ``pocket_speed`` is set
        self.legs: list[ContactMove] = []
        #: where the last leg starts: a floor contact may end only that slow leg
        floor_leg = max(self.slot_floor_z, lowest) + p.depth_tolerance + p.slow_margin
        legs = [("into the slot", self._bottom_goal, p.insert_speed)]
        if p.pocket_speed > 0:
            top = self.machine_top_z
            legs = [
                ("down to the pocket's edge", top + p.slow_margin, p.pocket_speed),
                ("into the pocket", top - p.slow_margin, p.insert_speed),
                ("down the pocket", floor_leg, p.pocket_speed),
                *legs,
            ]
        # Each leg ends below the one before (a margin too large for the pocket merges legs;
        # one of no length is left out) and never below the insertion's goal.
        above = self._above
        for k, (name, bottom, speed) in enumerate(legs):
            end = max(min(bottom, above), self._bottom_goal)
            if end < above - SAME_HEIGHT or k == len(legs) - 1:
                self._leg(name, end, speed)
                above = end
        self.insert = self.legs[-1]  #: the last leg, onto the floor at ``insert_speed``
        self.sequence = Sequence(
            "feed slot", [*self._carry_steps(), *self._insert_steps(), *self._let_go_steps()]
        )

    # --- the phases --------------------------------------------------------------------------
    def _carry_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            dev.move("up to the travel height", g, self._up_to_travel),
            dev.move("over the slot", g, self._over_slot),
            dev.move("down to the slot", g, self._down_to_slot),
            *self._hold_still_and_read("hanging part"),
        ]

    def _insert_steps(self) -> list[GuardedMotion]:
        return [
            *(leg.motion for leg in self.legs),
            check("on the slot floor", self.dev, self.params.guard, self._landed),
        ]

    def _let_go_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [dev.grip("let go", g, self._release), *self._way_out_steps()]

    def _way_out_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            dev.move("drag the gripper out", g, self._drag_out),
            *self._settle_and_check(
                "part left in the slot", self._let_go_of_weight, Failure.CHECK_FAILED
            ),
        ]

    #: The last step, the weight check: a stop there is its verdict, not an interruption.
    CHECK_STEP = "part left in the slot"

    @property
    def let_go_started(self) -> bool:
        """The jaws were told to open on the part in the pocket."""
        return self._open_to is not None

    @property
    def finishable(self) -> bool:
        """Stopped after the let go began and before the weight check: the part stands in the
        pocket, the hand is open, and :meth:`leave` does the rest."""
        return self._open_to is not None and self.sequence.current != self.CHECK_STEP

    def leave(self) -> SequenceSkill:
        """The rest of the way out of the slot from wherever this skill stopped after its let
        go began (a force-torque spike or a timeout while dragging out): the jaws opened again
        to the let go's width, the hand up to where the drag ends, the weight check. Why not a
        new feed: the hand is empty and the part stands in the pocket."""
        if not self.finishable:
            raise RuntimeError("leave() outside the way out: the part is still held or checked")
        dev, g = self.dev, self.params.guard
        return StepsSkill(Sequence("leave the slot", [
            dev.grip("open the jaws", g, self._open_fully), *self._way_out_steps(),
        ]))

    # --- where the part goes -----------------------------------------------------------------
    def _x_dir(self) -> NDArray[np.float64]:
        """Tool x over the slot: ``finger_dir``, or the held grasp's when the feed starts."""
        if self._x is None:
            p = self.params
            self._x = horizontal(
                p.finger_dir + (0.0,) if p.finger_dir else self.dev.arm.tool_pose().rotation[:, 0]
            )
        return self._x

    def _pose(self, bottom_z: float) -> Pose:
        p = self.params
        return hold_pose(
            self.slot_xy, bottom_z, self.part, self._x_dir(), self._offset, p.grip_depth,
            p.tip_offset,
        )

    # --- the steps' commands and checks ------------------------------------------------------
    def _travel_target(self) -> Pose:
        return self._pose(max(self._above, self.params.travel_z))

    def _up_to_travel(self) -> None:
        # Straight up first: the part may still be inside the bin, and the travel across may
        # be a joint move, which also goes sideways.
        p = self.params
        rise_to(self.dev.arm, self._travel_target().position[Z], p.travel_speed, p.acceleration)

    def _over_slot(self) -> None:
        self.joint_travel = self.travel.start(self.dev.arm, self._travel_target())

    def _leg(self, name: str, bottom: float, speed: float) -> None:
        """Add an insertion leg down to the part's bottom at ``bottom`` (m). Every leg measures
        contact from the hanging part's reading (before the first leg): read at its own start,
        a leg would take the braking of the leg before, or a contact it pressed, for nothing."""
        p, before = self.params, list(self.legs)
        self.legs.append(ContactMove(
            name, self.dev, p.insert_guard, lambda: self._leg_pose(bottom, before), speed,
            p.acceleration, p.contact_force, reference=lambda: self.reference.force,
        ))

    def _leg_pose(self, bottom: float, before: list[ContactMove]) -> Pose | None:
        """Where an insertion leg ends: the part's bottom at ``bottom``; None (the leg does
        not move) once a leg ``before`` it met something: that contact ended the insertion."""
        if any(leg.contact for leg in before):
            return None
        return self._pose(bottom)

    def _down_to_slot(self) -> None:
        p = self.params
        self.dev.arm.move_to(self._pose(self._above), p.approach_speed, p.acceleration)

    def _landed(self) -> str | None:
        """Where the insertion ended: on the slot floor, or let go within ``max_drop`` of it."""
        p = self.params
        bottom = (
            self.dev.arm.tool_pose().position[Z] - p.tip_offset + p.grip_depth - self.part.length
        )
        above_floor = bottom - self.slot_floor_z
        met = next((leg for leg in self.legs if leg.contact), None)
        if met is not None:
            if met is not self.insert or above_floor > p.depth_tolerance:
                where = "" if met is self.insert else f" in '{met.motion.name}'"
                return (
                    f"the part met resistance {1e3 * above_floor:.1f} mm above the slot "
                    f"floor{where} ({met.resisting:.1f} N): it is on the machine, on the "
                    "pocket's edge or on something in the pocket, not in the slot"
                )
            self.on_floor = True
            return None
        return self._no_floor(above_floor)

    def _no_floor(self, above_floor: float) -> str | None:
        """Arrived without contact ``above_floor`` m over the slot floor: too deep a grasp to
        reach it, or below where the floor should be; else a drop short enough to let go."""
        p = self.params
        if above_floor > p.max_drop:
            return (
                f"the grasp is too deep to reach the slot floor: the part would be let go "
                f"{1e3 * above_floor:.0f} mm above it (max_drop {1e3 * p.max_drop:.0f} mm; "
                f"grip_depth {1e3 * p.grip_depth:.0f} mm)"
            )
        if above_floor < p.depth_tolerance - p.overshoot:
            return (
                f"no slot floor felt {1e3 * -above_floor:.0f} mm below where it should be: "
                f"the grasp is deeper than grip_depth ({1e3 * p.grip_depth:.0f} mm) or "
                "nothing is held"
            )
        return None

    def _release(self) -> None:
        gripper = self.dev.gripper
        self._open_to = gripper.width() + self.params.release
        self._drag_from = self.dev.arm.tool_pose()
        gripper.open(self._open_to)

    def _open_fully(self) -> None:
        """The let go's opening again, to the same width (a no-op for jaws already there)."""
        assert self._open_to is not None
        self.dev.gripper.open(self._open_to)

    def _drag_out(self) -> None:
        # The finger in the hole slides up out of it; the pocket holds the part down. Up from
        # where the let go began, to the same height from wherever a stopped drag left it.
        p = self.params
        top = float(self._drag_from.position[Z]) + p.grip_depth + p.clear_height
        rise_to(self.dev.arm, top, p.approach_speed, p.acceleration)

    def _let_go_of_weight(self) -> str | None:
        if not self._weight_checked():
            return None
        lost = self.reference.lost()
        need = self.params.weight_check * self.part.mass * GRAVITY
        if lost < need:
            return (
                f"the part came out with the gripper: the wrench lost {lost:.2f} N of its "
                f"{self._weight():.2f} N weight"
            )
        return None


# --------------------------------------------------------------------------- PickFromSlot
def pick_finger_dir(slot_xy: ArrayLike, params: SlotParams) -> NDArray[np.float64]:
    """Tool x of the pick from the slot: ``finger_dir``, or towards the robot base."""
    if params.finger_dir:
        return horizontal(params.finger_dir + (0.0,))
    return horizontal(-np.array([*np.asarray(slot_xy, float)[XY], 0.0]))


def slot_view_pose(
    slot_xy: ArrayLike, rim_z: float, x: ArrayLike, camera: Camera, params: SlotParams
) -> Pose:
    """The TCP pose the wrist camera looks at the part standing in the slot from:
    ``view_height`` over its rim (``rim_z``, m), tool x along ``x`` (the pick's). Also where
    the cell brings the arm while the machine runs, so the pick has no way left to go."""
    rotation = hole_grasp_rotation(np.asarray(x, float))
    cam = camera.tool_T_camera().position
    target = np.array([*np.asarray(slot_xy, float)[XY], rim_z + params.view_height])
    return Pose(target - rotation @ cam, rotation)


class PickFromSlot(_SlotSkill):
    """Take the hole grasp on the part standing in the slot and lift it out.

    Before: the gripper is empty, anywhere above the cell's fixtures. After SUCCESS: the part
    hangs in the hole grasp (fingertips ``grip_depth`` below its rim, the outer finger towards
    ``finger_dir``), its bottom ``clear_height`` above the machine's top, over the slot.
    ``seen`` holds what the camera found (None: the slot's centre was assumed).

    Steps: (with the camera) look at the slot and find the rim; over the wall, open, down to the
    rim, read the empty gripper; beside the wall, pinch, check something is held; lift out,
    check the weight came along.
    """

    def __init__(
        self,
        slot_center: ArrayLike,
        part: Part,
        dev: Devices,
        params: SlotParams | None = None,
        **overrides: Any,
    ) -> None:
        """As :class:`FeedSlot` (its travel is the look's, or the caller's: no joint move)."""
        super().__init__(slot_center, part, dev, params, overrides)
        p = self.params
        self._outer, self._inner = pinched_span(part, dev.gripper.finger_width)
        self._offset = grasp_offset(part, dev.gripper.finger_width)
        self._rim_z = self.slot_floor_z + part.length
        self.seen: UprightPart | None = None
        self._pinched_at: Pose | None = None  #: the TCP's pose when the pinch was checked
        self._looking = p.use_camera and dev.camera is not None
        self._x = pick_finger_dir(self.slot_xy, p)
        self._rotation = hole_grasp_rotation(self._x)
        self.sequence = Sequence(
            "pick from slot",
            [
                *(self._look_steps() if self._looking else []),
                *self._approach_steps(),
                *self._grasp_steps(),
                *self._lift_steps(),
            ],
        )

    # --- the phases --------------------------------------------------------------------------
    def _look_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            dev.move("camera over the slot", g, self._view),
            frame_step("find the part in the slot", dev, g, self._locate, self._use_seen,
                       self._not_seen, Failure.NOTHING_FOUND),
        ]

    def _approach_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            dev.move("over the wall", g, self._over_wall),
            dev.grip("open over the wall", g, self._open_over_wall),
            dev.move("down to the rim", g, self._down_to_rim),
            *self._hold_still_and_read("empty gripper"),
        ]

    def _grasp_steps(self) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        return [
            dev.move("beside the wall", p.descent_guard, self._beside_wall),
            dev.grip("pinch the wall", g, lambda: dev.gripper.close(p.hold_force),
                     settle=p.pinch_settle),
            check("holding the part", dev, g, self._pinched, Failure.MISSED),
        ]

    def _lift_steps(self) -> list[GuardedMotion]:
        p = self.params
        return [
            self.dev.move("lift out of the slot", p.insert_guard, self._lift_out),
            *self._settle_and_check("part in the hand", self._weight_felt, Failure.MISSED),
        ]

    # --- where the grasp is ------------------------------------------------------------------
    def _axis_xy(self) -> NDArray[np.float64]:
        return self.seen.center if self.seen is not None else self.slot_xy

    def _tcp(self, tips_z: float) -> Pose:
        position = np.array(
            [*(self._axis_xy() + self._offset * self._x[XY]), tips_z + self.params.tip_offset]
        )
        return Pose(position, self._rotation)

    # --- the steps' commands and checks ------------------------------------------------------
    def _view(self) -> None:
        assert self.dev.camera is not None
        pose = slot_view_pose(self.slot_xy, self._rim_z, self._x, self.dev.camera, self.params)
        arm, p = self.dev.arm, self.params
        arm.move_path(
            travel_path(arm.tool_pose(), pose, p.min_radius), p.travel_speed, p.acceleration
        )

    def _locate(self, frame: Frame, world_T_camera: Pose) -> UprightPart | None:
        camera = self.dev.camera
        assert camera is not None
        return locate_upright_part(
            frame, camera.intrinsics(), world_T_camera, self.part, self.slot_xy,
            self.slot_floor_z, search=self.params.view_search,
        )

    def _use_seen(self, seen: UprightPart | None) -> None:
        self.seen = seen

    def _not_seen(self) -> str | None:
        return "no part seen standing in the slot" if self.seen is None else None

    def _over_wall(self) -> None:
        arm, p = self.dev.arm, self.params
        target = self._tcp(max(self._rim_z + p.clear_height, p.travel_z))
        if self._looking:
            arm.move_to(target, p.travel_speed, p.acceleration)
        else:
            arm.move_path(
                travel_path(arm.tool_pose(), target, p.min_radius), p.travel_speed, p.acceleration
            )

    def _open_over_wall(self) -> None:
        gaps = 2.0 * self.params.wall_gap  # exact: a wall gap on each side of the wall
        self.dev.gripper.open(self._outer - self._inner + gaps)

    def _down_to_rim(self) -> None:
        p = self.params
        self.dev.arm.move_to(self._tcp(self._rim_z + p.clear_height), p.approach_speed,
                             p.acceleration)

    def _beside_wall(self) -> None:
        p = self.params
        depth = min(p.grip_depth, self._rim_z - self.machine_top_z - p.finger_clearance)
        self.dev.arm.move_to(self._tcp(self._rim_z - depth),
                             p.beside_wall_speed_factor * p.approach_speed, p.acceleration)

    def _pinched(self) -> str | None:
        if not self.dev.gripper.object_detected():
            return "the hole grasp closed on nothing"
        self._pinched_at = self.dev.arm.tool_pose()
        return None

    def _lift_out(self) -> None:
        # Up from where the pinch was checked, to the same height from wherever a stopped lift
        # left it.
        p = self.params
        assert self._pinched_at is not None
        rise = (self.machine_top_z + p.clear_height) - self.slot_floor_z
        top = float(self._pinched_at.position[Z]) + rise
        rise_to(self.dev.arm, top, p.approach_speed, p.acceleration)

    #: The last step, the weight check: a stop there is its verdict, not an interruption.
    CHECK_STEP = "part in the hand"

    @property
    def finishable(self) -> bool:
        """Stopped after the pinch was checked and before the weight check: the part is in the
        hand, on its way out of the slot, and :meth:`finish` does the rest."""
        return self._pinched_at is not None and self.sequence.current != self.CHECK_STEP

    def finish(self) -> SequenceSkill:
        """The rest of the pick from wherever this skill stopped after its pinch was checked
        (a force-torque spike or a timeout while lifting out): up to where the lift ends, the
        weight check. Why not a new pick: the part is in the hand, half out of the slot; a new
        pick would start by opening over the wall."""
        if not self.finishable:
            raise RuntimeError("finish() outside the lift: nothing is held, or it was checked")
        return StepsSkill(Sequence("lift from slot", self._lift_steps()))

    def _weight_felt(self) -> str | None:
        if not self._weight_checked():
            return None
        gained = self.reference.gained()
        if gained < self.params.weight_check * self.part.mass * GRAVITY:
            return (
                f"the part stayed behind: the wrench gained {gained:.2f} N of its "
                f"{self._weight():.2f} N weight"
            )
        return None
