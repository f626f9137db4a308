"""Per-part pivot planner: choose ``l_a`` and ``alpha`` from the mechanics, not by hand.

Policy (Sec. III-C, "grasp with as large an l_a as possible to permit a small alpha"):

1. A deformable part is refused (the paper's water bottle, 0/10: the wall crushes at S).
2. The finger must fit the hole (Eq. 2 needs ``w < d``); then ``delta`` follows from Eq. 3.
3. For ``l_a`` from ``la_max`` downwards, find the smallest ``alpha_min`` whose Tilt is in force
   balance for every ``beta`` from 0 to ``beta_required``, whose jaw opening fits the stroke and
   whose finger hooks the hole (below). The plan uses ``alpha = alpha_min + alpha_margin``
   (2 deg by default) and only where the whole margin lies inside the feasible set: the smallest
   feasible alpha sits on the stability boundary, where any tilt error of the arm would leave it.
   The first ``l_a`` that has one wins.

``beta_required`` is, by default, the tilt at which the centre of mass passes over the pivot G,
``atan(a/b)``: beyond it the paper observes (Sec. III-B, Fig. 7) that losing balance only lets
gravity turn the part further towards upright while the finger in the hole keeps it. With
``full_tilt`` the whole range to pi/2 is required instead.

The paper's model has no term for getting the inner finger *into* the hole: as ``alpha -> 0`` its
contact H degenerates to pushing on the end face (the pinch of Sec. III-A), and Eq. 8 alone would
happily pick ``alpha`` near 0 for large ``l_a``. The planner therefore also requires the finger's
tip to reach ``hook_depth`` behind the rim: tilted by ``alpha`` and sliding down the hole's
free height below H (``2x`` for a round hole, Eq. 2; ``d`` for a rectangular one) the tip gets
``room * tan(alpha)`` in, so ``alpha >= atan(hook_depth / room)``.

Nor does the model bound the finger's length. With both fingertips at the same depth and the
outer one on the top surface, the inner tip reaches ``e_H = l sin(alpha) - delta cos(alpha)``
past the rim contact H along the finger; the palm would hit the rim if that exceeded the
finger's length, so the planner requires ``e_H <= finger_length - palm_margin``. This is what
keeps long parts with a large alpha (the cookie can, the wiring duct) at a small ``l_a``, as the
paper's Table 3 has them (0.28 and 0.53).

The planner bounds the reach from below too: ``e_H >= hold_share * room``, the room as in the
hook criterion. Through Align the part turns about the rim while the inner finger alone keeps
it (Sec. III-C), and what keeps the finger in the hole is its length past H against the room
the rim has to slide in: a short reach in a wide hole lets the rim slide off the tip as the
part swings upright. The hook criterion does not see this, because a wide hole gets its hook at
a small alpha (the plastic cup's 7.3 deg), where the tip reaches only 6.2 mm past H, 16 % of
its 39 mm room. Planned so, the cup's inner finger left the hole in 19 of 30 trials in the twin
(seeds 60000); on its tuning seeds (500-509), with the reach at 10.3, 12.3 and 14.3 mm (26,
32 and 37 %), 3, 1 and 0 of 10 did. The bushing's plan reaches 53 % of its 20 mm room and
holds. The default share, 0.4, leaves Table 3's other plans as they were and tilts the cup to
19.6 deg (the paper's 18). A part that cannot have that reach at any stable alpha whose
approach is clear is refused, with what the finger would meet on the way down.

The jaw opening at the grasp is the distance between the finger faces along the closing line,
``l cos(alpha) + delta sin(alpha)`` (the projection of S - H on it), plus the approach clearance.

Last, the approach itself (:func:`approach_problem`): the fingers come down along their own
axis from ``approach_distance`` back, the jaws opened by the gripper's ``clearance``, and the
inner finger then closes onto H. In the pivot plane each finger is a rectangle (its length and
thickness); none may cut into the part's walls (the top and bottom walls' sections, ``delta``
thick at the finger's edges) or the floor by more than ``contact_tolerance`` anywhere on the way
(each straight move is checked as the shape the finger sweeps) -- the fingers only set onto S
and H. A plan whose approach is
blocked is passed over for the next ``(l_a, alpha)``; a part with none left is refused, naming
what the finger meets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.parts import Gripper, Part, Section, hole_offset
from skills.mechanics.contact import Frictions, check_la
from skills.mechanics.region import (
    ANGLE_TOL,
    HALF_PI,
    alpha_axis,
    bisect_edge,
    stable_beta_max,
    tilt_ok_mask,
)

#: rad, the largest ``alpha_margin`` accepted (about 29 deg): a margin that large would leave
#: little of (0, pi/2) to plan in; a larger value is most likely degrees given as rad
MAX_ALPHA_MARGIN = 0.5
#: m, a length this short counts as none (an edge of no length has no normal), and a length
#: within it of a bound counts as on the bound: float rounding of sums of millimetre lengths
LENGTH_ROUNDING = 1e-12
#: m an overlap may exceed ``contact_tolerance`` by rounding alone: far below a finger's accuracy
OVERLAP_ROUNDING = 1e-9
#: How close (in steps) a ratio of lengths or angles may fall short of a whole number of steps
#: and still count as it: float division of 0.29 / 0.01 gives 28.999999999999996
STEP_ROUNDING = 1e-9
#: Decimals an ``l_a`` of the scan is rounded to: ``la_max - k * la_step`` by floats misses the
#: intended value in the last digits (0.9 - 6 * 0.01 is 0.8400000000000001), and plans are
#: compared and printed by that value
LA_DECIMALS = 10


@dataclass(frozen=True)
class PlannerOptions:
    """Search settings. ``la_max`` defaults to 0.9, the largest value the paper used, which
    keeps the outer finger's pad on the top surface rather than over the far edge."""

    la_max: float = 0.9
    la_min: float = 0.05
    la_step: float = 0.01
    full_tilt: bool = False
    equation: str = "auto"
    hook_depth: float = 0.005  # m the inner finger's tip must reach behind the rim
    palm_margin: float = 0.010  # m kept between the rim and the palm (finger base)
    hold_share: float = 0.4  # of the hole's free room the inner finger must reach past H
    #: m the pad must have free on either side in the hole: for the error of the pose the Grasp
    #: steers by across the part (the hand-eye calibration's 1 mm and the camera's) and for the
    #: pad's turn in the hole in Align. Measured in the twin, with the exact pose as well: a
    #: 20 mm pad in a 21 mm hole closed past the rim in 10 of 10 Grasps, in a 22 mm hole the
    #: Align jammed it against the wall (force guard) in 7 of 10; 2 mm a side (the narrow tube)
    #: pivots 9 of 10.
    side_room: float = 0.0015
    alpha_margin: float = math.radians(2.0)  # rad kept inside the feasible set's edge
    approach_distance: float = 0.06  # m the fingers travel along their axis onto the part
    contact_tolerance: float = 0.001  # m a finger may cut into the part (it sets onto S and H)
    alpha_samples: int = 179  # 0.5 degree scan, then bisection at the edge
    beta_samples: int = 181  # 0.5 degree path samples; the final plan is re-checked at 0.25

    def __post_init__(self) -> None:
        check_la(self.la_max)
        check_la(self.la_min)
        if self.la_min > self.la_max:
            raise ValueError(f"la_min {self.la_min:g} exceeds la_max {self.la_max:g}")
        if not math.isfinite(self.alpha_margin) or not 0 <= self.alpha_margin < MAX_ALPHA_MARGIN:
            raise ValueError(
                f"alpha_margin must lie in [0, {MAX_ALPHA_MARGIN:g}) rad, got {self.alpha_margin:g}"
            )
        if not math.isfinite(self.hook_depth) or self.hook_depth < 0:
            raise ValueError(f"hook_depth must be >= 0 m, got {self.hook_depth:g}")
        if not math.isfinite(self.side_room) or self.side_room < 0:
            raise ValueError(f"side_room must be >= 0 m, got {self.side_room:g}")
        if not math.isfinite(self.hold_share) or not 0 <= self.hold_share <= 1:
            raise ValueError(f"hold_share must lie in [0, 1], got {self.hold_share:g}")
        if not 0 < self.la_step <= 1:
            raise ValueError(f"la_step must lie in (0, 1], got {self.la_step:g}")


