"""Packing a part held in the hole grasp upright into a box, tight against walls and neighbours.

The application of Sec. IV-C of the paper (Fig. 15): a hybrid force-position push. The part is
set down a few millimetres short of its place towards ``-x, -y``, then pushed ``-z`` until the
box floor pushes back, ``+x`` until a wall or a packed neighbour does, ``+y`` likewise, let go and
the gripper withdrawn up (a last short ``+x`` push closes the millimetre the part was eased back
before the ``+y`` push, see ``back_off``). Each push runs in the arm's force mode
(:class:`~skills.force.ForcePush`, ``forceMode`` on a UR): ``contact_force`` along the push,
position held on the other axes, until the TCP stands still pressing -- the measured contact,
wherever it is. The force is added to the wrench read as the push begins (the held part's weight
and the sensor's offset), so only the reaction of the floor, a wall or a neighbour ends a push.

Why the hole grasp helps: the finger in the hole and the one on the wall hold the part from one
side only, so no finger sits between the part and the things it is pushed against; the gripper
is turned so the outer finger is on the *trailing* side (``-x, -y`` diagonal), where nothing has
been packed yet, and both pushes go through it (it pushes the part's wall ahead of it).

Packing order (:func:`tray_places`): the first part into the ``+x, +y`` corner, then along the
``+y`` wall towards ``-x``, then the next row: each new part is pushed into a corner made of
walls and parts already packed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.axes import XY, Z
from skills.force import ForcePush
from skills.motion import Guard, GuardedMotion, Sequence, Settled, wait
from skills.params import guard_field, si
from skills.slot import (
    GRAVITY,
    JOINT_TRAVEL_ACCELERATION,
    JOINT_TRAVEL_SPEED,
    JOINT_TRAVEL_TCP_SPEED,
    ContactMove,
    SequenceSkill,
    StepsSkill,
    Travel,
    WrenchReference,
    check,
    grasp_offset,
    hold_pose,
    horizontal,
    rise_to,
)
from skills.status import Failure
from skills.travel import ArmModel


@dataclass(frozen=True)
class PackParams:
    """Parameters of :class:`PackInBox` (SI units); the fields declared with
    :func:`~skills.params.si` are the ``skills.pack_in_box`` section of a cell's configuration."""

    #: m the fingertips reach below the rim in the hole grasp (in the cell: the slot's
    #: ``grip_depth``, the grasp every station shares, so not a key of its own)
    grip_depth: float = 0.020
    tip_offset: float = 0.005  #: m from the TCP to the fingertips along the tool z axis (gripper)
    #: Direction (x, y) of the outer finger from the part: the trailing side of both pushes.
    trail_dir: tuple[float, float] = (-1.0, -1.0)
    offset: float = si(
        0.004, "m", 0.0, 0.03, "the part is set down short of its place along -x and -y"
    )
    push_range: float = si(
        0.012, "m", 0.001, 0.1, "beyond the place a push may go before nothing to push on"
    )
    clear_height: float = si(0.02, "m", 0.0, 0.2, "above the highest thing in the box")
    travel_z: float = si(
        0.13, "m", 0.0, 0.5,
        "the lowest the part's bottom travels at; it must clear every fixture the arm travels "
        "over (a joint move sweeps an arc about the base, off the straight line)",
    )
    min_radius: float = si(0.30, "m", 0.0, 0.8, "from the base axis a travel path keeps")
    travel_speed: float = si(0.15, "m/s", 0.01, 1.0, "of the TCP travelling")
    joint_speed: float = si(*JOINT_TRAVEL_SPEED)
    joint_acceleration: float = si(*JOINT_TRAVEL_ACCELERATION)
    joint_tcp_speed: float = si(*JOINT_TRAVEL_TCP_SPEED)
    approach_speed: float = si(0.05, "m/s", 0.001, 0.5, "of the TCP approaching")
    push_speed: float = si(0.01, "m/s", 0.001, 0.1, "of every push")
    acceleration: float = si(0.3, "m/s^2", 0.01, 3.0, "of the TCP")
    settle: float = si(0.2, "s", 0.0, 5.0, "held still before a reference wrench is read")
    floor_gap: float = si(0.005, "m", 0.0, 0.05, "above the floor where the fast descent ends")
    #: 3 N, not 6: the held part hangs 0.5 mm above the floor (``lift_off``, unless
    #: ``floor_press`` presses it down), so a push needs little force to move it, only one the
    #: wrist feels far above its noise (the FT300's is about 0.1 N); every newton more is
    #: pressed into packed parts that the floor holds by their weight's friction alone (the
    #: bushing's: under 1 N), and a contact off their centre line turns sideways. At 6 N the
    #: twin moved packed bushings up to 1.8 mm a push.
    contact_force: float = si(
        3.0, "N", 0.5, 50.0,
        "each push presses with in force mode",
    )
    #: 6 N, the pushes' force before they came down to 3 N: the descent runs at the approach
    #: speed, where the held part's swing and the arm's braking read 3.3 N against the motion
    #: 113 mm above the floor (the twin, seed 64003) and a descent stopped on nothing
    descent_force: float = si(
        6.0, "N", 0.5, 50.0, "against the fast descent into the box that counts as contact"
    )
    contact_settle: float = si(
        0.15, "s", 0.0, 2.0, "a push stands still, pressing, before that counts as contact"
    )
    still_speed: float = si(
        0.002, "m/s", 0.0001, 0.05, "slower than this along a push is standing still"
    )
    overshoot: float = si(
        0.004, "m", 0.0, 0.02, "the -z push aims below the floor (contact stops it)"
    )
    lift_off: float = si(
        0.0005, "m", 0.0, 0.005,
        "back up after the floor contact, so the part slides freely",
    )
    #: The sideways pushes give way along z and press the held part onto the box floor with
    #: this force. Hanging ``lift_off`` above the floor, the held part touched its neighbour near
    #: the neighbour's top, and the arm drifting up 0.3 mm in the push rubbed that wall upwards:
    #: the neighbour, held up by the friction of the parts either side, lost the box floor, and
    #: the contact's slight slope slid it 2.35 mm off the +y wall (the twin, seed 64303's third
    #: packing). Pressed down (1 N), the held part cannot rise along its neighbour: that seed
    #: packed 10 of 10 instead of 4. Off by default: over the tipped bin's ten seeds it packed
    #: 90 of 100, and the two seeds it lost most on (20501, 20504: a shove it did not stop, and
    #: 2.1 mm gaps between rows) packed 10 of 10 each without it (docs/random_bin.md).
    floor_press: float = si(
        0.0, "N", 0.0, 20.0,
        "the held part presses the box floor with during the sideways pushes (0: z held)",
    )
    #: back after the +x contact, so the +y push does not rub along the +x neighbour (pressed
    #: together, two parts sliding past each other stopped the push short)
    back_off: float = si(0.001, "m", 0.0, 0.01, "back after the +x contact")
    #: the last +x push closes ``back_off`` and may go this much further before it counts as
    #: nothing felt: room for the part not sitting exactly ``back_off`` off its +x contact
    #: after the +y push (it slid along the +y wall or the neighbour gave a little)
    push_again_margin: float = si(
        0.002, "m", 0.0, 0.01, "the last +x push may go beyond the back_off it closes"
    )
    lean_force: float = si(
        1.0, "N", 0.0, 20.0,
        "pressed +y during the +x pushes: the part slides along the wall or the row before it",
    )
    release: float = si(0.006, "m", 0.0, 0.03, "the jaws open to let go")
    release_clearance: float = si(
        0.001, "m", 0.0, 0.01,
        "the finger in the hole moves off the wall once the jaws are open, before withdrawing",
    )
    #: 0: the jaws open symmetrically and the arm stands still, so the two pads leave the wall
    #: alike and neither is moved against it. At 0.35 (the arm following the outer finger out)
    #: seed 64301's eighth let go slid the packed bushing 4.3-4.8 mm off its neighbour, and the
    #: row failed the judge from there on; at 0, seeds 64301-64303 packed 30 of 30 and no let go
    #: moved its part more than 1.2 mm. The usual drift, 0.2-0.6 mm as the pinch's 20 N comes
    #: off in one or two ticks, is the same either way. At 0.5 (the inner finger meant to stay)
    #: an arm a little ahead of the jaws pressed the inner pad's tip into the wall (seed 62401):
    #: where the arm follows, it follows the opening the gripper *reports*, so it can lag the
    #: jaws but never lead them.
    release_follow: float = si(
        0.0, "1", 0.0, 1.0,
        "share of the opening the arm follows the outer finger out by (0: both pads leave the "
        "wall together; 0.5: the inner one would stay on it)",
    )
    release_speed: float = si(
        0.02, "m/s", 0.001, 0.15,
        "each finger's while letting go",
    )
    weight_check: float = si(
        0.5, "1", 0.0, 1.0, "fraction of the part's weight the wrench must lose; 0: no check"
    )
    #: The way up gives way in the plane only while a fingertip can touch the part: in force
    #: mode the open hand rises at the speed its small press gives (the twin's admittance:
    #: 15 mm/s at 3 N), and the whole 40 mm took 2.7 s of each packing. Above the rim by this
    #: much, the rest of the way up is a position move.
    rim_margin: float = si(
        0.003, "m", 0.0, 0.05,
        "the open fingertips rise this far above the part's rim, giving way, before the rest "
        "of the way up is a position move",
    )
    #: A part that came up with the open hand hangs on the finger in its hole (the twin: the
    #: inner pad wedged, the part lifted 10 mm with it; seed 20502's first packing): closing
    #: the jaws takes it in the hole grasp again, and the tree's retry packs it once more
    #: instead of stopping the cell with a part dangling from one finger.
    regrip_force: float = si(
        20.0, "N", 0.1, 235.0,
        "per finger, taking a part that came up with the open hand in the hole grasp again",
        actuator="grip_force",
    )
    guard: Guard = field(default_factory=Guard)
    push_guard: Guard = guard_field(30.0, 15.0, "every push and the descent into the box")


