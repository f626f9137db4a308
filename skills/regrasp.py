"""The regrasp baseline the pivot is measured against: pinch the lying part
from above, turn it upright in the air, stand it on the bin floor, let go; :class:`Align` then
takes the hole grasp on the standing part exactly as it does after the pivot's Tilt.

Why a baseline: the paper's claim for the pivot is that it reaches the hole grasp with less
motion than picking the part, turning it and regrasping it. The comparison is fair only if the
baseline runs under the same limits -- the pivot's ``approach_speed`` (and twice it,
``free_speed_factor``, for moves through free space and for carrying, as the pivot's own free
moves), ``acceleration``, guards
-- and ends in the same hole grasp taken by the same :class:`Align`.

Geometry (the lying part's :class:`PivotFrame`: axis ``u`` towards the open end, ``normal =
up x u``):

1. the closing line along ``closing_sign * normal``, the fingers down but leaning back towards
   the robot by ``pinch_tilt`` about the closing line (the pads still lie flat on the sides of
   the wall, so it is the same pinch across the outer diameter), the jaws open by ``wall_gap``
   a side; the TCP on the part's axis at its centre (``grip_offset``), at the height of the
   widest chord, the lowest fingertip corner ``tip_floor_clearance`` off the floor; approach
   along the fingers, pinch with ``pinch_force``;
2. one path, no stop between its waypoints: lift until the part can swing clear of the floor,
   (carry it to ``place_xy`` if given), turn the tool by 90 deg about ``-normal`` through the
   TCP -- the short way that brings ``u`` to ``up``, open end up -- and go down until the
   part's bottom is ``place_gap`` above the floor;
3. zero the wrist sensor (the tool's own weight now pulls sideways in the tool frame) and go
   down at a fifth of the approach speed (``set_down_speed_factor``) until the floor pushes back
   ``contact_force`` (a guarded contact move; arriving ``place_overshoot`` below the floor
   without feeling it fails);
4. open by ``wall_gap`` a side, back the fingers off the part along the tool axis, rise and
   turn fingers-down to just below where Align's wrist camera will look from (Align first
   draws the fingers back ``approach_distance``, which lands on that view), zero the sensor
   again (nothing held, fingers down: the state Align's guards assume).

Why the lean: standing, the tool's axis is the pinch's turned by 90 deg, i.e. ``pinch_tilt``
below horizontal, pointing away from the robot. With a horizontal tool (no lean) the UR5's
wrist links hang at the TCP's height, below the floor for a bushing pinched at its centre; at
55 deg they ride 0.1 m higher, above the bin's 80 mm wall, and every joint stays well inside
+-2 pi (wrist 3 near 0 rad with ``closing_sign = -1``). The lean is limited by the gripper body,
which must clear the lying part: a long, wide part (the cookie can) gets 20 deg, and then its
wrist is low and must stay inside the bin (``place_xy``, chosen by the trial runner).

After SUCCESS :meth:`Regrasp.standing_frame` is the frame to give :class:`Align`: its predicted
axis is where the TCP set the part down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.axes import XY, Z
from skills.motion import GuardedMotion, Sequence, wait
from skills.params import si
from skills.pivot.align import hole_grasp_rotation
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.slot import ContactMove, check
from skills.status import Status, StepResult

#: deg, the step of the search for the largest pinch tilt whose gripper body clears the lying
#: part: coarse enough for a short search, fine enough that the lean found is within 5 deg of
#: the largest (the planned leans, 55 and 20 deg, are multiples of it)
TILT_STEP_DEG = 5.0
#: points along the gripper body's lower edge tested against the lying part in that search:
#: one every 5 % of the edge, both ends included
EDGE_SAMPLES = 21
#: the least horizontal share of the tool axis the back-off divides by: with the tool nearly
#: vertical the back-off along the fingers stays within 1/0.3 (3.3 times) the clearance it
#: needs across, instead of growing without bound
MIN_BACK_OFF_REACH = 0.3


@dataclass(frozen=True)
class RegraspOptions:
    """What only the baseline needs (SI). Speeds, accelerations, guards, grip force, jaw gap,
    approach distance and clearances come from :class:`PivotParams`, shared with the pivot."""

    #: rad the pinch leans the fingers back towards the robot (about the closing line; the pads
    #: still lie flat on the wall's sides). Standing, the tool then points forward and this far
    #: down, so the UR5's wrist rides above and behind the TCP, clear of the floor and the bin's
    #: near wall; at 0 (tool horizontal) the wrist links reach below the floor.
    #: None: the largest up to ``max_tilt`` whose gripper body clears the lying part.
    pinch_tilt: float | None = None
    max_tilt: float = math.radians(55.0)  #: rad
    body_offset: float = 0.050  #: m from the TCP to the gripper body's face, along the fingers
    body_half_depth: float = 0.0175  #: m, half the gripper body's depth across the pad width
    body_clearance: float = 0.005  #: m kept between the gripper body and the lying part
    #: +1 or -1: the closing line along ``+-normal``. -1 keeps wrist 3 near 0 rad through the
    #: whole maneuver (+1 takes it to about -3.4 rad, nearer its +-2 pi limit).
    closing_sign: int = -1
    #: N per finger of the pinch; None: ``hold_force``. The pads touch the round wall on a
    #: narrow strip, which resists the part turning about the closing line only weakly: the
    #: turn's angular acceleration (3 rad/s^2 at the shared 0.3 m/s^2 limit) must not spin it.
    pinch_force: float | None = 40.0
    #: (x, y) m, world: where to stand the part; None: where it was pinched. The part is carried
    #: there at the lift height before it is turned (the wrist then swings in over the bin).
    place_xy: tuple[float, float] | None = None
    tip_floor_clearance: float = 0.005  #: m, the lowest fingertip corner above the floor
    #: m from the part's centre towards the open end where the pads pinch; None: the least that
    #: keeps the TCP ``min_place_height`` above the floor when the part stands.
    grip_offset: float | None = None
    #: m of the TCP above the floor, tool horizontal: the wrist sensor's radius (37.5 mm) and a
    #: margin below the tool axis.
    min_place_height: float = 0.030
    turn_clearance: float = 0.015  #: m between the swinging part and the floor during the turn
    place_gap: float = 0.008  #: m above the floor the carrying path leaves the part's bottom
    place_overshoot: float = 0.008  #: m below the floor the contact move aims (contact stops it)
    contact_force: float = 3.0  #: N of floor reaction that ends the descent
    back_off: float = 0.015  #: m the fingertips clear the standing part's wall when backing off
    zero_wait: float = 0.1  #: s held still before the sensor is zeroed (it averages 64 ms)
    #: The pads keep this far inside the part's ends, so neither pad hangs over an end and
    #: pinches on the edge of the wall.
    pad_end_margin: float = si(
        0.002, "m", 0.0, 0.02, "the pads keep inside the part's ends along its axis"
    )
    #: Gripper closed on the part, the fingers stand still this long before the pinch is checked
    #: (as long as the pivot's recovery waits on its pinch from above, ``pinch_settle``).
    pinch_settle: float = si(
        0.3, "s", 0.0, 2.0, "the pinch's fingers stand still this long before the check"
    )
    #: Moves through free space and carrying the pinched part run at this many times the
    #: pivot's ``approach_speed``, as the pivot's own free moves do: the same limits for both.
    free_speed_factor: float = si(
        2.0, "1", 0.1, 10.0, "times approach_speed for free moves and for carrying the part"
    )
    #: The descent onto the floor runs at this fraction of ``approach_speed``, slow enough for
    #: the contact move to stop on ``contact_force`` soon after the floor pushes back. 0.2: at
    #: the default approach speed the pivot's own touch speed (``touch_speed``, 0.01 m/s), so
    #: both methods meet a surface alike; at 0.5 the cookie can, the heaviest part held the
    #: farthest from the wrist, met the floor with 43-44 N and 8.1-8.3 N*m against the 8 N*m
    #: guard in 2 of 10 trials (`cell compare --part cookie_can --seed 63000`).
    set_down_speed_factor: float = si(
        0.2, "1", 0.01, 1.0, "times approach_speed for the descent onto the floor"
    )


def _rotation_about(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    return Rotation.from_rotvec(np.asarray(axis, float) * angle).as_matrix()


def pinch_rotation(frame: PivotFrame, tilt: float = 0.0, sign: int = -1) -> NDArray[np.float64]:
    """Closing line along ``sign * normal``; fingers down, leaning ``tilt`` (rad) back towards
    ``-u`` (the gripper body over the part's open-end side)."""
    x = sign * frame.normal
    z = -math.cos(tilt) * frame.up - math.sin(tilt) * frame.u
    return np.column_stack([x, np.cross(z, x), z])


def upright_turn(frame: PivotFrame) -> NDArray[np.float64]:
    """The world rotation that takes the lying part's axis ``u`` to ``up`` (90 deg about
    ``-normal``): the open end up, the closed end of a cup or bottle down."""
    return _rotation_about(-frame.normal, 0.5 * math.pi)  # exact: a right angle


@dataclass(frozen=True)
class _Carry:
    """The TCP poses of the turn upright, planned from the lying part's frame when the skill is
    built (module doc, step 2), and where the standing part's centre is from the TCP."""

    lifted: Pose  #: straight up from the pinch, high enough for the part to swing clear
    carried: Pose  #: over ``place_xy`` at that height (a waypoint only when it is given)
    turned: Pose  #: turned upright there
    above_floor: Pose  #: down until the part's bottom is ``place_gap`` above the floor
    down: Pose  #: the floor contact move's aim, ``place_overshoot`` below the floor
    rel_centre: NDArray[np.float64]  #: m, the standing part's centre from the TCP (world)


class Regrasp:
    """Pinch, lift, turn upright, set down on the floor, let go, back off (module doc).

    Three phases of named steps: pinch the lying part; lift and turn it upright and set it down
    until the floor pushes back; let go and back off to where Align looks from."""

    def __init__(
        self,
        frame: PivotFrame,
        part: Part,
        params: PivotParams,
        dev: Devices,
        options: RegraspOptions | None = None,
    ) -> None:
        """``frame``: the lying part's frame (its nominal or perceived pose; ``center`` at the
        axis, ``floor_z`` the floor). Raises ValueError when the part does not fit the jaws."""
        o = options or RegraspOptions()
        self.frame, self.part, self.params, self.options, self.dev = frame, part, params, o, dev
        #: m, the jaws open across the part
        self._opening = part.outer + 2.0 * params.wall_gap  # exact: wall_gap a side
        if self._opening > dev.gripper.stroke:
            raise ValueError(
                f"regrasp needs a jaw opening of {self._opening * 1e3:.1f} mm across the "
                f"{part.name}, the gripper has {dev.gripper.stroke * 1e3:.1f} mm"
            )
        self.grip_offset = self._pinch_offset()
        if o.closing_sign not in (1, -1):
            raise ValueError(f"closing_sign must be +1 or -1, got {o.closing_sign}")
        tilt = o.pinch_tilt if o.pinch_tilt is not None else self._clear_tilt(self.grip_offset)
        self.tilt = tilt  #: rad the pinch leans
        tcp_h = self._pinch_height()
        rot = pinch_rotation(frame, tilt, o.closing_sign)
        self.grasp = Pose(frame.point(self.grip_offset, tcp_h), rot)  #: TCP pose of the pinch
        self._pre = Pose(self.grasp.position - params.approach_distance * rot[:, Z], rot)
        self._carry = self._plan_carry(tcp_h)
        self.placed: Pose | None = None  #: the TCP's pose when the floor was felt
        # The floor is felt by the rise against the motion (``contact_force`` above the start's
        # reading, the held part and the turned tool's own weight in it); the guard is the
        # motions' own. The slide's low guard read absolutely would count the tool's weight,
        # turned 90 deg across the sensor with the part, as contact force.
        self._contact = ContactMove(
            "set down on the floor",
            dev,
            params.guard,
            lambda: self._carry.down,
            o.set_down_speed_factor * params.approach_speed,
            params.acceleration,
            o.contact_force,
        )
        self.sequence = Sequence(
            "regrasp", [*self._pinch_steps(), *self._set_down_steps(), *self._let_go_steps()]
        )

    # --- the plan ----------------------------------------------------------------------------
    def _pinch_offset(self) -> float:
        """m from the part's centre towards the open end where the pads pinch."""
        o, part = self.options, self.part
        a = 0.5 * part.length  # exact: the half length
        room = a - 0.5 * self.dev.gripper.finger_width - o.pad_end_margin  # exact: half a pad
        if o.grip_offset is None:
            offset = min(max(0.0, o.min_place_height - a), room)
        else:
            offset = o.grip_offset
        if not -room <= offset <= room:
            raise ValueError(f"grip_offset {offset:g} m puts the pads off the {part.name}")
        return offset

    def _pinch_height(self) -> float:
        """m of the TCP above the floor: pads at the widest, the lowest fingertip corner (the
        pad leans by ``tilt``) ``tip_floor_clearance`` off the floor."""
        p, o, tilt = self.params, self.options, self.tilt
        finger_width = self.dev.gripper.finger_width
        half_pad = 0.5 * finger_width  # exact: the pad's corner is half its width off its axis
        tip_drop = p.tip_offset * math.cos(tilt) + half_pad * math.sin(tilt)
        return max(0.5 * self.part.outer, o.tip_floor_clearance + tip_drop)  # exact: the radius

    def _plan_carry(self, tcp_h: float) -> _Carry:
        """The turn about the TCP and where it leaves the part; sets ``place_z`` and the
        predicted ``standing_axis``."""
        o, frame, rot = self.options, self.frame, self.grasp.rotation
        a, b = 0.5 * self.part.length, 0.5 * self.part.outer  # exact: half length, radius
        floor = frame.floor_z
        turn = upright_turn(frame)
        rel_centre = turn @ (frame.point(0.0, b) - self.grasp.position)
        bottom_below = a - rel_centre[Z]  # m from the TCP down to the part's bottom, standing
        lift_z = self._lift_z(tcp_h)
        lifted = Pose(np.array([*self.grasp.position[XY], lift_z]), rot)
        # The TCP's place: the standing axis lands on place_xy (the turn moves it off the TCP).
        xy = self.grasp.position[XY] if o.place_xy is None else (
            np.asarray(o.place_xy, float) - rel_centre[XY]
        )
        carried = Pose(np.array([*xy, lift_z]), rot)
        turned_rot = turn @ rot
        turned = Pose(carried.position, turned_rot)
        place_z = floor + bottom_below + o.place_gap
        self.place_z = floor + bottom_below  #: TCP height with the part standing on the floor
        above_floor = Pose(np.array([*xy, place_z]), turned_rot)
        down = Pose(
            above_floor.position - (o.place_gap + o.place_overshoot) * frame.up, turned_rot
        )
        self.standing_axis: NDArray[np.float64] = (xy + rel_centre[XY]).copy()
        return _Carry(lifted, carried, turned, above_floor, down, rel_centre)

    def _lift_z(self, tcp_h: float) -> float:
        """m, the TCP's height for the turn: everything of the part lies within ``swing`` of
        the TCP, so it swings through the turn ``turn_clearance`` above the floor."""
        o = self.options
        a, b = 0.5 * self.part.length, 0.5 * self.part.outer  # exact: half length, radius
        swing = math.hypot(a + abs(self.grip_offset), b) + abs(tcp_h - b)
        lift_z = self.frame.floor_z + max(swing + o.turn_clearance, o.min_place_height)
        return max(lift_z, self.grasp.position[Z])

    # --- the phases --------------------------------------------------------------------------
    def _pinch_steps(self) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        arm, gripper = dev.arm, dev.gripper
        o = self.options
        pinch_force = p.hold_force if o.pinch_force is None else o.pinch_force
        free_speed = o.free_speed_factor * p.approach_speed
        return [
            dev.grip("open across the part", g, lambda: gripper.open(self._opening)),
            dev.move(
                "above the part",
                g,
                lambda: arm.move_to(self._pre, free_speed, p.acceleration),
            ),
            dev.move(
                "down beside the wall",
                p.descent_guard,
                lambda: arm.move_to(self.grasp, p.approach_speed, p.acceleration),
            ),
            dev.grip(
                "pinch across the diameter", g, lambda: gripper.close(pinch_force),
                settle=o.pinch_settle,
            ),
            check("part in the pinch", dev, g, self._pinched),
        ]

    def _set_down_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            dev.move("lift and turn upright", g, self._lift_and_turn),
            wait("hold still", dev, g, self.options.zero_wait),
            self._zero("zero the wrist sensor"),
            self._contact.motion,
            check("on the floor", dev, g, self._floor_felt),
        ]

    def _let_go_steps(self) -> list[GuardedMotion]:
        dev, g = self.dev, self.params.guard
        return [
            dev.grip("let go", g, lambda: dev.gripper.open(self._opening)),
            dev.move("back off", g, self._back_off),
            wait("hold still again", dev, g, self.options.zero_wait),
            self._zero("zero the wrist sensor again"),
        ]

    # --- the steps' commands and checks ------------------------------------------------------
    def _zero(self, name: str) -> GuardedMotion:
        """Zero the wrist sensor: the tool's own weight pulls another way now."""
        dev = self.dev
        return GuardedMotion(
            name, dev.ft.bias, lambda: True, dev.arm, dev.ft, dev.clock, self.params.guard
        )

    def _pinched(self) -> str | None:
        return None if self.dev.gripper.object_detected() else "the pinch closed on nothing"

    def _lift_and_turn(self) -> None:
        # One profile over lift, turn and descent: the arm does not stop at the waypoints.
        c, p = self._carry, self.params
        waypoints = [c.lifted, c.turned, c.above_floor]
        if self.options.place_xy is not None:
            waypoints.insert(1, c.carried)
        speed = self.options.free_speed_factor * p.approach_speed
        self.dev.arm.move_path(waypoints, speed, p.acceleration)

    def _floor_felt(self) -> str | None:
        if not self._contact.contact:
            return (
                f"no floor felt {self.options.place_overshoot * 1e3:.0f} mm below where it "
                "should be"
            )
        pose = self.dev.arm.tool_pose()
        self.placed = pose
        self.standing_axis = (pose.position + self._carry.rel_centre)[XY].copy()
        return None

    def _back_off(self) -> None:
        # Along the fingers until the fingertips are clear of the near side of the wall.
        arm, p, o = self.dev.arm, self.params, self.options
        b = 0.5 * self.part.outer  # exact: the radius
        tool = arm.tool_pose()
        z = tool.rotation[:, Z]
        reach = max(float(np.hypot(*z[XY])), MIN_BACK_OFF_REACH)
        back = Pose(tool.position - (b + p.tip_offset + o.back_off) / reach * z, tool.rotation)
        arm.move_path([back, self._hand_over()], o.free_speed_factor * p.approach_speed,
                      p.acceleration)

    def _hand_over(self) -> Pose:
        """Where the back-off ends: fingers down, turned as Align turns them, ``approach_distance``
        straight below the pose from which Align's wrist camera looks at the standing part.

        Align starts by drawing the fingers back ``approach_distance`` along their axis and then
        moves the camera over the part; ending here makes that first move land on the view and
        the second one nil. Without a camera: ``clear_height`` over the rim."""
        p, f, dev = self.params, self.frame, self.dev
        rot = hole_grasp_rotation(-f.u)
        rim = f.floor_z + self.part.length
        if dev.camera is None:
            return Pose(np.array([*self.standing_axis, rim + p.clear_height + p.tip_offset]), rot)
        cam = dev.camera.tool_T_camera().position
        view = np.array([*self.standing_axis, rim + p.view_height]) - rot @ cam
        return Pose(view - p.approach_distance * f.up, rot)

    def _clear_tilt(self, offset: float) -> float:
        """The largest tilt (5 deg steps, at most ``max_tilt``) at which the gripper body's lower
        edge stays ``body_clearance`` above the lying part wherever it is over it."""
        o, part = self.options, self.part
        a, b = 0.5 * part.length, 0.5 * part.outer  # exact: half length, radius
        steps = int(math.floor(math.degrees(o.max_tilt) / TILT_STEP_DEG))
        for k in range(steps, -1, -1):
            tilt = math.radians(TILT_STEP_DEG * k)
            c, s = math.cos(tilt), math.sin(tilt)
            ok = True
            # along the face's lower edge (s, h from TCP)
            for t in np.linspace(-1.0, 1.0, EDGE_SAMPLES):
                along = o.body_offset * s - t * o.body_half_depth * c
                height = o.body_offset * c + t * o.body_half_depth * s
                over_part = -a - o.body_clearance <= offset + along <= a + o.body_clearance
                if over_part and height < b + o.body_clearance:
                    ok = False
                    break
            if ok:
                return tilt
        return 0.0

    def standing_frame(self) -> PivotFrame:
        """A frame whose Align prediction (``pivot - outer/2 u``) is the standing part's axis."""
        f = self.frame
        xy = self.standing_axis
        centre = np.array([*xy, 0.0]) + (f.section.a + 0.5 * self.part.outer) * f.u  # exact: r
        centre[Z] = f.floor_z + 0.5 * self.part.outer  # exact: the radius
        return replace(f, center=centre)

    @property
    def step(self) -> str:
        """Name of the step in progress (or ``done``)."""
        return self.sequence.current

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if result.status is Status.FAILURE:
            return result.failed(f"regrasp: {result.message}")
        return result

    def halt(self) -> None:
        self.sequence.halt()


__all__ = ["Regrasp", "RegraspOptions", "pinch_rotation", "upright_turn"]