@dataclass(frozen=True)
class PivotPlan:
    """The planner's answer for one part. Angles in rad, lengths in m."""

    part: str
    pivotable: bool
    reason: str
    l_a: float | None = None
    alpha: float | None = None
    alpha_min: float | None = None
    delta_m: float | None = None
    beta_required: float | None = None
    beta_stable_max: float | None = None
    opening_m: float | None = None
    alpha_hook: float | None = None
    reach_m: float | None = None  #: e_H, how far the inner finger reaches past H (m)
    frictions: Frictions = Frictions()
    gripper: Gripper = Gripper()

    @property
    def beta_ub(self) -> float | None:
        """Where balance is lost during the tilt (the paper's beta_ub), None if never."""
        if self.beta_stable_max is None or self.beta_stable_max >= HALF_PI - ANGLE_TOL:
            return None
        return self.beta_stable_max

    def to_json(self) -> dict[str, object]:
        return {
            "part": self.part,
            "pivotable": self.pivotable,
            "reason": self.reason,
            "l_a": self.l_a,
            "alpha": self.alpha,
            "alpha_deg": None if self.alpha is None else math.degrees(self.alpha),
            "alpha_min": self.alpha_min,
            "delta_m": self.delta_m,
            "beta_stable": None if self.beta_stable_max is None else [0.0, self.beta_stable_max],
            "beta_ub": self.beta_ub,
            "beta_required": self.beta_required,
            "opening_m": self.opening_m,
            "alpha_hook": self.alpha_hook,
            "reach_m": self.reach_m,
            "stroke_m": self.gripper.stroke,
            "finger_width_m": self.gripper.finger_width,
            "mu": {"S": self.frictions.mu_s, "H": self.frictions.mu_h, "G": self.frictions.mu_g},
        }


