"""Dragging a part no pivot clears where it lies: the plan, and the drag in the twin."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from cell.reach import ur5_reach
from drivers.parts import Gripper
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import plan_pivot
from skills.pivot.clearance import bin_walls, choose_end, lying_part
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.reposition import (
    Grip,
    MoveKind,
    RepositionParams,
    _pinch_clear,
    grips,
    plan_reposition,
    plan_roll,
    roll_pose,
    roll_stroke,
)

ROI = (0.22, 0.72, -0.16, 0.16)
WALLS = bin_walls(ROI, 0.0, 0.08, 0.005)
W = Gripper().finger_width


@pytest.fixture(scope="module")
def bushing():  # type: ignore[no-untyped-def]
    part = load_catalogue(None).get("bushing")
    plan = plan_pivot(part, Gripper(), Frictions())
    return part, PivotParams(l_a=plan.l_a, alpha=plan.alpha)


def test_a_part_with_an_end_near_a_wall_is_dragged_along_its_axis_away_from_it(bushing) -> None:
    part, pivot = bushing
    # its end 29 mm from the -x wall, its axis along x: neither end's pivot clears
    f = PivotFrame(part.section(W), np.array([0.283, 0.069, 0.017]), math.radians(165), 0.0)
    assert not choose_end(f, pivot, WALLS, W, 2, reach=ur5_reach).clearance.clear
    move = plan_reposition(f, part, pivot, RepositionParams(), WALLS, [], ROI, W, reach=ur5_reach)
    assert move is not None
    assert move.shift @ np.array([1.0, 0.0]) > 0.0  # away from the -x wall
    assert 0.0 < move.distance <= 0.15
    assert choose_end(move.target, pivot, WALLS, W, 2, reach=ur5_reach).clearance.clear
    # the shortest: one step less would not do
    shorter = RepositionParams(max_shift=move.distance - 0.01)
    if move.distance > 0.011:
        again = plan_reposition(f, part, pivot, shorter, WALLS, [], ROI, W, reach=ur5_reach)
        assert again is None or again.distance <= move.distance


def test_a_part_hemmed_in_by_neighbours_is_not_dragged(bushing) -> None:
    part, pivot = bushing
    f = PivotFrame(part.section(W), np.array([0.283, 0.069, 0.017]), math.radians(165), 0.0)
    # neighbours pressed against both its sides: the open jaws cannot come down beside it
    hem = [
        lying_part("a neighbour", (0.283, 0.069 + s * 0.036), math.radians(165), 0.068, 0.034, 0.0)
        for s in (-1.0, 1.0)
    ]
    move = plan_reposition(f, part, pivot, RepositionParams(), WALLS, hem, ROI, W, reach=ur5_reach)
    assert move is None


def _bushing_trial(tmp_path, seed: int) -> dict:  # type: ignore[no-untyped-def]
    """One ``cell pivot --pose random`` bushing trial at ``seed``, as a user runs it: its JSON."""
    out = tmp_path / "p.json"
    r = subprocess.run(
        [sys.executable, "-m", "cell.cli", "pivot", "--part", "bushing", "--pose", "random",
         "--trials", "1", "--seed", str(seed), "--json", str(out)],
        capture_output=True, text=True, timeout=600,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(out.read_text())["per_trial"][0]  # type: ignore[no-any-return]


def test_cell_pivot_drags_a_part_against_the_wall_then_pivots_it(tmp_path) -> None:
    """Trial seed 4013 (the part's end 29 mm from the bin's -x wall): judged by the twin."""
    trial = _bushing_trial(tmp_path, 4013)
    assert trial["repositioned"] is True
    assert trial["success"] is True, trial["failure"]
    moved = np.hypot(trial["perceived_pose"]["x"] - trial["true_pose"]["x"],
                     trial["perceived_pose"]["y"] - trial["true_pose"]["y"])
    assert moved > 0.01  # the look after the drag saw it somewhere else


def test_a_part_whose_middle_the_jaws_cannot_reach_is_taken_further_along(bushing) -> None:
    """Its middle 39 mm from the -x wall, its axis at 70 deg: the 2F-85's body would come
    down on the wall's top there, so the pinch is taken where it clears, and the drag plans it."""
    part, pivot = bushing
    f = PivotFrame(part.section(W), np.array([0.2594, 0.1139, 0.017]), math.radians(69.7), 0.0)
    params = RepositionParams()
    assert not _pinch_clear(f, part, params, WALLS, W)  # not at its middle
    move = plan_reposition(f, part, pivot, params, WALLS, [], ROI, W, reach=ur5_reach)
    assert move is not None
    assert move.grip != Grip()
    assert abs(move.grip.along) <= 0.5 * (part.length - W)  # the pads stay on the part
    assert _pinch_clear(f, part, params, WALLS, W, move.grip)
    assert _pinch_clear(move.target, part, params, WALLS, W, move.grip)
    # a search kept to the middle finds nothing
    middle_only = RepositionParams(grip_step=0.05, grip_below_axis=0.05)
    assert all(g == Grip() for g in grips(part, middle_only, W))
    assert plan_reposition(f, part, pivot, middle_only, WALLS, [], ROI, W, reach=ur5_reach) is None


