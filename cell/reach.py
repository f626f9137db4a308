"""The UR5's reach in the form the skills' planning asks for it
(:data:`skills.pivot.clearance.Reach`).

Skills know no particular arm; the cell knows it drives a UR5 and hands the skills this check,
built on the arm's own kinematics (:mod:`drivers.ur5.kinematics`: the chain the twin's arm runs
and the hardware's reach check uses), so a plan is made for the arm that will carry it out.

Why from the joints the arm is at, and along the way: a UR5 has up to eight joint solutions
for one TCP pose, and a linear move or a servo stream keeps the branch it starts on. A pose
solved from home may land on a branch the arm, coming from where it stands, never reaches --
or reach a pose the arm's own branch runs into a joint limit on the way to. So the check
starts at the joints the arm reports and follows the TCP along straight lines between the
poses in steps of :data:`REACH_STEP` (and :data:`REACH_TURN`), each solved from the last, as a
moveL or a servo stream does.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from drivers.pose import Pose
from drivers.ur5.kinematics import HOME_JOINTS, REACH_TOLERANCE, forward_kinematics, solve_ik

#: m of TCP travel between two poses the check solves on the way (a step the DLS solve follows
#: on the branch it starts on; the twin's arm and a UR track far finer)
REACH_STEP = 0.03
#: rad of tool rotation between two poses the check solves on the way
REACH_TURN = math.radians(10.0)
#: DLS iterations per solve; a step of REACH_STEP from the last solution converges in a few
REACH_ITERATIONS = 60


def ur5_reach(poses: Sequence[Pose]) -> int | None:
    """The index of the first of ``poses`` the UR5 cannot reach at all, or None: each pose
    solved from the joints of the one before, starting at home. For fixtures and places,
    whichever branch reaches them; a plan the arm is to carry out from where it stands is
    checked by :func:`ur5_reach_along`."""
    q = HOME_JOINTS
    for i, pose in enumerate(poses):
        q, miss = solve_ik(pose, q, iterations=200)
        if miss > REACH_TOLERANCE:
            return i
    return None


def ur5_reach_along(poses: Sequence[Pose], start: ArrayLike) -> int | None:
    """The index of the first of ``poses`` the UR5 cannot reach from the joints ``start``
    (rad), or None. The TCP is followed from there through each pose in turn along straight
    lines (position) and slerps (rotation), so the check keeps the branch the arm keeps."""
    q = np.asarray(start, float)
    here = forward_kinematics(q)
    for i, pose in enumerate(poses):
        distance, angle = here.distance(pose)
        steps = max(1, math.ceil(max(distance / REACH_STEP, angle / REACH_TURN)))
        for k in range(1, steps + 1):
            q, miss = solve_ik(here.interpolate(pose, k / steps), q, iterations=REACH_ITERATIONS)
            if miss > REACH_TOLERANCE:
                return i
        here = pose
    return None


def reach_from(joints: Callable[[], ArrayLike]) -> Callable[[Sequence[Pose]], int | None]:
    """:func:`ur5_reach_along` from the joints ``joints()`` reports when the check is made (the
    arm's :meth:`~drivers.arm.Arm.joint_positions`): a plan is checked from where the arm
    stands when it is made, not from home."""

    def reach(poses: Sequence[Pose]) -> int | None:
        return ur5_reach_along(poses, joints())

    return reach


__all__ = ["REACH_STEP", "REACH_TURN", "reach_from", "ur5_reach", "ur5_reach_along"]