def reach_depth(section: Section, l_a: float, alpha: np.ndarray | float) -> np.ndarray | float:
    """``e_H``: how far the inner fingertip reaches past the rim contact H along the finger (m)."""
    l = 2.0 * section.a * l_a  # exact: l = 2 a l_a, the paper's definition of l_a
    return l * np.sin(alpha) - section.delta * np.cos(alpha)


def jaw_opening(section: Section, l_a: float, alpha: np.ndarray | float) -> np.ndarray | float:
    """Finger-face distance along the closing line at the grasp (m)."""
    l = 2.0 * section.a * l_a  # exact: l = 2 a l_a, the paper's definition of l_a
    return l * np.cos(alpha) + section.delta * np.sin(alpha)


def _finger(tip: np.ndarray, z: np.ndarray, back: np.ndarray, length: float) -> np.ndarray:
    """The finger's outline in the pivot plane: its pad-face tip, the back of the tip, then the
    same two at the palm (``length`` up the finger, against ``z``)."""
    return np.array([tip, tip + back, tip + back - length * z, tip - length * z])


def _swept_overlap(
    poly: np.ndarray, shift: np.ndarray, box: tuple[float, float, float, float]
) -> float:
    """How deep (m) the convex ``poly``, translated by ``shift`` along a straight line, cuts
    into the box ``(s0, s1, h0, h1)`` anywhere on the way: the smallest overlap over the
    separating axes of the swept shape (the hull of the two ends: the polygon's edges, the
    direction of travel) and the box's. 0 or less: apart."""
    s0, s1, h0, h1 = box
    corners = np.array([[s0, h0], [s1, h0], [s1, h1], [s0, h1]])
    swept = np.vstack([poly, poly + shift])
    edges = [poly[(i + 1) % len(poly)] - poly[i] for i in range(len(poly))] + [shift]
    axes = [np.array([1.0, 0.0]), np.array([0.0, 1.0])]
    for edge in edges:
        norm = float(np.hypot(*edge))
        if norm > LENGTH_ROUNDING:
            axes.append(np.array([-edge[1], edge[0]]) / norm)
    depth = math.inf
    for axis in axes:
        a, b = swept @ axis, corners @ axis
        depth = min(depth, min(a.max(), b.max()) - max(a.min(), b.min()))
    return float(depth)


