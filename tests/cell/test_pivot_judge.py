"""The stricter judge of the pivot, shown to fail on skills that reach the same end state another
way: one that lets go, one that ends in a pinch, one that looks. Whole trials in the twin."""

from __future__ import annotations

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.devices import Devices
from drivers.parts import Gripper as GripperSpec
from drivers.pose import Pose
from lab.pivot_run import TrialSetup, run_trial
from sim.uncertainty import Uncertainty
from skills.mechanics.planner import plan_pivot
from skills.motion import GuardedMotion, Sequence, wait
from skills.pivot import Align, PickFromAbove, PivotParams, Tilt
from skills.pivot.align import hole_grasp_rotation

SEED = 11


@pytest.fixture(scope="module")
def setup() -> TrialSetup:
    """Without the cell's uncertainty: these trials show the judge at work on a skill that
    reaches the hole grasp another way, so the skill's own misses must not decide them."""
    part = load_catalogue().get("bushing")
    return TrialSetup(
        part=part, plan=plan_pivot(part, GripperSpec()), uncertainty=Uncertainty.ideal()
    )


class LetsGoAlign(Align):
    """The in-hand Align, but after the turn it lets go: the jaws open 10 mm and the fingers
    rise 30 mm, out of the hole, for 1.5 s, then come back."""

    def __init__(self, *args) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args)
        dev, g = self.dev, self.params.guard

        def rise(dz: float):  # type: ignore[no-untyped-def]
            def go() -> None:
                tool = dev.arm.tool_pose()
                dev.arm.move_to(Pose(tool.position + [0, 0, dz], tool.rotation), 0.02, 0.3)

            return go

        self.sequence.steps[1:1] = [
            dev.grip("let go", g, lambda: dev.gripper.open(dev.gripper.width() + 0.01)),
            dev.move("rise", g, rise(0.03)),
            wait("free", dev, g, 1.5),
            dev.move("back", g, rise(-0.03)),
        ]


class LooksAlign(Align):
    """The in-hand Align, but it takes one camera frame first ("to check")."""

    def __init__(self, *args) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args)
        dev = self.dev
        assert dev.camera is not None
        look = GuardedMotion(
            "look", dev.camera.capture, lambda: True, dev.arm, dev.ft, dev.clock, self.params.guard
        )
        self.sequence.steps.insert(0, look)


class OuterPinch:
    """After the Tilt: let go, straddle the standing part from above and pinch its outside."""

    def __init__(self, tilt: Tilt, setup: TrialSetup, params: PivotParams, dev: Devices) -> None:
        part, g, arm = setup.part, params.guard, dev.arm

        def axis() -> np.ndarray:
            frame = tilt.frame
            return frame.pivot - 0.5 * part.outer * frame.u

        def pose(height: float) -> Pose:
            rot = hole_grasp_rotation(-tilt.frame.u)
            return Pose(np.array([*axis()[:2], height + params.tip_offset]), rot)

        def retreat() -> None:
            tool = arm.tool_pose()
            back = tool.position - 0.06 * tool.rotation[:, 2]
            arm.move_to(Pose(back, tool.rotation), 0.05, 0.3)

        top = part.length
        self.sequence = Sequence(
            "outer pinch",
            [
                dev.grip("let go", g, lambda: dev.gripper.open(0.085)),
                dev.move("back", g, retreat),
                dev.move("above", g, lambda: arm.move_to(pose(top + 0.05), 0.1, 0.3)),
                dev.move("around", g, lambda: arm.move_to(pose(top - 0.03), 0.05, 0.3)),
                dev.grip("pinch", g, lambda: dev.gripper.close(15.0), settle=0.3),
                dev.move("lift", g, lambda: arm.move_to(pose(top + 0.02), 0.05, 0.3)),
            ],
        )

    def tick(self):  # type: ignore[no-untyped-def]
        return self.sequence.tick()

    def halt(self) -> None:
        self.sequence.halt()


def _align(cls):  # type: ignore[no-untyped-def]
    return lambda tilt, setup, params, dev: cls(lambda: tilt.frame, setup.part, params, dev)


def test_a_skill_that_lets_go_is_not_a_pivot(setup: TrialSetup) -> None:
    r = run_trial(setup, SEED, make_align=_align(LetsGoAlign))
    assert not r.inner_in_hole_all_along  # the watch saw the finger leave the hole
    assert r.longest_free_s > 1.0  # and the part untouched while it was out
    assert not r.success
    # counted by its phase and code, whatever the sentence says
    assert r.failure_code is not None and r.failure_key == f"{r.phase}: {r.failure_code}"


def test_a_skill_that_looks_is_not_a_pivot(setup: TrialSetup) -> None:
    r = run_trial(setup, SEED, make_align=_align(LooksAlign))
    assert r.end_state_ok  # the same hole grasp at the end ...
    assert r.camera_frames_steering == 1  # ... but steered by a frame
    assert not r.success and r.failure_code == "camera_used"
    assert r.inner_in_hole_all_along and r.final_grasp == "hole"


def test_a_skill_that_ends_in_a_pinch_is_not_a_pivot(setup: TrialSetup) -> None:
    r = run_trial(setup, SEED, make_align=OuterPinch)
    assert r.final_grasp == "pinch"
    assert not r.success and r.failure_code in ("not_hole_grasp", "no_finger_in_hole")


def test_the_regrasp_way_is_not_a_pivot_either(setup: TrialSetup) -> None:
    """Release, look and pick from above (the old Align, now the recovery) ends in a hole
    grasp that the end-state test alone accepts; the watch does not."""
    r = run_trial(setup, SEED, make_align=_align(PickFromAbove))
    assert r.end_state_ok and r.final_grasp == "hole"
    assert r.camera_frames_steering >= 1
    assert r.longest_free_s > 1.0
    assert not r.success
