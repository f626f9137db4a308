"""The tool on the arm's flange as the cell models it: the FT300 puck, the 2F-85's body and its
fingers, stacked along the flange's z axis (m).

Why a module of its own, beside the drivers: the arm's kinematics put the TCP at the end of this
stack, the twin builds its tool's links from it, and the skills sweep a model of the same tool
past the bin's walls -- and skills see no real driver. One set of numbers here keeps the TCP,
the twin and the planned sweeps in agreement; the planner's gripper model
(:class:`drivers.parts.Gripper`) takes its finger length from here too.

Tool axes: z out of the flange towards the fingertips, x the closing axis.
"""

from __future__ import annotations

from drivers.gripper_spec import default_gripper

FT_HEIGHT = 0.0375  #: the FT300 puck
FT_RADIUS = 0.0375  #: the FT300 puck's cylinder
GRIPPER_BODY_HEIGHT = 0.090  #: the 2F-85's body, from the puck to where the fingers leave it
#: the 2F-85's body as a box: x (closing axis), y, z (approach)
GRIPPER_BODY_SIZE = (0.075, 0.035, GRIPPER_BODY_HEIGHT)
FINGER_LENGTH = 0.055  #: the fingers, hanging below the gripper body fully open
#: The arm above the flange that a tool's sweep must clear too, as a box (x, y, z; z from the
#: flange up): the UR5's wrist 3 and the end of wrist 2 (their links are 75 mm across; a margin
#: each side)
WRIST_SIZE = (0.09, 0.09, 0.10)
FINGER_BASE_Z = FT_HEIGHT + GRIPPER_BODY_HEIGHT  #: where the fingers leave the body
#: How far the tips advance from fully open to closed (the 2F-85's linkage, 13.2 mm): the
#: fingers hang ``FINGER_LENGTH`` below the body open and this much more closed.
TIP_TRAVEL = default_gripper().tip_advance(0.0) - default_gripper().tip_advance(
    default_gripper().stroke
)
FINGER_TIP_Z = FINGER_BASE_Z + FINGER_LENGTH + TIP_TRAVEL  #: the tips, fingers closed
#: TCP offset from the flange along tool z (m): 5 mm above the fingertips' end, fingers closed
#: (at wider openings the tips sit higher: :meth:`drivers.gripper.Gripper.tip_advance`).
TCP_Z = FINGER_TIP_Z - 0.005

__all__ = [
    "FINGER_BASE_Z",
    "FINGER_LENGTH",
    "FINGER_TIP_Z",
    "FT_HEIGHT",
    "FT_RADIUS",
    "GRIPPER_BODY_HEIGHT",
    "GRIPPER_BODY_SIZE",
    "TCP_Z",
    "TIP_TRAVEL",
    "WRIST_SIZE",
]
