"""The regrasp baseline: tick by tick on fake devices (guards, halt, missed pinch, no floor), and
one trial in the twin that ends in the hole grasp, judged from the simulated state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.arm import MotionState
from drivers.devices import Devices
from sim.robot_model import FINGER_WIDTH
from skills.pivot import PivotFrame, PivotParams
from skills.regrasp import Regrasp, RegraspOptions, upright_turn
from skills.status import Status
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run


def _part(name: str = "bushing"):
    return load_catalogue().get(name)


def _frame(part) -> PivotFrame:
    return PivotFrame(part.section(FINGER_WIDTH), np.array([0.52, 0.0, 0.5 * part.outer]), 0.0)


def _devices(object_width: float | None = 0.034) -> dict:
    return {
        "arm": FakeArm(),
        "gripper": FakeGripper(object_width),
        "ft": FakeFT(),
        "clock": FakeClock(),
    }


def _skill(d: dict, part=None, **options) -> Regrasp:
    part = part or _part()
    dev = Devices(d["arm"], d["gripper"], d["ft"], d["clock"])
    return Regrasp(_frame(part), part, PivotParams(l_a=0.9, alpha=0.2847), dev,
                   RegraspOptions(**options))


def _floor_contact(skill: Regrasp, d: dict):
    """An on_tick that makes the floor push back once the set-down has started."""
    seen = {"ticks": 0}

    def on_tick(_: int) -> None:
        if skill.step == "set down on the floor":
            seen["ticks"] += 1
            if seen["ticks"] == 3:  # after the move took its reference
                rot = d["arm"].tool_pose().rotation
                d["ft"].value[:3] = rot.T @ np.array([0.0, 0.0, 5.0])  # the floor pushes up
        elif seen["ticks"]:
            d["ft"].value[:] = 0.0

    return on_tick


def test_turn_stands_the_part_open_end_up() -> None:
    frame = _frame(_part())
    assert np.allclose(upright_turn(frame) @ frame.u, [0.0, 0.0, 1.0])


def test_full_sequence_on_fakes_succeeds_and_predicts_the_standing_axis() -> None:
    d = _devices()
    skill = _skill(d)
    result, _ = run(skill, d, on_tick=_floor_contact(skill, d))
    assert result.status is Status.SUCCESS, result.message
    # Set down where it was pinched: the predicted axis is under the TCP of the pinch.
    assert np.allclose(skill.standing_axis, skill.grasp.position[:2], atol=1e-9)
    frame = skill.standing_frame()
    predicted = frame.pivot - 0.5 * skill.part.outer * frame.u
    assert np.allclose(predicted[:2], skill.standing_axis)
    # The pinch leans back; standing, the tool points forward and down (wrist above the TCP).
    assert 0.0 < skill.tilt <= math.radians(55.0)
    kinds = [c[0] for c in d["arm"].commands]
    assert kinds.count("path") >= 5


def test_ft_spike_fails_with_the_reason_and_stops_the_arm() -> None:
    d = _devices()
    skill = _skill(d)

    def spike(_: int) -> None:
        if skill.step == "lift and turn upright":
            d["ft"].value[:3] = [0.0, 0.0, 150.0]

    result, _ = run(skill, d, on_tick=spike)
    assert result.status is Status.FAILURE
    assert "regrasp: lift and turn upright: force-torque guard" in result.message
    assert d["arm"].stops >= 1
    assert d["arm"].state is MotionState.STOPPED


def test_halt_stops_the_arm_and_is_idempotent() -> None:
    d = _devices()
    skill = _skill(d)
    for _ in range(60):  # into the first arm motion
        skill.tick()
        d["arm"].tick()
        d["gripper"].tick()
        d["clock"].t += d["clock"].dt
        if skill.step == "down beside the wall":
            skill.tick()  # starts the descent
            break
    assert d["arm"].state is MotionState.MOVING
    skill.halt()
    assert d["arm"].state is MotionState.STOPPED
    stops = d["arm"].stops
    skill.halt()
    assert d["arm"].stops >= stops  # no error the second time


def test_pinch_on_nothing_fails() -> None:
    d = _devices(object_width=None)
    result, _ = run(_skill(d), d)
    assert result.status is Status.FAILURE
    assert "the pinch closed on nothing" in result.message


def test_no_floor_felt_fails() -> None:
    d = _devices()
    result, _ = run(_skill(d), d)
    assert result.status is Status.FAILURE
    assert "no floor felt" in result.message


def test_a_part_wider_than_the_stroke_is_refused() -> None:
    part = _part("cookie_can")
    wide = type(part)(**{**part.__dict__, "outer": 0.084, "hole": 0.07})
    with pytest.raises(ValueError, match="jaw opening"):
        _skill(_devices(), part=wide)


def test_regrasp_trial_in_the_twin_ends_in_the_hole_grasp() -> None:
    import argparse

    from lab.pivot_cmd import build_setup
    from lab.regrasp_run import GripperProbe, run_regrasp_trial

    ns = argparse.Namespace(
        trials=1, jobs=1, mu_ground=None, record=None, catalogue=None, part="bushing",
        cell=None, force=False, la=None, alpha=None, nominal=True,
        ideal=True,  # the skill in the twin as tuned; the cell's uncertainty: docs/pivot_in_hand.md
    )
    setup, _, _ = build_setup(ns)
    probe = GripperProbe()
    result = run_regrasp_trial(setup, 100, on_frame=probe, frame_every=1)
    assert result.success, result.failure
    assert result.tilt_deg < 10.0 and result.height_m > 0.01
    assert probe.tact_time is not None and 10.0 < probe.tact_time < result.sim_time
    assert probe.sweep.volume_cm3 > 1000.0
