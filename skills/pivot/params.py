"""Parameters of the pivot skills (SI units). ``l_a`` and ``alpha`` come from the planner."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from skills.motion import Guard


@dataclass(frozen=True)
class PivotParams:
    l_a: float
    alpha: float  #: rad
    grip_force: float = 2.0  #: N per finger while the grasp pivots the part (Grasp, Tilt)
    hold_force: float = 15.0  #: N per finger of the final hole grasp that lifts the part
    press_depth: float = 0.0005  #: m the outer fingertip is set into S (a light, sure contact)
    close_lead: float = 0.001  #: m the palm leads the outer finger while the jaws close
    close_speed: float = 0.02  #: m/s of each finger while closing onto H
    approach_clearance: float = 0.010  #: m of extra jaw opening during the approach
    approach_distance: float = 0.06  #: m back along the fingers before the final approach
    tip_offset: float = 0.005  #: m from the TCP to the fingertips along the tool z axis
    approach_speed: float = 0.05  #: m/s
    tilt_speed: float = 0.01  #: m/s of the TCP along the arc (quasi-static, Sec. II-B)
    acceleration: float = 0.3  #: m/s^2
    #: theta of Fig. 10 (rad). None: to upright (90 deg), the part carried the whole way with
    #: the finger in its hole (Sec. III-B) -- or as far as the fingertips stay
    #: ``floor_clearance`` above the floor; the part's weight stands it up the rest of the way.
    tilt_angle: float | None = None
    tilt_past_tip: float = math.radians(4.0)  #: rad the arc goes on past the tip-over angle
    #: m the jaws open once the part passes ``ease_before_tip`` short of its tip-over angle:
    #: gravity then stands the part on its base a little ahead of the arc, and a part that lands
    #: upright before the arc ends is not pressed into the floor. Far smaller than the play of
    #: the inner finger in the hole, so that finger never leaves it.
    tilt_ease: float = 0.003
    ease_before_tip: float = math.radians(3.0)  #: rad
    tilt_floor_clearance: float = 0.003  #: m kept between the fingertips and the floor on the arc
    finger_thickness: float = 0.008  #: m from a pad's face to the back of its finger
    locate_pivot: bool = True  #: place P_c from where the closed grasp found the rim
    tilt_squeeze: float | None = None  #: m the jaws may still close along the arc (None: free)
    tilt_axes: tuple[bool, bool, bool] = (False, False, True)  #: tool axes that give way
    tilt_press: float = 30.0  #: N the fingers may press along the arc before the TCP gives way
    tilt_compliance: float = 0.002  #: m/(N*s) the TCP gives way per newton over ``tilt_press``
    tilt_backoff: float = 0.004  #: m, the most the TCP gives way along the fingers (0: rigid)
    settle: float = 0.3  #: s to let the standing part come to rest after the arc
    #: Align in hand: rad/s of the turn about the rim contact that brings the fingers parallel
    #: to the standing part's axis.
    align_speed: float = 0.5
    align_press: float = 0.0005  #: m the turn's centre lies inside the rim (keeps the contact)
    narrow_speed: float = 0.02  #: m/s of each finger while the jaws narrow around the wall
    clear_height: float = 0.03  #: m above the rim for moves over the standing part
    view_height: float = 0.20  #: m of the wrist camera above the rim when it looks for the part
    view_search: float = 0.08  #: m the standing part may be from where the Tilt predicts it
    wall_gap: float = 0.004  #: m between each pad and the wall before the pinch
    lift_height: float = 0.05  #: m, the lift after Align
    release: float = 0.004  #: m the jaws ease before Align turns the gripper
    wall_depth: float = 0.040  #: m the fingertips reach below the rim for the hole grasp
    floor_clearance: float = 0.012  #: m kept between the fingertips and the floor
    guard: Guard = field(default_factory=Guard)  #: FT and time limits of every motion
    #: The descent into the hole: a pad landing on the rim must stop the arm, not crush the part.
    descent_guard: Guard = field(default_factory=lambda: Guard(max_force=25.0, timeout=10.0))
    tilt_guard: Guard = field(default_factory=lambda: Guard(max_force=80.0, timeout=20.0))
