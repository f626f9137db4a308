"""Parameters of the pivot skills (SI units). ``l_a`` and ``alpha`` come from the planner."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from skills.motion import Guard


@dataclass(frozen=True)
class PivotParams:
    l_a: float
    alpha: float  #: rad
    grip_force: float = 3.0  #: N per finger while pinching
    press_depth: float = 0.0  #: m the arm presses S down after closing (holds S against sliding)
    approach_clearance: float = 0.010  #: m of extra jaw opening during the approach
    approach_distance: float = 0.06  #: m back along the fingers before the final approach
    tip_offset: float = 0.005  #: m from the TCP to the fingertips along the tool z axis
    approach_speed: float = 0.05  #: m/s
    tilt_speed: float = 0.01  #: m/s of the TCP along the arc (quasi-static, Sec. II-B)
    acceleration: float = 0.3  #: m/s^2
    #: theta of Fig. 10. The paper uses 90 deg and less when S slides; the default stops 15 deg
    #: past the tip-over angle atan(a/b), after which gravity stands the part up (Sec. III-B).
    tilt_angle: float = math.radians(80.0)
    tilt_press: float = 8.0  #: N the fingers may press on the part along the arc
    tilt_compliance: float = 0.002  #: m/(N*s) the TCP gives way per newton over ``tilt_press``
    tilt_backoff: float = 0.006  #: m, the most the TCP gives way (the hook must stay in the hole)
    slide_stop: float = 0.020  #: m of S sliding (jaw closing) that ends the arc
    settle: float = 1.0  #: s to let the part come to rest after the arc
    align_speed: float = 0.02  #: m/s of the TCP while the gripper turns about the rim
    lift_height: float = 0.05  #: m, the lift after Align
    release: float = 0.004  #: m the jaws open to let go of the pinch before Align
    wall_depth: float = 0.015  #: m the fingertips reach below the rim for the hole grasp
    wall_gap: float = 0.004  #: m between each finger and the wall before the final pinch
    guard: Guard = field(default_factory=Guard)  #: FT and time limits of every motion
    tilt_guard: Guard = field(default_factory=lambda: Guard(max_force=80.0, timeout=20.0))
