"""The paper's planar pivot mechanics (Sec. II-III): contact wrenches, force balance, regions,
and the per-part planner that turns a part's geometry into ``(l_a, alpha)``."""

from skills.mechanics.contact import Frictions, Section, contact_wrenches
from skills.mechanics.part import Gripper, Part
from skills.mechanics.planner import PivotPlan, PlannerOptions, plan_pivot

__all__ = [
    "Frictions",
    "Gripper",
    "Part",
    "PivotPlan",
    "PlannerOptions",
    "Section",
    "contact_wrenches",
    "plan_pivot",
]