def approach_problem(
    section: Section,
    l_a: float,
    alpha: float,
    gripper: Gripper = Gripper(),
    options: PlannerOptions = PlannerOptions(),
) -> str | None:
    """What the fingers meet on the way to the grasp at ``(l_a, alpha)``, or None when clear.

    In the pivot plane, ``s`` along the axis from the part's centre (open end at ``+a``) and
    ``h`` up from the floor: the outer fingertip ends on S ``= (a - l, 2b)``, the inner one
    ``opening`` from it along the closing line ``x = (-cos alpha, sin alpha)``, fingers along
    ``z = (-sin alpha, -cos alpha)``. The approach ends ``clearance`` wider (the outer finger on
    S, the inner one further out), comes ``approach_distance`` down ``z``, and the inner finger
    closes onto H.
    """
    a, b, delta = section.a, section.b, section.delta
    l = 2.0 * a * l_a  # exact: l = 2 a l_a, the paper's definition of l_a
    x = np.array([-math.cos(alpha), math.sin(alpha)])
    z = np.array([-math.sin(alpha), -math.cos(alpha)])
    length, thick = gripper.finger_length, gripper.finger_thickness
    outer_tip = np.array([a - l, 2.0 * b])  # exact: the top surface, the height D = 2b
    inner_tip = outer_tip - float(jaw_opening(section, l_a, alpha)) * x
    obstacles = {
        "the rim and the wall above the hole": (-a, a, 2.0 * b - delta, 2.0 * b),  # exact: D = 2b
        "the wall below the hole": (-a, a, 0.0, delta),
        "the floor": (-a - 1.0, a + 1.0, -1.0, 0.0),
    }
    tol = options.contact_tolerance
    down = options.approach_distance * z
    moves = (  # (finger, when, pad tip at the start, travel)
        ("outer", "on the way down onto S", outer_tip - down, down),
        ("inner", "on the way down", inner_tip - gripper.clearance * x - down, down),
        ("inner", "closing onto H", inner_tip - gripper.clearance * x, gripper.clearance * x),
    )
    for finger, when, tip, travel in moves:
        back = (thick if finger == "outer" else -thick) * x
        outline = _finger(tip, z, back, length)
        for what, box in obstacles.items():
            depth = _swept_overlap(outline, travel, box)
            if depth > tol + OVERLAP_ROUNDING:
                return (
                    f"approach blocked: the {finger} finger cuts {depth * 1e3:.1f} mm into "
                    f"{what} {when} (l_a {l_a:.2f}, alpha {math.degrees(alpha):.1f} deg)"
                )
    return None


def _run_starts(mask: np.ndarray, length: int) -> list[int]:
    """Indices where ``mask`` starts ``length`` consecutive True values, in order."""
    starts, run = [], 0
    for i, value in enumerate(mask):
        run = run + 1 if value else 0
        if run >= length:
            starts.append(i - length + 1)
            run = 0
    return starts


def hole_room(part: Part, finger_width: float) -> float:
    """m, the free height a finger of ``finger_width`` has in the hole along the pivot plane:
    the chord ``2x`` of Eq. 2 for a round hole, ``d`` for a rectangular one."""
    if part.hole_shape == "circle":
        return 2.0 * hole_offset(part.hole, finger_width)  # exact: the chord is 2x (Eq. 2)
    return part.hole


def hook_alpha(part: Part, finger_width: float, hook_depth: float) -> float:
    """Smallest alpha (rad) at which the inner finger's tip gets ``hook_depth`` behind the rim."""
    return math.atan2(hook_depth, hole_room(part, finger_width))


