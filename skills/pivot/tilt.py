"""Tilt (Sec. III-B, Fig. 10): carry the grasp along the arc of radius r about the far bottom
corner P_c by theta, so the part turns about G while the fingers keep S and H.

The arc is streamed to the arm one control step at a time, position-controlled along the arc and
force-limited along the fingers (hybrid force-position, as the paper's packing uses): when the
outer finger presses on S harder than ``tilt_press`` the TCP backs off along the fingers, at most
``tilt_backoff``. A part lying a few millimetres away from its nominal place turns about a pivot
that is not the planned P_c; with rigid fingers the arc would then squeeze the part between S and
the floor (the twin measured 80 N for a 2.7 mm offset), which the real 2F-85's compliant
linkage would have absorbed.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from drivers.pose import Pose
from skills.compliance import Compliance, CompliantPath
from skills.motion import Devices, Sequence, wait
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import StepResult


class Tilt:
    """The arc as a guarded, streamed motion; the FT guard is the paper's emergency stop.

    The arc starts from the tool's measured pose when the Tilt starts, so ``r`` is the real
    distance to the pivot, and the pivot itself is placed from where the grasp found the rim
    (:meth:`PivotFrame.located`). The jaws hold the pinch but may close only ``tilt_squeeze``
    further: the grasp stays the rigid one the mechanics assume, where a gripper that kept
    closing would drag S towards the rim early. The arc ends ``tilt_past_tip`` beyond the tip-over
    angle, and the part is given ``settle`` seconds to stand up and come to rest. A part that
    swings up ahead of the arc earlier (the jaws close by ``swing_stop`` once S has lost it) ends
    the arc there; once the jaws have stopped (the swing is over) they let it go: turning on
    would catch its wall and drag it back down.
    """

    def __init__(self, frame: PivotFrame, params: PivotParams, dev: Devices) -> None:
        self.frame = frame
        p, arm, gripper = params, dev.arm, dev.gripper
        tip = frame.section.tip_angle
        self.angle = (
            p.tilt_angle if p.tilt_angle is not None else min(0.5 * math.pi, tip + p.tilt_past_tip)
        )  #: theta (rad) of this Tilt
        state: dict[str, float] = {}

        def path() -> Callable[[float], Pose]:
            tool = arm.tool_pose()
            state["width"] = gripper.width()
            if p.tilt_squeeze is not None:
                # Hold the pinch but let the jaws follow the part only this far: the mechanics
                # of Sec. II-III take the grasp as rigid while the part turns.
                floor = max(0.0, state["width"] - p.tilt_squeeze)
                gripper.close(p.grip_force, p.close_speed, floor)
            if p.locate_pivot:
                self.frame = frame.located(tool, gripper.width())
            return lambda s: self.frame.tilt_pose(tool, s * self.angle)

        def swung() -> bool:
            # The jaws close fast once the part has turned ahead of them towards upright. Well
            # before the tip-over angle a closing is S sliding towards the rim instead (the
            # paper's drifting l_a): the arc goes on.
            if self.arc.progress * self.angle < tip - p.swing_window:
                state["width"] = min(state["width"], gripper.width())
                return False
            return state["width"] - gripper.width() >= p.swing_stop

        def length(pose_at: Callable[[float], Pose]) -> float:
            return float(np.linalg.norm(pose_at(0.0).position - self.frame.pivot)) * self.angle

        self.arc = CompliantPath(
            "arc about P_c",
            dev,
            p.tilt_guard,
            path,
            length,
            p.tilt_speed,
            p.acceleration,
            Compliance(
                axes=p.tilt_axes,
                deadband=p.tilt_press,
                gain=p.tilt_compliance,
                limit=p.tilt_backoff,
            ),
            stop_when=swung,
        )

        def let_go() -> None:
            if self.arc.stopped_early:  # the part swung up ahead: do not drag it back down
                gripper.open(gripper.width() + p.release)

        self.sequence = Sequence(
            "tilt",
            [
                self.arc.motion(),
                dev.grip("let the swing end", p.tilt_guard, lambda: None, settle=0.3),
                dev.grip("let a swung part go", p.tilt_guard, let_go),
                wait("let the part settle", dev, p.tilt_guard, p.settle),
            ],
        )

    @property
    def theta(self) -> float:
        """rad of arc commanded so far."""
        return self.arc.progress * self.angle

    def tick(self) -> StepResult:
        return self.sequence.tick()

    def halt(self) -> None:
        self.sequence.halt()
