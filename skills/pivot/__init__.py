"""The paper's maneuver as step-wise skills: Grasp, Tilt, Align (Sec. III-C, Fig. 10), and the
recovery (PickFromAbove) run only when the in-hand Align failed."""

from skills.pivot.align import Align
from skills.pivot.frame import PivotFrame
from skills.pivot.grasp import Grasp
from skills.pivot.params import PivotParams
from skills.pivot.recover import PickFromAbove, PickStanding, plan_standing_pick
from skills.pivot.tilt import Tilt

__all__ = [
    "Align",
    "Grasp",
    "PivotFrame",
    "PickFromAbove",
    "PickStanding",
    "PivotParams",
    "Tilt",
    "plan_standing_pick",
]
