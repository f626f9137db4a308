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

import numpy as np

from drivers.arm import MotionState
from drivers.pose import Pose
from skills.motion import Devices, GuardedMotion, Sequence, wait
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.status import StepResult


class Tilt:
    """The arc as a guarded, streamed motion; the FT guard is the paper's emergency stop.

    The arc starts from the tool's measured pose when the Tilt starts, so ``r`` is the real
    distance to the pivot. The paper shortens theta when S slides (Sec. IV-B); here the jaw
    opening is watched instead: once S has slid ``slide_stop`` towards the rim, the centre of
    mass is about to pass G and the part swings upright on the finger in the hole, so the arc
    stops there and the part is given ``settle`` seconds to come to rest.
    """

    def __init__(self, frame: PivotFrame, params: PivotParams, dev: Devices) -> None:
        self.frame = frame
        self.stopped_by_slide = False
        self.theta = 0.0  #: rad of arc commanded so far
        self.backoff = 0.0  #: m the TCP has given way along the fingers
        self.peak_press = 0.0  #: N, largest press of the fingers on the part along the arc
        p, arm, gripper, clock, ft = params, dev.arm, dev.gripper, dev.clock, dev.ft
        state: dict[str, float | Pose] = {}

        def start() -> None:
            tool = arm.tool_pose()
            state.update(grasp=tool, width=gripper.width(), t=clock.now(), omega=0.0)
            radius = max(1e-3, float(np.linalg.norm(tool.position - frame.pivot)))
            state["omega_max"] = p.tilt_speed / radius
            state["alpha_max"] = p.acceleration / radius

        def advance() -> bool:
            now = clock.now()
            dt = max(0.0, now - float(state["t"]))
            state["t"] = now
            if float(state["width"]) - gripper.width() >= p.slide_stop:
                self.stopped_by_slide = True
                arm.stop()
                return True
            if self.theta >= p.tilt_angle:
                arm.stop()
                return True
            omega = min(float(state["omega_max"]), float(state["omega"]) + state["alpha_max"] * dt)
            state["omega"] = omega
            self.theta = min(p.tilt_angle, self.theta + omega * dt)
            press = max(0.0, -float(ft.wrench()[2]))
            self.peak_press = max(self.peak_press, press)
            self.backoff = float(
                np.clip(self.backoff + p.tilt_compliance * (press - p.tilt_press) * dt,
                        0.0, p.tilt_backoff)
            )
            target = frame.tilt_pose(state["grasp"], self.theta)  # type: ignore[arg-type]
            z = target.rotation[:, 2]
            arm.servo(Pose(target.position - self.backoff * z, target.rotation))
            return False

        def failed() -> str | None:
            st = arm.status()
            if st.state is MotionState.FAULT:
                return f"arm fault: {st.message}"
            return None

        arc = GuardedMotion(
            "arc about P_c", start, advance, arm, ft, clock, p.tilt_guard, failed
        )
        self.sequence = Sequence(
            "tilt", [arc, wait("let the part settle", dev, p.tilt_guard, p.settle)]
        )

    @property
    def theta_deg(self) -> float:
        return math.degrees(self.theta)

    def tick(self) -> StepResult:
        return self.sequence.tick()

    def halt(self) -> None:
        self.sequence.halt()