def test_a_round_part_along_a_wall_is_rolled_away_from_it(bushing) -> None:
    """Lying along the +y wall, 16 mm from it: no end's pivot clears, the jaws cannot come down
    on the wall's side to pinch it, so it is rolled across its axis, away from the wall."""
    part, pivot = bushing
    f = PivotFrame(part.section(W), np.array([0.3466, 0.1272, 0.017]), -0.209, 0.0)
    params = RepositionParams()
    assert not choose_end(f, pivot, WALLS, W, 2, reach=ur5_reach).clearance.clear
    assert not any(_pinch_clear(f, part, params, WALLS, W, g) for g in grips(part, params, W))
    move = plan_reposition(f, part, pivot, params, WALLS, [], ROI, W, reach=ur5_reach)
    assert move is not None and move.kind is MoveKind.ROLL
    assert move.shift @ np.array([0.0, -1.0]) > 0.0  # away from the +y wall
    assert abs(float(move.shift @ f.u[:2])) < 1e-9  # across its axis: a part rolls no other way
    assert move.distance <= params.roll_max
    assert choose_end(move.target, pivot, WALLS, W, 2, reach=ur5_reach).clearance.clear
    # a part with a rectangular hole (a box outside) does not roll
    box = dataclasses.replace(part, hole_shape="rectangle")
    assert plan_roll(f, box, pivot, params, WALLS, [], ROI, W, reach=ur5_reach) is None


def test_a_full_stroke_runs_the_contact_back_across_the_tips_width(bushing) -> None:
    """Where a stroke starts (the top under the tips' leading edge) and where a full one ends
    (under their trailing edge) lie one stroke apart for the same top: the 20 mm tips less
    2 mm at each edge, 16 mm; the tips then travelled twice that while the part rolled one."""
    part, _ = bushing
    f = PivotFrame(part.section(W), np.array([0.40, 0.0, 0.017]), 0.3, 0.0)
    params, direction = RepositionParams(), f.normal
    start = roll_pose(f.center, f, part, params, direction, W)
    ended = roll_pose(f.center, f, part, params, direction, W, ended=True)
    assert roll_stroke(W) == pytest.approx(0.016)
    assert (ended.position - start.position) @ direction == pytest.approx(roll_stroke(W))
    for pose in (start, ended):  # fingertips on the top, fingers down, side by side along u
        tips = pose.position + params.tip_offset * pose.rotation[:, 2]
        assert tips[2] == pytest.approx(f.floor_z + part.outer)
        assert pose.rotation[:, 2] == pytest.approx([0.0, 0.0, -1.0])
        assert abs(pose.rotation[:, 0] @ f.u) == pytest.approx(1.0)


def test_cell_pivot_rolls_a_bushing_off_the_wall_then_pivots_it(tmp_path) -> None:
    """Trial seed 21010 (the bushing along the +y wall, 16 mm from it): rolled, judged by the
    twin; the part moved by the physics of the roll, never set."""
    trial = _bushing_trial(tmp_path, 21010)
    assert trial["repositioned"] is True and trial["moved_by"] == "roll"
    assert trial["success"] is True, trial["failure"]
    moved = trial["true_pose"]["y"] - trial["perceived_pose"]["y"]
    assert moved > 0.005  # the look after the roll saw it further from the +y wall


def test_a_roll_stroke_presses_from_the_reading_before_the_touch_and_stops_at_its_travel() -> None:
    """The stroke begins pressing on the part's top: its force mode is set from the reading
    taken before the fingertips came down (else the touch's own force would be added to the
    press), pushes across at most ``roll_push`` at ``roll_speed``, and ends at its travel."""
    from skills.motion import Guard
    from skills.reposition import RollStroke
    from tests.skills.test_slot_packing_fakes import dev, devices, push_back

    d = devices()
    p = RepositionParams()
    push_back(d, (0.0, 0.0, 6.0))  # the fingertips already pressing on the top
    before = np.array([0.0, 0.0, -1.5])  # what the wrist read before they came down
    direction = np.array([0.0, -1.0, 0.0])
    stroke = RollStroke("roll", dev(d), Guard(80.0, 8.0, 10.0), p, direction, lambda: 0.032,
                        lambda: before)
    stroke.motion.start()
    selection, wrench, limits = d["arm"].force
    assert selection[:3].all() and not selection[3:].any()
    assert wrench[:3] == pytest.approx([0.0, -p.roll_push, 1.5 - p.roll_press])
    assert limits[:3] == pytest.approx([0.0, p.roll_speed, p.roll_speed])
    for _ in range(1000):
        d["arm"].tick()
        d["clock"].t += d["clock"].dt
        if stroke.motion.tick().done:
            break
    assert stroke.travelled == pytest.approx(0.032, abs=p.roll_speed * d["arm"].dt)
    assert d["arm"].force is None  # stopped at its travel


def test_the_jaws_never_come_down_astride_a_thin_wall(bushing) -> None:
    """A part 19 mm off the +x wall, its axis along y (seed 20601 of the tipped bin): opened
    around it, the outer finger would come down just outside the 5 mm wall and the 2F-85's body
    onto the wall's top (273 N in the twin). The tool's model is points 10-12 mm apart; the wall
    must still be seen between them."""
    part, _ = bushing
    walls = bin_walls(ROI, 0.0, 0.08, 0.005)
    f = PivotFrame(part.section(W), np.array([0.7008, -0.0658, 0.017]), math.radians(-90.4), 0.0)
    assert not _pinch_clear(f, part, RepositionParams(), walls, W, Grip())
