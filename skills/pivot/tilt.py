"""Tilt (Fig. 2(ii)-(iii), Fig. 10): carry the grasp along the arc of radius r about the pivot
corner P_c by theta, so the part turns about G while the fingers keep S and H."""

from __future__ import annotations

from drivers.arm import MotionState
from drivers.pose import Pose
from skills.motion import Devices, GuardedMotion, Sequence, wait
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import StepResult


class Tilt:
    """One guarded Cartesian path through the arc; the FT guard is the paper's emergency stop.

    The arc starts from the tool's measured pose when the Tilt starts, so ``r`` is the real
    distance to the pivot. The paper shortens theta when S slides (Sec. IV-B); here the jaw
    opening is watched instead: once S has slid ``slide_stop`` towards the rim, the centre of
    mass is about to pass G and the part swings upright on the finger in the hole, so the arc
    stops there and the part is given ``settle`` seconds to come to rest.
    """

    def __init__(self, frame: PivotFrame, params: PivotParams, dev: Devices) -> None:
        self.path: list[Pose] = []
        self.stopped_by_slide = False
        p, arm, gripper = params, dev.arm, dev.gripper
        state: dict[str, float] = {}

        def start() -> None:
            state["width"] = gripper.width()
            self.path = frame.tilt_path(arm.tool_pose(), p.tilt_angle)
            arm.move_path(self.path, p.tilt_speed, p.acceleration)

        def finished() -> bool:
            if state["width"] - gripper.width() >= p.slide_stop:
                self.stopped_by_slide = True
                arm.stop()
                return True
            return arm.status().state is MotionState.DONE

        def failed() -> str | None:
            st = arm.status()
            if st.state is MotionState.FAULT:
                return f"arm fault: {st.message}"
            return None

        arc = GuardedMotion(
            "arc about P_c", start, finished, arm, dev.ft, dev.clock, p.tilt_guard, failed
        )
        self.sequence = Sequence(
            "tilt", [arc, wait("let the part settle", dev, p.tilt_guard, p.settle)]
        )

    def tick(self) -> StepResult:
        return self.sequence.tick()

    def halt(self) -> None:
        self.sequence.halt()
