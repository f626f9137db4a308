"""Tilt (Sec. III-B, Fig. 10): carry the grasp along the arc of radius r about the far bottom
corner P_c until the part stands, the finger caught in the hole all the way.

The arc is streamed to the arm one control step at a time, position-controlled along the arc and
force-limited along the fingers (hybrid force-position, as the paper's packing uses): when the
outer finger presses on S harder than ``tilt_press`` the TCP backs off along the fingers, at most
``tilt_backoff``. A part lying a few millimetres away from its nominal place turns about a pivot
that is not the planned P_c; with rigid fingers the arc would then squeeze the part between S and
the floor (the twin measured 80 N for a 2.7 mm offset), which the real 2F-85's compliant
linkage would have absorbed.

Past the tip-over angle the part's weight turns it towards upright by itself (Sec. III-B), the
pads still pinching the wall (the jaws may ease by ``tilt_ease`` there, off by default: a part
let fall free from the arc's end left the inner finger on its rim), and the finger in the hole
keeps it from going further. The arc ends at theta = 90 deg, the part standing with the
inner finger over its rim -- never let go.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drivers.devices import Devices
from drivers.pose import Pose
from skills.axes import Z
from skills.compliance import Compliance, CompliantPath
from skills.mechanics.contact import HALF_PI
from skills.motion import Guard, Sequence, wait_steady
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import StepResult

#: Angles at which the fingertips' clearance of the floor is checked, from the tip-over angle to
#: the arc's end (``tilt_past_tip``, 4 deg by default: 30 steps of 0.13 deg)
FLOOR_CHECKS = 31


class Tilt:
    """The arc as a guarded, streamed motion; the FT guard is the paper's emergency stop.

    The arc starts from the tool's measured pose when the Tilt starts, so ``r`` is the real
    distance to the pivot, and the pivot itself is placed from where the grasp found the rim
    (:meth:`PivotFrame.located`). The jaws hold the pinch but may close only ``tilt_squeeze``
    further: the grasp stays the rigid one the mechanics assume, where a gripper that kept
    closing would drag S towards the rim early.
    """

    def __init__(
        self, frame: PivotFrame | Callable[[], PivotFrame], params: PivotParams, dev: Devices
    ) -> None:
        """``frame`` may be a callable, read when the arc starts (the frame the Grasp measured:
        its floor where the outer finger found S)."""
        self._frame_source = frame if callable(frame) else (lambda: frame)
        self.frame = self._frame_source()
        self.params = params
        self.dev = dev
        p = params
        self.tip = self.frame.section.tip_angle  #: rad, beta where the weight passes over G
        self.angle = p.tilt_angle if p.tilt_angle is not None else HALF_PI  #: theta (rad)
        self.start_width = 0.0  #: m, jaw opening when the arc started
        self._start_tool: Pose | None = None  #: the tool's measured pose when the arc started
        self.eased = False  #: the jaws have eased past the tip-over angle
        #: the node's force and torque limits over the arc's own time
        self.guard = Guard(p.guard.max_force, p.guard.max_torque, p.tilt_timeout)
        self.arc = CompliantPath(
            "arc about P_c",
            dev,
            self.guard,
            self._path,
            self._length,
            self._arc_speed,
            p.acceleration,
            Compliance(
                axes=p.tilt_axes,
                deadband=p.tilt_press,
                gain=p.tilt_compliance,
                limit=p.tilt_backoff,
            ),
            stop_when=self._ease_past_tip,
        )
        self.sequence = Sequence(
            "tilt",
            [
                self.arc.motion(),
                wait_steady(
                    "let the part stand", dev, self.guard, p.stand_band, p.stand_window, p.settle
                ),
            ],
        )

    def _path(self) -> Callable[[float], Pose]:
        arm, gripper, p = self.dev.arm, self.dev.gripper, self.params
        self.frame = self._frame_source()
        tool = arm.tool_pose()
        self._start_tool = tool
        self.start_width = gripper.width()
        if p.tilt_squeeze is not None:
            # Hold the pinch but let the jaws follow the part only this far: the mechanics
            # of Sec. II-III take the grasp as rigid while the part turns.
            gripper.close(p.grip_force, p.close_speed, max(0.0, self.start_width - p.tilt_squeeze))
        if p.locate_pivot:
            self.frame = self.frame.located(tool, gripper.width())
        if p.tilt_angle is None:
            self.angle = self._clear_of_floor(tool, gripper.width() + p.tilt_ease)
        return lambda s: self.frame.tilt_pose(tool, s * self.angle)

    def _clear_of_floor(self, tool: Pose, width: float) -> float:
        """The largest theta (rad, at most 90 deg) at which every fingertip corner stays
        ``tilt_floor_clearance`` above the floor. A grasp with S near the far end (large l_a) puts
        the outer finger's back below the floor before the part is upright; the arc stops short
        and the part's weight stands it up the rest of the way."""
        p = self.params
        floor = self.frame.floor_z + p.tilt_floor_clearance
        half = 0.5 * width  # exact: each pad's face lies half the opening from the TCP
        corners = [
            (side * half + side * back, p.tip_offset + self.dev.gripper.tip_advance(width))
            for side in (1.0, -1.0)
            for back in (0.0, p.finger_thickness)
        ]
        best = self.tip
        end = min(HALF_PI, self.tip + p.tilt_past_tip)
        for theta in np.linspace(self.tip, end, FLOOR_CHECKS):
            pose = self.frame.tilt_pose(tool, float(theta))
            lowest = min(
                float((pose.position + x * pose.rotation[:, 0] + z * pose.rotation[:, Z])[Z])
                for x, z in corners
            )
            if lowest < floor:
                break
            best = float(theta)
        return best

    def _length(self, pose_at: Callable[[float], Pose]) -> float:
        return float(np.linalg.norm(pose_at(0.0).position - self.frame.pivot)) * self.angle

    def _arc_speed(self, length: float) -> float:
        """m/s along the arc: the part turning at ``tilt_rate`` about G, the TCP at most at
        ``tilt_speed``. Quasi-static is a bound on how fast the part turns; at one TCP speed
        a part held far from its pivot (the cookie can, r = 0.11 m) turns at a third of the
        rate of one held close (the bushing, 0.04 m)."""
        p = self.params
        if self.angle <= 0.0:  # no arc to turn along: the cap alone
            return p.tilt_speed
        return min(p.tilt_speed, p.tilt_rate * length / self.angle)  # length = r * angle

    def _ease_past_tip(self) -> bool:
        """Never ends the arc early: eases the jaws once, just before the tip-over angle the
        tool has *reached*. The arm trails the streamed arc (a UR's servoj by its lookahead,
        0.05 s: 3.5 deg at 70 deg/s), so the commanded angle would ease early, with the part
        not yet over its tip (the bottle then lost the hole in 2 of 10)."""
        p = self.params
        if not self.eased and self.measured_theta >= self.tip - p.ease_before_tip:
            self.eased = True
            if p.tilt_ease > 0.0:
                self.dev.gripper.open(self.dev.gripper.width() + p.tilt_ease, p.close_speed)
        return False

    @property
    def theta(self) -> float:
        """rad of arc commanded so far."""
        return self.arc.progress * self.angle

    @property
    def measured_theta(self) -> float:
        """rad the tool has turned since the arc started, from the arm's measured pose (the
        arc turns about one axis, so the whole relative rotation is the angle along it)."""
        if self._start_tool is None:
            return 0.0
        return self.dev.arm.tool_pose().distance(self._start_tool)[1]

    def tick(self) -> StepResult:
        return self.sequence.tick()

    def halt(self) -> None:
        self.sequence.halt()