def plan_pivot(
    part: Part,
    gripper: Gripper = Gripper(),
    frictions: Frictions = Frictions(),
    options: PlannerOptions = PlannerOptions(),
) -> PivotPlan:
    """Plan the Grasp/Tilt for ``part``; a refusal carries the reason instead of numbers."""
    common = {"part": part.name, "frictions": frictions, "gripper": gripper}
    if not part.rigid:
        return PivotPlan(
            pivotable=False,
            reason="deformable part: the outer finger crushes the wall at S and the part slides "
            "at H (the paper's water bottle, 0/10)",
            **common,
        )
    if gripper.finger_width >= part.hole:
        return PivotPlan(
            pivotable=False,
            reason=f"hole narrower than the finger: d = {part.hole * 1e3:.1f} mm <= "
            f"w = {gripper.finger_width * 1e3:.1f} mm",
            **common,
        )
    side = 0.5 * (part.hole - gripper.finger_width)  # exact: the pad centred in the hole
    if side < options.side_room:
        return PivotPlan(
            pivotable=False,
            reason=f"the pad nearly fills the hole: the {gripper.finger_width * 1e3:.1f} mm pad "
            f"leaves {side * 1e3:.1f} mm on either side in the {part.hole * 1e3:.1f} mm hole, less "
            f"than the {options.side_room * 1e3:.1f} mm the pose's error across the part and the "
            f"pad's turn in the hole need",
            **common,
        )
    section = part.section(gripper.finger_width)
    beta_req = HALF_PI if options.full_tilt else min(HALF_PI, section.tip_angle)
    usable = gripper.stroke - gripper.clearance
    alpha_hook = hook_alpha(part, gripper.finger_width, options.hook_depth)
    reach_max = gripper.finger_length - options.palm_margin
    reach_min = options.hold_share * hole_room(part, gripper.finger_width)
    alphas = alpha_axis(options.alpha_samples)
    n_la = int(math.floor((options.la_max - options.la_min) / options.la_step + STEP_ROUNDING)) + 1
    stable_somewhere = False
    approach_blocked: str | None = None  #: the last plan passed over for its approach
    margin_steps = int(math.ceil(options.alpha_margin / (alphas[1] - alphas[0]) - STEP_ROUNDING))
    for la in options.la_max - options.la_step * np.arange(n_la):
        la = float(round(la, LA_DECIMALS))

        def feasible(al: np.ndarray, la: float = la) -> tuple[np.ndarray, np.ndarray]:
            """(stable and fits the stroke and hooks the hole, stable) for each alpha."""
            ok = tilt_ok_mask(
                section, la, al, frictions, beta_req, options.equation, options.beta_samples
            )
            fits = (jaw_opening(section, la, al) <= usable + LENGTH_ROUNDING) & (al >= alpha_hook)
            reach = reach_depth(section, la, al)
            fits &= (reach <= reach_max + LENGTH_ROUNDING) & (
                reach >= reach_min - LENGTH_ROUNDING
            )
            return ok & fits, ok

        both, ok = feasible(alphas)
        stable_somewhere |= bool(ok.any())
        for first in _run_starts(both, margin_steps + 1):
            # The approach first (cheap): a run whose start is blocked is passed over before
            # its edge is refined.
            blocked = approach_problem(
                section, la, float(alphas[first]) + options.alpha_margin, gripper, options
            )
            if blocked is not None:
                approach_blocked = blocked
                continue
            # The edge of the feasible set, refined by bisection, then the margin inside it.
            alpha_min = float(alphas[first])
            if first > 0 and not both[first - 1]:
                alpha_min = bisect_edge(
                    lambda a: bool(feasible(np.array([a]))[0][0]),
                    alpha_min,
                    float(alphas[first - 1]),
                )
            alpha = alpha_min + options.alpha_margin
            end = stable_beta_max(section, la, alpha, frictions, options.equation)
            if end is None or end < beta_req - ANGLE_TOL:  # a sliver the scan stepped over
                continue
            blocked = approach_problem(section, la, alpha, gripper, options)
            if blocked is not None:
                approach_blocked = blocked
                continue
            return PivotPlan(
                pivotable=True,
                reason="ok",
                l_a=la,
                alpha=alpha,
                alpha_min=alpha_min,
                delta_m=section.delta,
                beta_required=beta_req,
                beta_stable_max=end,
                opening_m=float(jaw_opening(section, la, alpha)),
                alpha_hook=alpha_hook,
                reach_m=float(reach_depth(section, la, alpha)),
                **common,
            )
    if approach_blocked is not None:
        reason = (
            f"{approach_blocked}; every other stable (l_a, alpha) that fits the stroke and "
            f"reaches {reach_min * 1e3:.0f} mm past the rim is blocked too"
        )
    elif stable_somewhere:
        reason = (
            f"stroke too short: every stable (l_a, alpha) with alpha >= "
            f"{math.degrees(alpha_hook):.1f} deg (to hook the hole) needs a jaw opening above "
            f"{usable * 1e3:.0f} mm (stroke {gripper.stroke * 1e3:.0f} mm less "
            f"{gripper.clearance * 1e3:.0f} mm approach clearance), a finger longer than "
            f"{gripper.finger_length * 1e3:.0f} mm or one that reaches less than "
            f"{reach_min * 1e3:.0f} mm past the rim"
        )
    else:
        reason = (
            f"no stable path: no l_a in [{options.la_min:g}, {options.la_max:g}] and alpha in "
            f"(0, 90) deg keeps force balance from beta = 0 to "
            f"{math.degrees(beta_req):.1f} deg with mu_S={frictions.mu_s:g}, "
            f"mu_H={frictions.mu_h:g}, mu_G={frictions.mu_g:g}"
        )
    return PivotPlan(
        pivotable=False,
        reason=reason,
        delta_m=section.delta,
        beta_required=beta_req,
        alpha_hook=alpha_hook,
        **common,
    )
