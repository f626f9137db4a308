"""The per-part planner: l_a and alpha from the mechanics, or a reason why not."""

import math

import pytest

from cell.catalogue import load_catalogue
from drivers.parts import Gripper, Part
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import (
    PlannerOptions,
    approach_problem,
    hole_room,
    hook_alpha,
    jaw_opening,
    plan_pivot,
    reach_depth,
)
from skills.mechanics.region import check_tilt

BUSHING = Part("bushing", 0.068, 0.034, 0.028, "circle", 0.156)
CAN = Part("cookie_can", 0.160, 0.066, 0.060, "circle", 0.12, open_ends=1)


def test_bushing_plan_is_stable_along_the_tilt_and_fits_the_stroke() -> None:
    plan = plan_pivot(BUSHING)
    assert plan.pivotable, plan.reason
    assert plan.l_a == pytest.approx(0.9)  # the largest allowed: the stroke is not the limit
    assert plan.delta_m == pytest.approx(0.0072, abs=5e-5)
    section = BUSHING.section(0.020)
    assert check_tilt(section, plan.l_a, plan.alpha, Frictions(), section.tip_angle).ok
    assert plan.alpha >= plan.alpha_hook
    assert plan.opening_m + Gripper().clearance <= Gripper().stroke
    # alpha keeps the margin above the smallest feasible alpha, which is the hook angle here
    # (the mechanics alone would accept a flatter gripper at l_a = 0.9, see test_balance); the
    # finger then reaches past H more than the hold share of the room
    assert plan.alpha == pytest.approx(plan.alpha_min + PlannerOptions().alpha_margin)
    assert plan.alpha_min == pytest.approx(plan.alpha_hook, abs=1e-6)
    room = hole_room(BUSHING, 0.020)
    assert reach_depth(section, plan.l_a, plan.alpha) > PlannerOptions().hold_share * room


CUP = load_catalogue(None).get("plastic_cup")


def test_a_wide_hole_is_tilted_until_the_finger_reaches_far_enough_past_the_rim() -> None:
    # The cup's hook comes at 7.3 deg (a 39 mm chord), where the finger reaches 6 mm past H and
    # the rim slides off it in Align; the hold share tilts it until it reaches 40 % of the room.
    section = CUP.section(0.020)
    room = hole_room(CUP, 0.020)
    hooked = plan_pivot(CUP, options=PlannerOptions(hold_share=0.0))
    held = plan_pivot(CUP)
    assert hooked.pivotable and held.pivotable
    assert reach_depth(section, hooked.l_a, hooked.alpha) < PlannerOptions().hold_share * room
    assert held.alpha > hooked.alpha
    assert held.alpha_min is not None and held.alpha_min > held.alpha_hook
    assert reach_depth(section, held.l_a, held.alpha_min) == pytest.approx(
        PlannerOptions().hold_share * room, abs=1e-6
    )


def test_a_hold_share_no_alpha_reaches_is_refused_naming_it() -> None:
    # A 20 mm-long ring cannot reach 90 % of its room past the rim with any plan that is stable,
    # fits the stroke and comes down clear.
    ring = Part(name="ring", length=0.020, outer=0.042, hole=0.034, mass=0.03)
    plan = plan_pivot(ring, options=PlannerOptions(hold_share=0.9))
    assert not plan.pivotable
    assert "past the rim" in plan.reason


def test_bad_hold_share_raises() -> None:
    with pytest.raises(ValueError, match="hold_share must lie in"):
        PlannerOptions(hold_share=1.5)


def test_long_part_is_limited_by_the_stroke() -> None:
    plan = plan_pivot(CAN)
    assert plan.pivotable
    section = CAN.section(0.020)
    usable = Gripper().stroke - Gripper().clearance
    assert plan.opening_m <= usable + 1e-9
    # a smaller alpha at this l_a would need more opening than the stroke gives
    assert jaw_opening(section, plan.l_a, plan.alpha_min - 1e-3) > usable
    # Near alpha = 90 deg the opening shrinks to delta (4.7 mm): a stroke below that cannot grasp.
    short = plan_pivot(CAN, Gripper(stroke=0.008, clearance=0.004))
    assert not short.pivotable and short.reason.startswith("stroke too short")


