"""Tilt (Fig. 2(ii)-(iii), Fig. 10): carry the grasp along the arc of radius r about the pivot
corner P_c by theta, so the part turns about G while the fingers keep S and H."""

from __future__ import annotations

from drivers.pose import Pose
from skills.motion import Devices, Sequence
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import StepResult


class Tilt:
    """One guarded Cartesian path through the arc; the FT guard is the paper's emergency stop.

    The arc starts from the tool's measured pose when the Tilt starts (after the grasp's press),
    so ``r`` is the real distance to the pivot.
    """

    def __init__(self, frame: PivotFrame, params: PivotParams, dev: Devices) -> None:
        self.path: list[Pose] = []
        p, arm = params, dev.arm

        def start() -> None:
            self.path = frame.tilt_path(arm.tool_pose(), p.tilt_angle)
            arm.move_path(self.path, p.tilt_speed, p.acceleration)

        self.sequence = Sequence("tilt", [dev.move("arc about P_c", p.tilt_guard, start)])

    def tick(self) -> StepResult:
        return self.sequence.tick()

    def halt(self) -> None:
        self.sequence.halt()