class PackInBox(SequenceSkill):
    """Put the part held in the hole grasp into its place in the box by pushing.

    Before: the part hangs in the hole grasp (fingertips ``grip_depth`` below its rim), anywhere
    the arm can travel from. After SUCCESS: the part stands on the box floor, pushed against
    whatever is on its ``+x`` and ``+y`` sides; the jaws are open; the fingertips are
    ``clear_height`` above its rim. ``contacts`` holds the TCP pose at each contact (``floor``,
    ``+x``, ``+y``) and ``placed_xy`` where the part's axis ended (m, from the arm's pose).

    Steps: over the place, read the hanging part; down into the box and onto its floor; push
    ``+x``, ``+y`` and ``+x`` again; let go (the jaws open about a still arm by default), move the
    open hand off the wall, withdraw up (giving way until the fingertips are out of the hole, then a
    position move), check the weight stayed in the box; a part that came up with the hand is
    gripped again and the step fails, so a retry can pack it once more.
    """

    def __init__(
        self,
        place: ArrayLike,
        part: Part,
        dev: Devices,
        params: PackParams | None = None,
        top_z: float | None = None,
        arm_model: ArmModel | None = None,
        **overrides: Any,
    ) -> None:
        """``place``: (x, y, z) of the part's bottom centre in the box (m; z the box floor), as
        :func:`tray_places` gives. ``top_z``: height (m) of the highest thing in or around the
        box (default: the top of a packed part). ``arm_model``: the arm's kinematics, for
        travelling by a joint move (None: straight travel paths only). ``overrides``: fields of
        :class:`PackParams`."""
        p = replace(params or PackParams(), **overrides)
        self.part, self.dev, self.params = part, dev, p
        self.travel = Travel.of(arm_model, p)
        self.joint_travel = False  #: the travel over the place was a joint move
        target = np.asarray(place, float)
        self.place_xy, self.floor_z = target[XY].copy(), float(target[Z])
        self._top = self.floor_z + part.length if top_z is None else float(top_z)
        self._offset = grasp_offset(part, dev.gripper.finger_width)
        self._x = horizontal((*p.trail_dir, 0.0))  #: tool x: the outer finger's side
        self._start_xy = self.place_xy - p.offset
        self._reach = p.offset + p.push_range  #: m a push may go before nothing is felt
        self.contacts: dict[str, Pose] = {}
        self.placed_xy: NDArray[np.float64] | None = None
        self.reference = WrenchReference(dev)
        self._jaws_still = Settled(dev.gripper, dev.clock, p.settle)  #: the let go's end
        self._open_from = 0.0  #: m, the jaws' reported opening when the let go began
        self._let_go_from = Pose()  #: the TCP's pose when the let go began
        self._let_go_started = False
        self._off_wall_xy: NDArray[np.float64] | None = None  #: m, where "off the wall" goes
        self._leaves: list[Sequence] = []  #: the sequences :meth:`leave` handed out
        self._came_up: str | None = None  #: why the weight check failed (None: it passed)
        self._closing_seen = False  #: the jaws were seen moving since the re-grip began
        self._make_contact_moves()
        self.sequence = Sequence(
            "pack in box",
            [
                *self._over_place_steps(),
                *self._onto_floor_steps(),
                *self._push_steps(),
                *self._let_go_steps(),
            ],
        )

    def _make_contact_moves(self) -> None:
        """The fast guarded descent into the box, then the force-mode pushes: -z onto the floor,
        +x, +y and +x again, each pressing ``contact_force`` until it stands on a contact."""
        p, dev = self.params, self.dev
        self.descend = ContactMove(
            "down into the box", dev, p.push_guard,
            lambda: self._pose(self.floor_z + p.floor_gap), p.approach_speed, p.acceleration,
            p.descent_force,
        )

        def push(
            name: str, direction: tuple[float, float, float], reach: float,
            free: tuple[int, ...] = (), lean: tuple[float, float, float] = (0.0, 0.0, 0.0),
            reference: Callable[[], NDArray[np.float64] | None] | None = None,
        ) -> ForcePush:
            return ForcePush(
                name, dev, p.push_guard, direction, p.contact_force, p.push_speed, reach,
                settle=p.contact_settle, still_speed=p.still_speed, free=free, lean=lean,
                reference=reference,
            )

        def sideways(
            name: str, direction: tuple[float, float, float], reach: float,
            free: tuple[int, ...] = (), lean: tuple[float, float, float] = (0.0, 0.0, 0.0),
        ) -> ForcePush:
            """A push in the floor's plane, pressing the part onto the floor (``floor_press``).
            Its nothing-pressed is the hanging part's reading: read at the push's start, it
            would hold the press of the push before as nothing and press again on top."""
            if p.floor_press <= 0:
                return push(name, direction, reach, free, lean)
            return push(name, direction, reach, (*free, Z), (lean[0], lean[1], -p.floor_press),
                        lambda: self.reference.force)

        lean_y = (0.0, p.lean_force, 0.0)

        self.floor = push("push -z onto the floor", (0.0, 0.0, -1.0), p.floor_gap + p.overshoot)
        # The +x pushes give way along y and lean +y with ``lean_force``. Held in y, the part
        # (set down ``offset`` short along -y too) met its round neighbour below the centre line
        # and shoved the row off the +y wall (the twin measured 3.5 mm); free but not leaning,
        # it still met it below the line and the row buckled 2-4 mm off the wall; leaning, it
        # slides up to the wall (or the row before it) on the way and meets the neighbour on
        # their centre line.
        self.push_x = sideways("push +x", (1.0, 0.0, 0.0), self._reach, (1,), lean_y)
        self.push_y = sideways("push +y", (0.0, 1.0, 0.0), self._reach)
        #: Closes the ``back_off`` again: a short +x push once the part sits home on +y.
        self.push_x_again = sideways(
            "push +x again", (1.0, 0.0, 0.0), p.back_off + p.push_again_margin, (1,), lean_y
        )
        # The open hand comes up in force mode until its fingertips are above the part's rim,
        # giving way in the plane to anything it touches, with nothing pressed beyond the empty
        # hand's reading (:meth:`_empty_hand`); the rest of the way up is a position move.
        # A position move up dragged the part sideways by the finger still touching the hole's
        # wall: a flat pad in a round (or 12-sided) hole touches it with a corner once the part
        # has turned a little in the grasp, and the twin measured 22-25 N on that corner and a
        # whole packed row dragged 6 mm off its wall. Giving way, the corner slides off the wall.
        self.withdraw = self._withdraw_move()

    def _withdraw_move(self) -> ForcePush:
        p = self.params
        return ForcePush(
            "withdraw up", self.dev, p.guard, (0.0, 0.0, 1.0), p.contact_force, p.approach_speed,
            lambda: self._tip_depth() + min(p.rim_margin, p.clear_height),
            settle=p.contact_settle,
            still_speed=p.still_speed,
            free=(0, 1), reference=self._empty_hand, free_speed=p.release_speed,
        )

    # --- the phases --------------------------------------------------------------------------
    def _over_place_steps(self) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        return [
            dev.move("up to the travel height", g, self._up_to_travel),
            dev.move("over the place", g, self._over_place),
            self.reference.hold("hold still", g, p.settle),
            check("read the hanging part", dev, g, self.reference.read),
        ]

    def _onto_floor_steps(self) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        return [
            self.descend.motion,
            check("clear way down", dev, g, self._clear_descent, Failure.BLOCKED),
            wait("hold still above the floor", dev, g, p.settle),
            self.floor.motion,
            check("on the floor", dev, g, self._on_floor),
        ]

    def _push_steps(self) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        return [
            dev.move("lift off the floor", g, lambda: self._move_by(0.0, 0.0, p.lift_off)),
            self.push_x.motion,
            check(
                "+x contact",
                dev,
                g,
                lambda: self._felt(self.push_x, "wall or part on +x"),
                Failure.NO_CONTACT,
            ),
            dev.move("ease off +x", g, lambda: self._move_by(-p.back_off, 0.0)),
            self.push_y.motion,
            check(
                "+y contact",
                dev,
                g,
                lambda: self._felt(self.push_y, "wall or part on +y"),
                Failure.NO_CONTACT,
            ),
            self.push_x_again.motion,
            check("where it went", dev, g, self._placed),
        ]

    def _let_go_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            # Hold where the part actually is, not where the push aimed: letting go under the
            # push's preload (up to 50 N seen) wedges the fingers.
            dev.move("relax the push", g, self._relax),
            # The jaws settle before the hand moves on. Where the arm follows the outer finger
            # (release_follow > 0) it follows the opening the gripper reports, tick by tick: an
            # arm moved on its own clock ran ahead of jaws that started late and pressed the
            # inner pad into the wall.
            GuardedMotion("let go", self._release, self._follow_opening, dev.arm, dev.ft,
                          dev.clock, g),
            dev.move("off the wall", g, self._off_the_wall),
            *self._way_up_steps(self.withdraw),
        ]

    def _way_up_steps(self, withdraw: ForcePush) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        return [
            withdraw.motion,
            check("withdrawn", dev, g, lambda: self._withdrawn(withdraw)),
            dev.move("up clear", g, self._up_clear),
            self.reference.hold("settle", g, p.settle),
            GuardedMotion("part left in the box", self._grip_if_lifted, self._gripped_again,
                          dev.arm, dev.ft, dev.clock, g, self._came_up_reason),
        ]

    # --- after a failure past the let go ----------------------------------------------------
    #: The last step, the weight check (and the re-grip of a part that came up): a stop there
    #: is its own verdict, not an interruption, and the jaws may be closing on the part.
    CHECK_STEP = "part left in the box"

    @property
    def let_go_started(self) -> bool:
        """The jaws were told to open on the part in its place."""
        return self._let_go_started

    @property
    def finishable(self) -> bool:
        """Stopped after the let go began and before the weight check: the part stands in its
        place, the hand is open around it, and :meth:`leave` does the rest."""
        return self._let_go_started and self.sequence.current != self.CHECK_STEP

    def leave(self) -> SequenceSkill:
        """The rest of the way out of the box from wherever this skill stopped after its let
        go began (a force-torque spike, a timeout, a protective stop the arm came back from, on
        the way up): the jaws opened again to the let go's width about a still arm, the open
        hand off the wall unless that move already ran (to the same place in the plane, at the
        height it stands), then the way up giving way in the plane and the weight check, as
        the packing itself would have ended. Each call is a fresh try of that rest. Why not a
        new packing: the hand is empty and the part stands where it was pushed."""
        if not self.finishable:
            raise RuntimeError("leave() outside the way out: the part is still held or checked")
        dev, g = self.dev, self.params.guard
        steps = [GuardedMotion("open the jaws", self._open_fully, self._jaws_still, dev.arm,
                               dev.ft, dev.clock, g)]
        if not any(seq.passed("off the wall") for seq in (self.sequence, *self._leaves)):
            steps.append(dev.move("off the wall", g, self._off_the_wall))
        leave = Sequence("leave the box", [*steps, *self._way_up_steps(self._withdraw_move())])
        self._leaves.append(leave)
        return StepsSkill(leave)

    # --- where the part goes -----------------------------------------------------------------
    def _pose(self, bottom_z: float) -> Pose:
        """The hold pose with the part's bottom at ``bottom_z``, short of its place."""
        p = self.params
        return hold_pose(
            self._start_xy, bottom_z, self.part, self._x, self._offset, p.grip_depth,
            p.tip_offset,
        )

    def _shifted(self, dx: float, dy: float, dz: float = 0.0) -> Pose:
        """The tool's pose now, moved by (dx, dy, dz) m."""
        tool = self.dev.arm.tool_pose()
        return Pose(tool.position + np.array([dx, dy, dz]), tool.rotation)

    # --- the steps' commands and checks ------------------------------------------------------
    def _travel_target(self) -> Pose:
        p = self.params
        return self._pose(max(self._top + p.clear_height, p.travel_z))

    def _up_to_travel(self) -> None:
        # Straight up first, as in the feed: the travel across may be a joint move.
        p = self.params
        rise_to(self.dev.arm, self._travel_target().position[Z], p.travel_speed, p.acceleration)

    def _over_place(self) -> None:
        self.joint_travel = self.travel.start(self.dev.arm, self._travel_target())

    def _move_by(self, dx: float, dy: float, dz: float = 0.0) -> None:
        p = self.params
        self.dev.arm.move_to(self._shifted(dx, dy, dz), p.approach_speed, p.acceleration)

    def _clear_descent(self) -> str | None:
        if self.descend.contact:
            p, tool = self.params, self.dev.arm.tool_pose()
            z = tool.position[Z] - p.tip_offset + p.grip_depth - self.part.length
            return (
                f"the part hit something {1e3 * (z - self.floor_z):.0f} mm above the box "
                f"floor ({self.descend.resisting:.1f} N) on the way down"
            )
        return None

    def _on_floor(self) -> str | None:
        if not self.floor.contact:
            return "no box floor felt below the part"
        self.contacts["floor"] = self.dev.arm.tool_pose()
        return None

    def _felt(self, move: ForcePush, what: str) -> str | None:
        if not move.contact:
            return f"no {what} felt within {1e3 * self._reach:.0f} mm"
        self.contacts[move.motion.name.split()[-1]] = self.dev.arm.tool_pose()
        return None

    def _placed(self) -> str | None:
        tcp = self.dev.arm.tool_pose().position[XY]
        self.placed_xy = tcp - self._offset * self._x[XY]
        return None

    def _relax(self) -> None:
        arm, p = self.dev.arm, self.params
        arm.move_to(arm.tool_pose(), p.approach_speed, p.acceleration)

    def _release(self) -> None:
        """Open by ``release``: the jaws open symmetrically about the TCP, which
        :meth:`_follow_opening` holds or moves after the outer finger (``release_follow``).
        The inner finger moving towards the hole's centre once caught a round part wedged
        against the +y wall (48 N, 9 N*m), on code whose way up did not yet give way in the
        plane; in 155 let gos with the jaws opening about a still arm (six staged runs and ten
        tipped bins) none caught."""
        gripper, p = self.dev.gripper, self.params
        self._open_from = gripper.width()
        self._let_go_from = self.dev.arm.tool_pose()
        self._let_go_started = True
        self._jaws_still.reset()
        gripper.open(self._open_from + p.release, p.release_speed)

    def _open_fully(self) -> None:
        """The let go's opening again, to the same width (a no-op for jaws already there),
        the arm held where it stopped."""
        p = self.params
        self._jaws_still.reset()
        self.dev.gripper.open(self._open_from + p.release, p.release_speed)

    def _follow_opening(self) -> bool:
        """Keep the arm ``release_follow`` of the *reported* opening after the outer finger (0,
        the default: the arm stands still and the jaws open about it); done once the jaws have
        stood still for ``settle``. Following what the gripper reports, the arm can lag the
        jaws but never lead them, however late they start."""
        p, start = self.params, self._let_go_from
        opened = max(0.0, self.dev.gripper.width() - self._open_from)
        dx, dy = p.release_follow * opened * self._x[XY]
        self.dev.arm.servo(Pose(start.position + np.array([dx, dy, 0.0]), start.rotation))
        return self._jaws_still()

    def _off_the_wall(self) -> None:
        """Move the open hand towards the hole's centre by ``release_clearance``: the finger
        in the hole, still touching the wall it gripped, dragged the part up and 5 mm aside as
        it withdrew (the twin measured it). The place in the plane is fixed the first time,
        from where the let go left the hand, so a move started again goes to the same place."""
        p = self.params
        tool = self.dev.arm.tool_pose()
        if self._off_wall_xy is None:
            self._off_wall_xy = tool.position[XY] - p.release_clearance * self._x[XY]
        target = np.array([*self._off_wall_xy, tool.position[Z]])
        self.dev.arm.move_to(Pose(target, tool.rotation), p.release_speed, p.acceleration)

    def _tip_depth(self) -> float:
        """How far (m) the fingertips reach below the part's rim, measured: the TCP's height
        when the part stood on the floor (``contacts["floor"]``) against the part's length.
        The grasp may have slipped from the nominal ``grip_depth``; the force mode's way up
        must last until the tips are out of the hole, wherever they are."""
        p = self.params
        floor = self.contacts.get("floor")
        if floor is None:
            return p.grip_depth
        tips = float(floor.position[Z]) - p.tip_offset
        return max(p.grip_depth, self.floor_z + self.part.length - tips)

    def _up_clear(self) -> None:
        """The rest of the way up: the fingertips ``clear_height`` above the rim (nothing
        there to touch: the packed parts are no higher than the part just let go)."""
        p = self.params
        tool = self.dev.arm.tool_pose()
        top = self.floor_z + self.part.length + p.clear_height + p.tip_offset
        rest = max(0.0, top - float(tool.position[Z]))
        self.dev.arm.move_to(self._shifted(0.0, 0.0, rest), p.approach_speed, p.acceleration)

    def _empty_hand(self) -> NDArray[np.float64] | None:
        """The force on the empty hand (N, base frame): the hanging part's reading less its
        weight, so the way up presses ``contact_force`` whatever the part weighs. None before
        the reading (the withdrawal then measures from where it begins)."""
        if self.reference.force is None:
            return None
        return self.reference.force + np.array([0.0, 0.0, self.part.mass * GRAVITY])

    @staticmethod
    def _withdrawn(withdraw: ForcePush) -> str | None:
        if withdraw.contact:
            return (
                f"the open hand was held down on its way up ({withdraw.resisting:.1f} N) "
                f"{1e3 * withdraw.travelled:.0f} mm above where it let go"
            )
        return None

    def _grip_if_lifted(self) -> None:
        """The weight check; a part that came up is taken in the hole grasp again (see
        ``regrip_force``), so it is held, not dangling, when the step fails."""
        self._came_up = self._let_go()
        self._closing_seen = False
        if self._came_up is not None:
            self._jaws_still.reset()
            # as slowly as the jaws let go: the pads meet the part's wall gently
            self.dev.gripper.close(self.params.regrip_force, self.params.release_speed)

    def _gripped_again(self) -> bool:
        return self._came_up is None  # else the step ends in _came_up_reason, jaws closed

    def _came_up_reason(self) -> str | None:
        if self._came_up is None:
            return None
        gripper = self.dev.gripper
        # a gripper that starts late is still before it moves: wait until it moved or holds
        self._closing_seen = self._closing_seen or gripper.moving()
        if not self._jaws_still() or not (self._closing_seen or gripper.object_detected()):
            return None
        held = "gripped again" if gripper.object_detected() else "the jaws closed empty"
        return f"{self._came_up}; {held}"

    def _let_go(self) -> str | None:
        p, part = self.params, self.part
        if p.weight_check <= 0 or self.reference.force is None:
            return None
        lost = self.reference.lost()
        if lost < p.weight_check * part.mass * GRAVITY:
            return (
                f"the part came up with the gripper: the wrench lost {lost:.2f} N of its "
                f"{part.mass * GRAVITY:.2f} N weight"
            )
        return None