def test_refusals_carry_their_reason() -> None:
    bottle = Part("water_bottle", 0.161, 0.030, 0.025, "circle", 0.02, rigid=False)
    assert plan_pivot(bottle).reason.startswith("deformable part")
    rail = Part("mounting_rail", 0.083, 0.0076, 0.0064, "rectangle", 0.02)
    assert plan_pivot(rail).reason.startswith("hole narrower than the finger")
    # A pad that nearly fills the hole has no room for the pose's error and its turn: 0.5 mm
    # either side of a 20 mm pad in a 21 mm hole is refused, 4 mm in the bushing's 28 is not.
    small_cup = Part("small_cup", 0.070, 0.025, 0.021, "circle", 0.015)
    tight = plan_pivot(small_cup)
    assert not tight.pivotable and tight.reason.startswith("the pad nearly fills the hole")
    looser = plan_pivot(small_cup, options=PlannerOptions(side_room=0.0004))
    assert not looser.reason.startswith("the pad nearly fills the hole")
    assert plan_pivot(BUSHING).pivotable
    slippery = plan_pivot(BUSHING, frictions=Frictions(0.0, 0.0, 0.0))
    assert not slippery.pivotable and slippery.reason.startswith("no stable path")


def test_full_tilt_requirement_changes_the_plan() -> None:
    loose = plan_pivot(BUSHING, frictions=Frictions(0.0, 0.0, 0.4))
    strict = plan_pivot(
        BUSHING, frictions=Frictions(0.0, 0.0, 0.4), options=PlannerOptions(full_tilt=True)
    )
    assert loose.pivotable and strict.pivotable
    assert strict.l_a < loose.l_a  # beta_ub forces a smaller l_a (Fig. 7)
    assert strict.beta_ub is None  # stable to 90 deg


def test_hook_angle_grows_with_a_shallow_hole() -> None:
    deep = hook_alpha(BUSHING, 0.020, 0.005)
    assert deep == pytest.approx(math.atan(0.005 / (2 * 0.0098)), rel=1e-3)
    narrow = Part("bottle", 0.083, 0.035, 0.022, "circle", 0.09)
    assert hook_alpha(narrow, 0.020, 0.005) > deep


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"length": -0.01}, "length must be > 0"),
        ({"hole": 0.04}, "hole (40 mm) must be smaller"),
        ({"hole_shape": "oval"}, "hole_shape must be one of circle, rectangle"),
        ({"open_ends": 3}, "open_ends must be 1 or 2"),
    ],
)
def test_bad_part_raises(kwargs: dict, needle: str) -> None:
    base = dict(name="p", length=0.068, outer=0.034, hole=0.028, hole_shape="circle", mass=0.1)
    base.update(kwargs)
    with pytest.raises(ValueError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        Part(**base)


def test_finger_wider_than_hole_raises_from_the_library() -> None:
    with pytest.raises(ValueError, match="not narrower than the hole"):
        BUSHING.section(0.030)


# --- the approach at alpha ------------------------------------------------------------------

THICK = Part(name="thick_bushing", length=0.060, outer=0.040, hole=0.022, mass=0.15)
#: the approach's checks alone: the thick bushing's 1 mm either side of the pad is refused by
#: the default side room before any approach is looked at
NO_SIDE_ROOM = PlannerOptions(side_room=0.0)


def test_approach_blocked_by_the_wall_below_a_narrow_hole_names_it() -> None:
    # l_a 0.9 at 30.6 deg is stable and fits the stroke, but the inner finger, closing onto H,
    # cuts into the wall below the 22 mm hole (the chord leaves it 9 mm).
    reason = approach_problem(THICK.section(0.020), 0.9, math.radians(30.6))
    assert reason is not None
    assert "inner finger" in reason and "wall below the hole" in reason and "closing" in reason


def test_the_planner_passes_a_blocked_approach_over_for_one_that_is_clear() -> None:
    plan = plan_pivot(THICK, options=NO_SIDE_ROOM)
    assert plan.pivotable and plan.l_a is not None and plan.alpha is not None
    assert plan.l_a < 0.9  # 0.9 is blocked (above); the next clear l_a is taken
    assert approach_problem(THICK.section(0.020), plan.l_a, plan.alpha) is None


def test_every_table3_plan_has_a_clear_approach() -> None:
    for part in load_catalogue(None).parts.values():
        plan = plan_pivot(part)
        if plan.pivotable:
            assert plan.l_a is not None and plan.alpha is not None
            section = part.section(Gripper().finger_width)
            assert approach_problem(section, plan.l_a, plan.alpha) is None, part.name


def test_a_gripper_whose_fingers_cannot_get_in_is_refused_with_the_approach() -> None:
    plan = plan_pivot(THICK, Gripper(finger_thickness=0.05), options=NO_SIDE_ROOM)
    assert not plan.pivotable
    assert plan.reason.startswith("approach blocked: ")


def test_fingers_coming_down_clear_of_the_part_pass() -> None:
    # A wide hole and a small alpha: the inner finger comes down beyond the open end, the outer
    # one onto the top surface; nothing is cut.
    wide = Part(name="sleeve", length=0.050, outer=0.060, hole=0.050, mass=0.06)
    assert approach_problem(wide.section(0.020), 0.9, math.radians(10.0)) is None
