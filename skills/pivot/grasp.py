"""Grasp (Sec. III-C, Fig. 2(i)): tilt the gripper by alpha over the lying part's open end, so
that one finger drops into the hole and the other lands on the top surface at l, then close."""

from __future__ import annotations

import math

from drivers.devices import Devices
from drivers.pose import Pose
from skills.motion import GuardedMotion, Sequence
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import Failure, Status, StepResult


class Grasp:
    """Open, approach along the fingers, close onto H while S stays put; fail if nothing is held.

    The outer finger's tip is set on the top surface at S (the edge of its pad face is the
    finger's lowest point), pressed ``press_depth`` into it. The jaws then close while the arm
    moves the TCP towards the outer finger by half the closing, so the outer finger stays at S
    and the inner one travels alone to the rim at H. A plain close would not do: the 2F-85's
    fingers are coupled, so either S is held by friction and the inner finger stalls short of H,
    or S slides and the part is shoved along the floor; both shrink ``l`` away from the plan.
    """

    def __init__(self, frame: PivotFrame, params: PivotParams, dev: Devices) -> None:
        self.frame, self.params, self.dev = frame, params, dev
        p = params
        target = frame.grasp_pose(p.l_a, p.alpha, p.tip_offset)
        self.target: Pose = Pose(target.position - p.press_depth * frame.up, target.rotation)
        opening = frame.opening(p.l_a, p.alpha)
        if opening + p.approach_clearance > dev.gripper.stroke:
            raise ValueError(
                f"grasp needs a jaw opening of {(opening + p.approach_clearance) * 1e3:.1f} mm, "
                f"the gripper has {dev.gripper.stroke * 1e3:.1f} mm"
            )
        self._start_width = opening + p.approach_clearance  #: m, the jaws on the approach
        self._pre = self._keep_outer_pad_at_s()
        # The lead climbs by sin(alpha) along the closing line: keep that within half the press
        # so the outer finger stays on S (the cookie can's 33 deg lifted it off at 1 mm).
        self._lead = min(p.close_lead, 0.5 * p.press_depth / max(math.sin(p.alpha), 1e-6))
        self._closed_from = 0.0  #: m, the jaw opening when the close began
        self._moved_at = 0.0  #: s (clock), the last tick the fingers moved, or the close began
        self.sequence = Sequence("grasp", self._steps())

    def _keep_outer_pad_at_s(self) -> Pose:
        """The approach opening keeps the outer pad's face at S: only the inner finger has the
        clearance, so it starts short of H. Shifts ``target`` by half the clearance and returns
        the pose ``approach_distance`` before it along the fingers, shifted alike."""
        p = self.params
        z = self.target.rotation[:, 2]
        pre = Pose(self.target.position - p.approach_distance * z, self.target.rotation)
        shift = 0.5 * p.approach_clearance * self.target.rotation[:, 0]
        self.target = Pose(self.target.position - shift, self.target.rotation)
        return Pose(pre.position - shift, pre.rotation)

    def _steps(self) -> list[GuardedMotion]:
        dev, p, g = self.dev, self.params, self.params.guard
        arm, gripper = dev.arm, dev.gripper
        return [
            dev.grip("open", g, lambda: gripper.open(self._start_width)),
            dev.move("above the open end", g, self._over_pre),
            dev.move(
                "approach at alpha",
                g,
                lambda: arm.move_to(self.target, p.approach_speed, p.acceleration),
            ),
            GuardedMotion("close onto H", self._close, self._closed, arm, dev.ft, dev.clock, g),
        ]

    def _over_pre(self) -> None:
        """To the pre-approach pose from ``approach_height`` straight above it (or from where
        the tool is, if that is higher): only the last, vertical leg comes near the bin."""
        p, arm = self.params, self.dev.arm
        pre = self._pre
        above = pre.position + p.approach_height * self.frame.up
        tool = arm.tool_pose()
        above[2] = max(above[2], float(tool.position[2]))
        arm.move_path([Pose(above, pre.rotation), pre], 2 * p.approach_speed, p.acceleration)

    def _close(self) -> None:
        p, gripper = self.params, self.dev.gripper
        self._closed_from = gripper.width()
        self._moved_at = self.dev.clock.now()
        gripper.close(p.grip_force, p.close_speed)

    def _closed(self) -> bool:
        # Keep the outer (+x) finger where it is: closing moves it by half the closing
        # towards the TCP, so the TCP follows it that far along +x -- and leads by
        # ``close_lead``, since a finger held on S by friction only closes when the palm
        # moves. When the inner finger stops at H the lead is all S is dragged.
        gripper, clock = self.dev.gripper, self.dev.clock
        closing = self._closed_from - gripper.width()
        x = self.target.rotation[:, 0]
        position = self.target.position + (0.5 * closing + self._lead) * x
        self.dev.arm.servo(Pose(position, self.target.rotation))
        if gripper.moving():
            self._moved_at = clock.now()
            return False
        return clock.now() - self._moved_at >= 0.2

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if result.status is Status.SUCCESS:
            self.dev.arm.stop()
            if not self.dev.gripper.object_detected():
                return StepResult(
                    Status.FAILURE, "grasp: missed, the fingers closed on nothing", Failure.MISSED
                )
        return result

    def halt(self) -> None:
        self.sequence.halt()
