"""Feeding a part held in the hole grasp into the machine's slot, and picking it out again.

The application of Sec. IV-C of the paper (Fig. 16): the slot is a square pocket only 5 mm wider
than the part (2.5 mm a side), so a finger on the part's outer wall cannot enter it; in the hole
grasp the outer finger stays above the machine while the part and the finger inside its hole go
in. :class:`FeedSlot`:

1. lift to the travel height and carry the part over the slot (the slot's place comes from the
   cell's configuration, never from the simulator), fingers down, so the part's axis is over the
   pocket's centre;
2. hold still and read the wrench with the part hanging (the reference for contact and weight);
3. lower the part into the pocket slowly until the slot floor pushes back (the force along the
   motion rises by ``contact_force`` over the reference), or until the outer finger would come
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

from drivers.arm import MotionState
from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.motion import Failed, Guard, GuardedMotion, Sequence, arm_failure, wait
from skills.params import guard_field, si
from skills.perception import UprightPart, locate_upright_part
from skills.pivot.align import hole_grasp_rotation, pinched_span
from skills.status import Failure, StepResult

GRAVITY = 9.81  #: m/s^2


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
    slot_depth: float = si(
        0.040, "m", 0.005, 0.3, "the pocket's depth: the machine's top above its floor"
    )
    tip_offset: float = si(0.005, "m", 0.0, 0.05, "from the TCP to the fingertips along tool z")
    #: Direction (x, y) of tool x -- the outer finger's side of the part -- over the slot;
    #: None keeps the held grasp's (FeedSlot) or points it at the robot base (PickFromSlot).
    finger_dir: tuple[float, float] | None = None
    clear_height: float = si(
        0.02, "m", 0.0, 0.2, "between the part (or fingertips) and the machine's top"
    )
    travel_z: float = si(
        0.13, "m", 0.0, 0.5, "the lowest the part's bottom (or the fingertips) travels at"
    )
    min_radius: float = si(0.30, "m", 0.0, 0.8, "from the base axis a travel path keeps")
    travel_speed: float = si(0.15, "m/s", 0.01, 1.0, "of the TCP travelling")
    approach_speed: float = si(0.05, "m/s", 0.001, 0.5, "of the TCP approaching")
    insert_speed: float = si(0.01, "m/s", 0.001, 0.1, "into the pocket and onto its floor")
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
    hold_force: float = si(15.0, "N", 1.0, 100.0, "per finger of the hole grasp (pick)")
    view_height: float = si(
        0.20, "m", 0.05, 1.0, "of the camera above the rim when looking (pick)"
    )
    view_search: float = si(0.03, "m", 0.0, 0.2, "the part may stand off the slot's centre")
    use_camera: bool = True  #: PickFromSlot finds the rim with the camera (if there is one)
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
    return 0.5 * (outer + inner)


def horizontal(v: ArrayLike) -> NDArray[np.float64]:
    """Unit vector of the horizontal part of ``v`` (x, y, 0)."""
    a = np.asarray(v, float)
    h = np.array([a[0], a[1], 0.0])
    n = float(np.linalg.norm(h))
    if n < 1e-9:
        raise ValueError(f"direction {a!r} has no horizontal part")
    return h / n


def hold_pose(
    axis_xy: ArrayLike, bottom_z: float, part: Part, x_dir: ArrayLike, offset: float,
    grip_depth: float, tip_offset: float,
) -> Pose:
    """TCP pose that holds ``part`` in the hole grasp with its axis at ``axis_xy`` and its bottom
    at ``bottom_z`` (m), the outer finger towards ``x_dir``."""
    x = horizontal(x_dir)
    xy = np.asarray(axis_xy, float)[:2]
    z = bottom_z + part.length - grip_depth + tip_offset
    return Pose(np.array([*(xy + offset * x[:2]), z]), hole_grasp_rotation(x))


def travel_path(start: Pose, target: Pose, min_radius: float) -> list[Pose]:
    """Waypoints from ``start`` to ``target``: up (or down) to the target's height first, then
    across; when the straight line across would pass within ``min_radius`` (m) of the base axis
    (where a UR5's wrist cannot follow a Cartesian line), through a point on an arc around it."""
    up = Pose(np.array([*start.position[:2], target.position[2]]), start.rotation)
    a, b = up.position[:2], target.position[:2]
    d = b - a
    s = float(np.clip(-(a @ d) / max(float(d @ d), 1e-12), 0.0, 1.0))
    closest = float(np.linalg.norm(a + s * d))
    points = [up]
    if closest < min_radius:
        ang_a, ang_b = math.atan2(a[1], a[0]), math.atan2(b[1], b[0])
        turn = (ang_b - ang_a + math.pi) % (2.0 * math.pi) - math.pi
        radius = max(min_radius, float(np.linalg.norm(a)), float(np.linalg.norm(b)))
        steps = max(1, int(abs(turn) // math.radians(40.0)))
        for k in range(1, steps + 1):
            frac = k / (steps + 1)
            ang = ang_a + turn * frac
            pos = np.array([radius * math.cos(ang), radius * math.sin(ang), target.position[2]])
            points.append(Pose(pos, up.interpolate(target, frac).rotation))
    points.append(target)
    if up.distance(start)[0] < 1e-4:
        points = points[1:]
    return points


def world_force(dev: Devices) -> NDArray[np.float64]:
    """The force (N) the environment applies to the tool, in the base frame."""
    return dev.arm.tool_pose().rotation @ np.asarray(dev.ft.wrench()[:3], float)


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
        target: Callable[[], Pose],
        speed: float,
        acceleration: float,
        threshold: float,
    ) -> None:
        self.dev, self._target, self.threshold = dev, target, threshold
        self._speed, self._acc = speed, acceleration
        self.contact = False
        self.contact_pose: Pose | None = None
        self.resisting = 0.0  #: N, the newest force against the motion (above the reference)
        self._ref = np.zeros(3)
        self._dir = np.zeros(3)
        self.motion = GuardedMotion(
            name, self._start, self._finished, dev.arm, dev.ft, dev.clock, guard, self._failed
        )

    def _start(self) -> None:
        target = self._target()
        start = self.dev.arm.tool_pose().position
        d = target.position - start
        self._dir = d / max(float(np.linalg.norm(d)), 1e-9)
        self._ref = world_force(self.dev)
        self.contact, self.contact_pose = False, None
        self.dev.arm.move_to(target, self._speed, self._acc)

    def _finished(self) -> bool:
        self.resisting = -float((world_force(self.dev) - self._ref) @ self._dir)
        if self.resisting > self.threshold:
            self.dev.arm.stop()
            self.contact, self.contact_pose = True, self.dev.arm.tool_pose()
            return True
        return self.dev.arm.status().state is MotionState.DONE

    def _failed(self) -> Failed | None:
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
        s = self.sequence
        return s.steps[s.index].name if s.index < len(s.steps) else "done"


# ------------------------------------------------------------------------------ FeedSlot
class FeedSlot(SequenceSkill):
    """Put the part held in the hole grasp into the slot, let go, drag the gripper out.

    Before: the part hangs in the hole grasp (Align's, or :class:`PickFromSlot`'s), fingers down,
    ``params.grip_depth`` below its rim. After SUCCESS: the part stands in the pocket, the jaws
    are open by ``release`` more than they held it, the fingertips are ``clear_height`` above the
    machine's top, over the slot. ``on_floor`` says whether the floor was felt (else the part was
    let go ``drop`` metres above it).
    """

    def __init__(
        self,
        slot_center: ArrayLike,
        part: Part,
        dev: Devices,
        params: SlotParams | None = None,
        **overrides: Any,
    ) -> None:
        """``slot_center``: (x, y, z) of the centre of the pocket's floor (m, base frame);
        ``overrides``: fields of :class:`SlotParams` to change (``grip_depth=0.02``)."""
        p = replace(params or SlotParams(), **overrides)
        self.part, self.dev, self.params = part, dev, p
        slot = np.asarray(slot_center, float)
        self.slot_xy, self.slot_floor_z = slot[:2].copy(), float(slot[2])
        self.machine_top_z = self.slot_floor_z + p.slot_depth
        offset = grasp_offset(part, dev.gripper.finger_width)
        arm, g = dev.arm, p.guard
        # Lowest the part's bottom may go: the outer fingertip stays above the machine.
        lowest = self.machine_top_z + p.finger_clearance - part.length + p.grip_depth
        self.drop = max(0.0, lowest - self.slot_floor_z)  #: m above the floor it is let go
        bottom_goal = max(self.slot_floor_z - p.overshoot, lowest)
        st: dict[str, object] = {}
        self.on_floor = False
        self.reason: str | None = None

        def x_dir() -> NDArray[np.float64]:
            if "x" not in st:
                st["x"] = horizontal(
                    p.finger_dir + (0.0,) if p.finger_dir else arm.tool_pose().rotation[:, 0]
                )
            return st["x"]  # type: ignore[return-value]

        def pose(bottom_z: float) -> Pose:
            return hold_pose(self.slot_xy, bottom_z, part, x_dir(), offset, p.grip_depth,
                             p.tip_offset)

        above = self.machine_top_z + p.clear_height

        def over_slot() -> None:
            target = pose(max(above, p.travel_z))
            arm.move_path(travel_path(arm.tool_pose(), target, p.min_radius), p.travel_speed,
                          p.acceleration)

        def down_to_slot() -> None:
            arm.move_to(pose(above), p.approach_speed, p.acceleration)

        def reference() -> str | None:
            st["held"] = world_force(dev)
            return None

        self.insert = ContactMove(
            "into the slot", dev, p.insert_guard, lambda: pose(bottom_goal), p.insert_speed,
            p.acceleration, p.contact_force,
        )

        def landed() -> str | None:
            bottom = arm.tool_pose().position[2] - p.tip_offset + p.grip_depth - part.length
            above_floor = bottom - self.slot_floor_z
            if self.insert.contact:
                if above_floor > p.depth_tolerance:
                    return (
                        f"the part met resistance {1e3 * above_floor:.1f} mm above the slot "
                        f"floor ({self.insert.resisting:.1f} N): it is on the machine or the "
                        "pocket's edge, not in the slot"
                    )
                self.on_floor = True
                return None
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

        def release() -> None:
            dev.gripper.open(dev.gripper.width() + p.release)

        def drag_out() -> None:
            # The finger in the hole slides up out of it; the pocket holds the part down.
            tool = arm.tool_pose()
            rise = p.grip_depth + p.clear_height
            target = Pose(tool.position + np.array([0.0, 0.0, rise]), tool.rotation)
            arm.move_to(target, p.approach_speed, p.acceleration)

        def let_go_of_weight() -> str | None:
            if p.weight_check <= 0 or "held" not in st:
                return None
            lost = float(world_force(dev)[2] - st["held"][2])  # type: ignore[index]
            need = p.weight_check * part.mass * GRAVITY
            if lost < need:
                return (
                    f"the part came out with the gripper: the wrench lost {lost:.2f} N of its "
                    f"{part.mass * GRAVITY:.2f} N weight"
                )
            return None

        self.sequence = Sequence(
            "feed slot",
            [
                dev.move("over the slot", g, over_slot),
                dev.move("down to the slot", g, down_to_slot),
                wait("hold still", dev, g, p.settle),
                check("read the hanging part", dev, g, reference),
                self.insert.motion,
                check("on the slot floor", dev, g, landed),
                dev.grip("let go", g, release),
                dev.move("drag the gripper out", g, drag_out),
                wait("settle", dev, g, p.settle),
                check("part left in the slot", dev, g, let_go_of_weight),
            ],
        )


# --------------------------------------------------------------------------- PickFromSlot
class PickFromSlot(SequenceSkill):
    """Take the hole grasp on the part standing in the slot and lift it out.

    Before: the gripper is empty, anywhere above the cell's fixtures. After SUCCESS: the part
    hangs in the hole grasp (fingertips ``grip_depth`` below its rim, the outer finger towards
    ``finger_dir``), its bottom ``clear_height`` above the machine's top, over the slot.
    ``seen`` holds what the camera found (None: the slot's centre was assumed).
    """

    def __init__(
        self,
        slot_center: ArrayLike,
        part: Part,
        dev: Devices,
        params: SlotParams | None = None,
        **overrides: Any,
    ) -> None:
        """As :class:`FeedSlot`."""
        p = replace(params or SlotParams(), **overrides)
        self.part, self.dev, self.params = part, dev, p
        slot = np.asarray(slot_center, float)
        self.slot_xy, self.slot_floor_z = slot[:2].copy(), float(slot[2])
        self.machine_top_z = self.slot_floor_z + p.slot_depth
        arm, gripper, camera, g = dev.arm, dev.gripper, dev.camera, p.guard
        outer, inner = pinched_span(part, gripper.finger_width)
        offset = 0.5 * (outer + inner)
        rim_z = self.slot_floor_z + part.length
        self.seen: UprightPart | None = None
        st: dict[str, object] = {}
        looking = p.use_camera and camera is not None

        x = horizontal(p.finger_dir + (0.0,) if p.finger_dir else -np.array([*self.slot_xy, 0]))
        rotation = hole_grasp_rotation(x)

        def axis_xy() -> NDArray[np.float64]:
            return self.seen.center if self.seen is not None else self.slot_xy

        def tcp(tips_z: float) -> Pose:
            return Pose(np.array([*(axis_xy() + offset * x[:2]), tips_z + p.tip_offset]),
                        rotation)

        def view() -> None:
            if not looking:
                return
            assert camera is not None
            cam = camera.tool_T_camera().position
            target = np.array([*self.slot_xy, rim_z + p.view_height]) - rotation @ cam
            pose = Pose(target, rotation)
            arm.move_path(travel_path(arm.tool_pose(), pose, p.min_radius), p.travel_speed,
                          p.acceleration)

        def look() -> str | None:
            if not looking:
                return None
            assert camera is not None
            frame = camera.capture()
            world_T_camera = arm.tool_pose() @ camera.tool_T_camera()
            self.seen = locate_upright_part(
                frame, camera.intrinsics(), world_T_camera, part, self.slot_xy,
                self.slot_floor_z, search=p.view_search,
            )
            if self.seen is None:
                return "no part seen standing in the slot"
            return None

        def over_wall() -> None:
            target = tcp(max(rim_z + p.clear_height, p.travel_z))
            if looking:
                arm.move_to(target, p.travel_speed, p.acceleration)
            else:
                arm.move_path(travel_path(arm.tool_pose(), target, p.min_radius),
                              p.travel_speed, p.acceleration)

        def reference() -> str | None:
            st["empty"] = world_force(dev)
            return None

        def open_over_wall() -> None:
            gripper.open(outer - inner + 2.0 * p.wall_gap)

        def down_to_rim() -> None:
            arm.move_to(tcp(rim_z + p.clear_height), p.approach_speed, p.acceleration)

        def beside_wall() -> None:
            depth = min(p.grip_depth, rim_z - self.machine_top_z - p.finger_clearance)
            arm.move_to(tcp(rim_z - depth), 0.5 * p.approach_speed, p.acceleration)

        def pinched() -> str | None:
            if not gripper.object_detected():
                return "the hole grasp closed on nothing"
            return None

        def lift_out() -> None:
            tool = arm.tool_pose()
            rise = (self.machine_top_z + p.clear_height) - self.slot_floor_z
            target = Pose(tool.position + np.array([0.0, 0.0, rise]), tool.rotation)
            arm.move_to(target, p.approach_speed, p.acceleration)

        def weight_felt() -> str | None:
            if p.weight_check <= 0 or "empty" not in st:
                return None
            gained = float(st["empty"][2] - world_force(dev)[2])  # type: ignore[index]
            if gained < p.weight_check * part.mass * GRAVITY:
                return (
                    f"the part stayed behind: the wrench gained {gained:.2f} N of its "
                    f"{part.mass * GRAVITY:.2f} N weight"
                )
            return None

        seeing = [
            dev.move("camera over the slot", g, view),
            check("find the part in the slot", dev, g, look, Failure.NOTHING_FOUND),
        ]
        self.sequence = Sequence(
            "pick from slot",
            [
                *(seeing if looking else []),
                dev.move("over the wall", g, over_wall),
                dev.grip("open over the wall", g, open_over_wall),
                dev.move("down to the rim", g, down_to_rim),
                wait("hold still", dev, g, p.settle),
                check("read the empty gripper", dev, g, reference),
                dev.move("beside the wall", p.descent_guard, beside_wall),
                dev.grip("pinch the wall", g, lambda: gripper.close(p.hold_force), settle=0.3),
                check("holding the part", dev, g, pinched, Failure.MISSED),
                dev.move("lift out of the slot", p.insert_guard, lift_out),
                wait("settle", dev, g, p.settle),
                check("part in the hand", dev, g, weight_felt, Failure.MISSED),
            ],
        )
