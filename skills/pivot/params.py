"""Parameters of the pivot skills (SI units). ``l_a`` and ``alpha`` come from the planner; the
fields declared with :func:`~skills.params.si` are the ``skills.pivot`` section of a cell's
configuration (and per-node overrides of the grasp, tilt, align and pick_from_above nodes)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from skills.motion import Guard
from skills.params import guard_field, si

#: rad per degree, exact: the configuration's defaults below are written in degrees
DEG = math.pi / 180.0


@dataclass(frozen=True)
class PivotParams:
    l_a: float
    alpha: float  #: rad
    grip_force: float = si(
        20.0, "N", 0.1, 235.0, "per finger while the grasp pivots the part (Grasp, Tilt)",
        actuator="grip_force",
    )
    hold_force: float = si(
        20.0, "N", 0.1, 235.0, "per finger of the hole grasp that lifts", actuator="grip_force"
    )
    pinch_settle: float = si(
        0.3, "s", 0.0, 2.0, "the pinch's fingers stand still this long before the part is lifted "
        "(the recovery's pick from above)"
    )
    touch_standoff: float = si(
        0.004, "m", 0.0, 0.03,
        "the outer tip stops this far above S before feeling for it (more than the height "
        "the camera, the hand-eye calibration and the part's tolerances leave unknown)",
    )
    height_tolerance: float = si(
        0.004, "m", 0.0, 0.03, "S may lie this much lower than expected and still be found"
    )
    touch_force: float = si(5.0, "N", 1.0, 50.0, "the wrist feels S pushing back with this")
    touch_speed: float = si(0.01, "m/s", 0.001, 0.1, "of the descent that feels for S")
    touch_settle: float = si(
        0.05, "s", 0.0, 1.0, "the descent stands still pressing this long to count as contact"
    )
    #: 2: the descent first covers the standoff to where S should be, then as much again and
    #: ``height_tolerance`` on, before it gives up on finding S
    touch_reach_factor: float = si(
        2.0, "1", 1.0, 10.0,
        "the feel for S goes at most this many touch_standoff, plus height_tolerance, down",
    )
    #: 0.002 m/s and 0.7: the contact test of the packing pushes (skills.force), which the
    #: feel for S has run with since it shares their force push
    touch_still_speed: float = si(
        0.002, "m/s", 0.0001, 0.05, "slower than this, the descent onto S is standing still"
    )
    touch_contact_ratio: float = si(
        0.7, "1", 0.1, 1.0,
        "share of touch_force that must press back, the descent still, to count as contact",
    )
    pinch_friction: float = si(
        0.6, "1", 0.1, 2.0,
        "the least pad-part friction the grasp counts on: S is pressed so the pinch cannot "
        "drag the outer pad along the surface",
    )
    press_gain: float = si(
        0.0002, "m/(N*s)", 0.0, 0.01, "the TCP moves down per newton S is pressed too little"
    )
    close_settle: float = si(0.2, "s", 0.0, 2.0, "the fingers stand still this long: closed")
    press_confirm: float = si(
        0.5, "1", 0.0, 1.0,
        "share of the press at S the closed grasp must still read (its mean while the fingers "
        "stood still), else the outer finger lost the top surface",
    )
    width_tolerance: float = si(
        0.006, "m", 0.0, 0.03,
        "Align's close on the wall may end this far inside the wall's width before it counts as "
        "no wall between the fingers",
    )
    pinch_width_margin: float = si(
        0.004, "m", 0.0, 0.03,
        "the pinched jaws may stand this far wider than the wall before the hole grasp counts as "
        "missed: wider, a pad is outside the part (the jaws closed across its outer diameter)",
    )
    #: 0.012, not Align's 0.006: a light part starts turning about G under the unit's 20 N pinch
    #: before the close is done, and the jaws follow it -- the 15 g cup's ran 6.1-6.4 mm past the
    #: planned rim contact in the twin with the inner finger on the rim, and at 0.006 those
    #: grasps were called misses (cup 7/10 on its tuning seeds 500-509, 10/10 at 0.012; the other
    #: four Table 3 parts 10/10 at both). A finger that misses the rim closes onto the wall's
    #: section or shut, far narrower.
    rim_tolerance: float = si(
        0.012, "m", 0.0, 0.05,
        "the Grasp's close may run this far past the planned rim contact before it counts as a "
        "miss (a light part turning about G under the pinch lets the jaws follow it)",
    )
    close_lead: float = si(0.001, "m", 0.0, 0.01, "the palm leads the outer finger closing")
    close_speed: float = si(
        0.02, "m/s", 0.001, 0.15, "of each finger while closing onto H", actuator="finger_speed"
    )
    #: m of extra jaw opening during the approach (in the cell: the planner's gripper model,
    #: :class:`drivers.parts.Gripper`, so the plan and the skill agree; not a key of its own)
    approach_clearance: float = 0.010
    approach_distance: float = si(
        0.06, "m", 0.0, 0.2, "back along the fingers before the final approach"
    )
    #: The pre-approach pose is reached from straight above it: a straight move from wherever the
    #: camera looked from would sweep the open jaws through the bin's walls or a neighbour.
    approach_height: float = si(
        0.10, "m", 0.0, 0.5, "above the pre-approach pose the gripper arrives before going down"
    )
    clearance_margin: float = si(
        0.006, "m", 0.0, 0.05,
        "the tool's planned sweep keeps from a bin wall or a neighbour (else the other end, "
        "a drag, or the part is left)",
    )
    tip_offset: float = 0.005  #: m from the TCP to the fingertips along the tool z axis (gripper)
    approach_speed: float = si(0.05, "m/s", 0.001, 0.5, "of the TCP on approaches")
    #: Moves with nothing near the fingers go faster than the approaches, moves that put a pad
    #: beside a wall slower; both as factors of ``approach_speed``, so configuring it scales them.
    transfer_speed_factor: float = si(
        2.0, "1", 0.1, 10.0,
        "times approach_speed of the moves over the part: down to the pre-approach pose (Grasp), "
        "to the camera's view and over the wall (recovery)",
    )
    descent_speed_factor: float = si(
        0.5, "1", 0.01, 1.0,
        "times approach_speed of the recovery's descent into the hole beside the wall",
    )
    #: The arc's speed is the part's turning rate times the radius (quasi-static is a bound on
    #: how fast the part turns), capped at ``tilt_speed``. Tuning seeds 500-519 with the 2F-85:
    #: 40 deg/s (bushing 0.030 m/s, bottle 0.032, duct 0.052, can at the 0.07 cap) made 79 of
    #: 80 against 78 at 0.02 m/s for every part, the Tilts 2.1-2.5 s against 2.9-7.3 s; the
    #: bushing at 0.07 m/s lost 5 of 20 (the inner finger out of the hole). With the 20 N grip
    #: and round parts, tuning seeds 64000-64019: 70 deg/s kept bushing, bottle and duct at 20
    #: of 20 (the can 19, its miss in the Grasp), the Tilt phase 1.4-1.5 s against 2.1 s.
    tilt_speed: float = si(
        0.07, "m/s", 0.001, 0.1, "the TCP's top speed along the arc"
    )
    tilt_rate: float = si(
        70.0 * DEG, "rad/s", 1.0 * DEG, 180.0 * DEG,
        "how fast the part may turn about G in the Tilt (slow: quasi-static, Sec. II-B); "
        "the arc runs at this times its radius, at most tilt_speed",
    )
    acceleration: float = si(0.3, "m/s^2", 0.01, 3.0, "of the TCP")
    #: theta of Fig. 10 (rad). None: to upright (90 deg), the part carried the whole way with
    #: the finger in its hole (Sec. III-B) -- or as far as the fingertips stay
    #: ``floor_clearance`` above the floor; the part's weight stands it up the rest of the way.
    tilt_angle: float | None = None
    tilt_past_tip: float = si(
        4.0 * DEG, "rad", 0.0, 30.0 * DEG, "the arc goes on past the tip-over angle"
    )
    #: The jaws may open once the part passes ``ease_before_tip`` short of its tip-over angle,
    #: so gravity stands it up ahead of the arc. Off by default: with the pinch eased, a part
    #: gripping the pads and the floor hard (mu_H >= 0.82, mu_G >= 0.52) fell from the arc's end
    #: so fast that its rim left the inner finger, which then stood on the rim (bushing from
    #: random poses, tuning seeds 20400-20429: 4 of 4 such failures with 3 mm, 1 with 1.5 mm,
    #: none with 0; the own catalogue's coupling 4 -> 6 of 10, square box 0 -> 2).
    tilt_ease: float = si(0.0, "m", 0.0, 0.01, "the jaws ease near the tip-over angle")
    ease_before_tip: float = si(
        3.0 * DEG, "rad", 0.0, 20.0 * DEG, "the ease starts this far before tip-over"
    )
    tilt_floor_clearance: float = si(
        0.003, "m", 0.0, 0.02, "kept between the fingertips and the floor on the arc"
    )
    finger_thickness: float = 0.008  #: m from a pad's face to its back (the gripper model's)
    locate_pivot: bool = True  #: place P_c from where the closed grasp found the rim
    tilt_squeeze: float | None = None  #: m the jaws may still close along the arc (None: free)
    tilt_axes: tuple[bool, bool, bool] = (False, False, True)  #: tool axes that give way
    tilt_press: float = si(
        30.0, "N", 1.0, 200.0, "the fingers may press along the arc before the TCP gives way"
    )
    tilt_compliance: float = si(
        0.002, "m/(N*s)", 0.0, 0.05, "the TCP gives way per newton over tilt_press"
    )
    tilt_backoff: float = si(
        0.004, "m", 0.0, 0.02, "the most the TCP gives way along the fingers (0: rigid)"
    )
    tilt_timeout: float = si(20.0, "s", 1.0, 600.0, "the longest the arc may take")
    settle: float = si(
        0.3, "s", 0.0, 5.0, "the longest the Tilt waits for the standing part to come to rest"
    )
    #: The wait ends as soon as the wrist's force holds within ``stand_band`` for
    #: ``stand_window`` (a part still rocking against the fingers moves it; one at rest, or
    #: free of the fingers, does not), and at ``settle`` at the latest (a window longer than
    #: ``settle`` makes it a fixed wait of ``settle``). 1 N is ten times the FT300's noise
    #: (about 0.1 N rms); 0.05 s is five of its samples.
    stand_band: float = si(
        1.0, "N", 0.05, 20.0, "the wrist's force varies less than this: the part is at rest"
    )
    stand_window: float = si(
        0.05, "s", 0.01, 1.0, "over this long, for the Tilt's wait to end before settle"
    )
    #: 2.0 rad/s (115 deg/s), ``narrow_speed`` 0.05 m/s and ``slide_speed`` 0.1 m/s: the
    #: standing part waits free between the Tilt and the hole grasp (Sec. IV-B: it must stand on
    #: its own meanwhile), and the less it waits the less it drifts and the sooner a pad touches
    #: it again (tuning seeds 510-529, five parts: 72 of 100 against 63 at 1.0 rad/s and
    #: 0.05 m/s; fingers at 0.1 m/s took the bushing from 20 to 15 of 20).
    align_speed: float = si(
        2.0, "rad/s", 3.0 * DEG, 120.0 * DEG, "of Align's turn about the rim contact (in hand)"
    )
    align_press: float = si(
        5.0, "N", 0.5, 100.0, "the pads may press along the closing line in Align's turn and "
        "slide before the TCP gives way (the standing part is not shoved)"
    )
    align_compliance: float = si(
        0.002, "m/(N*s)", 0.0, 0.05, "the TCP gives way per newton over align_press"
    )
    align_backoff: float = si(
        0.004, "m", 0.0, 0.02, "the most the TCP gives way along the closing line in the turn "
        "(the slide: the two wall gaps)"
    )
    align_acceleration: float = si(
        8.0, "rad/s^2", 0.1, 40.0, "of Align's turn about the rim contact (in hand)"
    )
    narrow_speed: float = si(
        0.05, "m/s", 0.001, 0.15, "of each finger closing on the wall and easing off it (Align)",
        actuator="finger_speed",
    )
    clear_height: float = si(0.03, "m", 0.0, 0.2, "above the rim for moves over the part")
    view_height: float = si(
        0.20, "m", 0.05, 1.0, "of the wrist camera above the rim (the recovery's look)"
    )
    view_search: float = si(
        0.08, "m", 0.0, 0.3, "the standing part may be off its predicted place (recovery)"
    )
    wall_gap: float = si(0.004, "m", 0.0, 0.02, "between each pad and the wall before the pinch")
    slide_speed: float = si(
        0.1, "m/s", 0.001, 0.5,
        "of the slide into the hole, the pads a wall gap off each face (Align)",
    )
    lift_height: float = si(0.05, "m", 0.0, 0.3, "the lift after Align")
    release: float = si(0.004, "m", 0.0, 0.03, "the jaws ease before Align turns the gripper")
    #: m the fingertips reach below the rim for the hole grasp; in the cell, the slot's
    #: ``grip_depth`` (the grasp the slot and the box expect), so it is not a key of its own.
    wall_depth: float = 0.040
    floor_clearance: float = si(0.012, "m", 0.0, 0.05, "kept between fingertips and floor")
    guard: Guard = field(default_factory=Guard)  #: FT and time limits of every motion
    descent_guard: Guard = guard_field(
        25.0, 10.0, "the slide into the hole (a pad on the rim must stop the arm)"
    )
