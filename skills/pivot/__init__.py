"""The paper's maneuver as step-wise skills: Grasp, Tilt, Align (Sec. III-C, Fig. 10)."""

from skills.pivot.align import Align
from skills.pivot.frame import PivotFrame
from skills.pivot.grasp import Grasp
from skills.pivot.params import PivotParams
from skills.pivot.tilt import Tilt

__all__ = ["Align", "Grasp", "PivotFrame", "PivotParams", "Tilt"]
