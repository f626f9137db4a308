"""The paper's planar pivot mechanics (Sec. II-III): contact wrenches, force balance, regions,
and the per-part planner that turns a part's geometry into ``(l_a, alpha)``. The part and gripper
geometry they work on is :mod:`drivers.parts`."""

from skills.mechanics.contact import Frictions, contact_wrenches
from skills.mechanics.planner import PivotPlan, PlannerOptions, plan_pivot

__all__ = [
    "Frictions",
    "PivotPlan",
    "PlannerOptions",
    "contact_wrenches",
    "plan_pivot",
]
