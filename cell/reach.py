"""The UR5's reach in the form the skills' planning asks for it
(:data:`skills.pivot.clearance.Reach`).

Skills know no particular arm; the cell knows it drives a UR5 and hands the skills this check,
built on the arm's own kinematics (:mod:`drivers.ur5.kinematics`: the chain the twin's arm runs
and the hardware's reach check uses), so a plan is made for the arm that will carry it out.
"""

from __future__ import annotations

from collections.abc import Sequence

from drivers.pose import Pose
from drivers.ur5.kinematics import HOME_JOINTS, REACH_TOLERANCE, solve_ik


def ur5_reach(poses: Sequence[Pose]) -> int | None:
    """The index of the first of ``poses`` the UR5 cannot reach, or None: each pose solved from
    the joints of the one before, starting at home (poses along one motion have nearby
    solutions; solving each from home might land on another branch)."""
    q = HOME_JOINTS
    for i, pose in enumerate(poses):
        q, miss = solve_ik(pose, q, iterations=200)
        if miss > REACH_TOLERANCE:
            return i
    return None


__all__ = ["ur5_reach"]
