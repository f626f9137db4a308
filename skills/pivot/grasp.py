"""Grasp (Sec. III-C, Fig. 2(i)): tilt the gripper by alpha over the lying part's open end, so
that one finger drops into the hole and the other lands on the top surface at l, then close.

The Grasp is steered by what a real cell senses, not by the heights a twin knows exactly:

1. The jaws open to the planned opening plus the approach clearance, and the gripper comes down
   at alpha until the outer fingertip is ``touch_standoff`` above where S should be -- a margin
   larger than what the camera, the hand-eye calibration and the part's tolerances leave unknown
   of the height. Where the tip is comes from the gripper's linkage: a 2F-85's tips sit 8 mm
   higher at a 70 mm opening than closed (:meth:`drivers.gripper.Gripper.tip_advance`).
2. It feels for S: a force-controlled descent (the arm's force mode, straight down) until the
   wrist feels the top surface push back with ``touch_force``. That measures the part's height;
   the pivot frame's floor is corrected from it (:attr:`Grasp.frame`), so the Tilt turns about
   the real corner G.
3. The jaws close onto H while the arm keeps the outer finger on S: the TCP follows half the
   closing along the closing line (the 2F-85's jaws are symmetric; led by the arm's servo lag,
   :meth:`Grasp._width_ahead`), backs off along the fingers
   by the tips' advance (its linkage), and presses S down with the force the pinch needs to hold
   there by friction. A 2F-85 pinches with 20 N at least; at S that pinch pulls the pad along the
   surface with ``F cos(alpha)`` against a grip of ``mu (F sin(alpha) + P)``, so S holds only
   with a press ``P >= F (cos(alpha) / mu - sin(alpha))``, ``mu`` the least pad friction the
   cell counts on (``pinch_friction``). Without it the close drags S towards the rim and shoves
   the part (the twin measured l_a 0.9 -> 0.3 and the part pushed 4 mm).
4. The grasp is confirmed from what the wrist and the jaws report: the fingers stopped (the
   unit's object flag), at an opening within ``rim_tolerance`` of the one the plan puts H at,
   with S pressed. A close that ran past H (the inner finger missed the rim) fails as a miss.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from drivers.devices import Devices
from drivers.pose import Pose
from skills.axes import Z
from skills.force import ForcePush, world_force
from skills.motion import GuardedMotion, Sequence
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import Failure, Status, StepResult

UP = np.array([0.0, 0.0, 1.0])


def pinch_press(grip_force: float, alpha: float, friction: float) -> float:
    """N the arm must press S down with so that a pinch of ``grip_force`` (N) at ``alpha`` (rad)
    does not drag the outer pad along the top surface, with pad friction at least ``friction``
    (module doc, step 3). 0 where friction alone holds it."""
    return max(0.0, grip_force * (math.cos(alpha) / friction - math.sin(alpha)))


class Grasp:
    """Open, approach, feel for S, close onto H pressing S; fail if the grasp is not felt."""

    touch_step = "feel for S"
    close_step = "close onto H"

    def __init__(self, frame: PivotFrame, params: PivotParams, dev: Devices) -> None:
        self.frame, self.params, self.dev = frame, params, dev
        p = params
        gripper = dev.gripper
        self.opening = frame.opening(p.l_a, p.alpha)  #: m, the jaws with S and H touched
        if self.opening + p.approach_clearance > gripper.stroke:
            raise ValueError(
                f"grasp needs a jaw opening of {(self.opening + p.approach_clearance) * 1e3:.1f} "
                f"mm, the gripper has {gripper.stroke * 1e3:.1f} mm"
            )
        self._start_width = self.opening + p.approach_clearance  #: m, the jaws on the approach
        #: N, the press at S the pinch needs (module doc)
        self.press = max(p.touch_force, pinch_press(p.grip_force, p.alpha, p.pinch_friction))
        self.rotation = frame.grasp_rotation(p.alpha)
        self._x, self._z = self.rotation[:, 0], self.rotation[:, Z]
        # The outer pad's tip over S, ``touch_standoff`` up; only the inner finger has the
        # approach clearance, so the TCP sits half of it towards the inner finger.
        reach = p.tip_offset + gripper.tip_advance(self._start_width)
        a, b = frame.section.a, frame.section.b
        l = 2.0 * a * p.l_a  # exact: l = 2 a l_a, the paper's definition of l_a
        s_point = frame.point(a - l, 2.0 * b)  # exact: S on the top surface, at D = 2b
        tcp = s_point - 0.5 * self._start_width * self._x - reach * self._z  # exact: pads' middle
        self.standoff = Pose(tcp + p.touch_standoff * UP, self.rotation)
        self._pre = Pose(self.standoff.position - p.approach_distance * self._z, self.rotation)
        self.touch = ForcePush(
            self.touch_step, dev, p.guard, (0.0, 0.0, -1.0), p.touch_force, p.touch_speed,
            p.touch_reach_factor * p.touch_standoff + p.height_tolerance, settle=p.touch_settle,
            still_speed=p.touch_still_speed, contact_ratio=p.touch_contact_ratio,
        )
        self.s_height: float | None = None  #: m, where the outer tip found S
        self.shove = 0.0  #: m the TCP gave way along the closing line while closing (diagnostic)
        self._touched: Pose | None = None  #: the TCP pose where S was felt
        self._closed_from = 0.0  #: m, the reported opening when the close began
        self._advance_from = 0.0  #: m, the tips' advance then
        self._press_offset = 0.0  #: m the press regulation has moved the TCP down since
        self._moved_at = 0.0  #: s (clock), the last tick the fingers moved
        self._close_began = 0.0  #: s (clock), when the jaws were told to close
        self._t = 0.0
        #: N, the press at S read each tick since the fingers last moved: the confirmation
        #: averages these (one sample after the arm stops caught the contact mid-bounce)
        self._settled_press: list[float] = []
        self.sequence = Sequence("grasp", self._steps())

    def _steps(self) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        arm, gripper = dev.arm, dev.gripper
        return [
            dev.grip("open", g, lambda: gripper.open(self._start_width)),
            dev.move("above the open end", g, self._over_open_end),
            dev.move(
                "down to the pre-approach",
                g,
                lambda: arm.move_to(self._pre, self._transfer_speed, p.acceleration),
            ),
            dev.move(
                "approach at alpha",
                g,
                lambda: arm.move_to(self.standoff, p.approach_speed, p.acceleration),
            ),
            self.touch.motion,
            GuardedMotion(self.close_step, self._close, self._closed, arm, dev.ft, dev.clock, g,
                          self._close_failed, Failure.MISSED),
        ]

    @property
    def _transfer_speed(self) -> float:
        p = self.params
        return p.transfer_speed_factor * p.approach_speed

    def _over_open_end(self) -> None:
        """To ``approach_height`` straight above the pre-approach pose, turned as the approach
        needs; the next step goes straight down from there, so only that vertical leg comes
        near the bin. Within millimetres it is the pose the plan's reach check follows the TCP
        to from where the arm stands (the check's sweep leaves out the standoff and the tips'
        travel); a pose kept level with a higher tool, as before, was out of the UR5's reach
        at the bin's far corner where the checked one was not.

        Two moves, each stopping at its end, not one path through both: a path runs its corner
        at full speed, and where the first leg is mostly the tilt to alpha (the tool already
        over the part and turned to the grasp's yaw) the tool's mass, a hand's length behind
        the TCP, swings about it and stops dead at the corner. In the twin that read 68-107 N
        at the wrist with nothing touched (the tool heading down at 0.52 m/s, commanded 0.2)."""
        p, arm = self.params, self.dev.arm
        pre = self._pre
        above = pre.position + p.approach_height * self.frame.up
        arm.move_to(Pose(above, pre.rotation), self._transfer_speed, p.acceleration)

    # --- the close ---------------------------------------------------------------------------
    def _close(self) -> None:
        p, gripper, arm = self.params, self.dev.gripper, self.dev.arm
        if not self.touch.contact:
            return  # _close_failed says why
        self._touched = arm.tool_pose()
        reach = p.tip_offset + gripper.tip_advance(gripper.width())
        half = 0.5 * gripper.width()  # exact: the outer pad lies half the opening from the TCP
        tip = self._touched.position + half * self._x + reach * self._z
        self.s_height = float(tip[Z])
        # The part's top is where the tip stopped: the floor of the pivot plane follows from it.
        floor = self.s_height - 2.0 * self.frame.section.b  # exact: the top is D = 2b up
        self.frame = dataclasses.replace(self.frame, floor_z=floor)
        self._closed_from = gripper.width()
        self._advance_from = gripper.tip_advance(self._closed_from)
        self._press_offset = 0.0
        self._moved_at = self._t = self._close_began = self.dev.clock.now()
        gripper.close(p.grip_force, p.close_speed)

    def _closed(self) -> bool:
        """Keep the outer pad on S and pressing it while the jaws close (module doc, step 3);
        done once the fingers have stood still for ``close_settle``."""
        gripper, clock, p = self.dev.gripper, self.dev.clock, self.params
        if self._touched is None:
            return False
        now = clock.now()
        dt, self._t = max(0.0, now - self._t), now
        width = self._width_ahead(now)
        closing = self._closed_from - width
        advance = gripper.tip_advance(width) - self._advance_from
        pressing = float(world_force(self.dev) @ UP)
        self._press_offset += p.press_gain * (self.press - pressing) * dt
        self._press_offset = min(max(self._press_offset, -p.touch_standoff), p.height_tolerance)
        half = 0.5 * closing  # exact: symmetric jaws, each pad moves half the closing
        position = (
            self._touched.position
            + (half + min(p.close_lead, half)) * self._x
            - advance * self._z
            - self._press_offset * UP
        )
        self.dev.arm.servo(Pose(position, self.rotation))
        if gripper.moving():
            self._moved_at = now
            self._settled_press.clear()
            return False
        self._settled_press.append(pressing)
        return now - self._moved_at >= p.close_settle

    def _width_ahead(self, now: float) -> float:
        """The opening the jaws will have when the arm gets where it is sent now: the arm
        trails its stream by :meth:`drivers.arm.Arm.servo_lag` (a UR's servoj lookahead), and a
        palm that lags the closing jaws leaves the outer pad held on S by friction, which
        stalls the jaws short of H (the twin: 6 mm short, the inner finger out of the hole).
        The closing rate is the one measured since the close began (the reported width
        comes in counts, too coarse for a rate from one tick to the next)."""
        gripper = self.dev.gripper
        width = gripper.width()
        lag = self.dev.arm.servo_lag()
        if lag <= 0.0 or not gripper.moving():
            return width
        rate = max(0.0, self._closed_from - width) / max(now - self._close_began, lag)
        return max(0.0, width - rate * lag)

    def _close_failed(self) -> str | None:
        """No top surface where the part should lie, or the jaws ran past where the plan puts H
        (the inner finger did not catch the rim)."""
        if not self.touch.contact:
            return "the outer finger found no top surface where the part should lie"
        p, width = self.params, self.dev.gripper.width()
        if width < self.opening - p.rim_tolerance:
            return (f"the jaws closed to {width * 1e3:.1f} mm, past the rim at "
                    f"{self.opening * 1e3:.1f} mm: the inner finger missed it")
        return None

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if result.status is Status.SUCCESS:
            self.dev.arm.stop()
            gripper, p = self.dev.gripper, self.params
            pressing = self.settled_press
            if not gripper.object_detected():
                return StepResult(
                    Status.FAILURE, "grasp: missed, the fingers closed on nothing", Failure.MISSED
                )
            if pressing < p.press_confirm * self.press:
                return StepResult(
                    Status.FAILURE,
                    f"grasp: S is not pressed ({pressing:.1f} N, want {self.press:.1f} N): the "
                    "outer finger lost the top surface", Failure.MISSED,
                )
        return result

    @property
    def settled_press(self) -> float:
        """N, S's press as the wrist read it while the closed fingers stood still (the mean
        over ``close_settle``): the press regulation keeps the contact moving a little, and the
        stiff contact rings, so a single reading swung 10 N either way in the twin (a can whose
        press read 5.3 N after the arm stopped had averaged 15 N while settled)."""
        if not self._settled_press:
            return float(world_force(self.dev) @ UP)
        return float(np.mean(self._settled_press))

    def halt(self) -> None:
        self.sequence.halt()

