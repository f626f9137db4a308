"""The UR5's reach in the form the skills' planning asks for it
(:data:`skills.pivot.clearance.Reach`).

Skills know no particular arm; the cell knows it drives a UR5 and hands the skills this check,
built on the arm's own kinematics (:mod:`drivers.ur5.kinematics`: the chain the twin's arm runs
and the hardware's reach check uses), so a plan is made for the arm that will carry it out.

Why from the joints the arm is at, and along the way: a UR5 has up to eight joint solutions
for one TCP pose, and a linear move or a servo stream keeps the branch it starts on. A pose
solved from home may land on a branch the arm, coming from where it stands, never reaches --
or reach a pose the arm's own branch runs into a joint limit on the way to. So the check
starts at the joints the arm reports and follows the TCP along a straight line to the first
pose in steps of :data:`REACH_STEP` (and :data:`REACH_TURN`), each solved from the last, as
a moveL does.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.pose import Pose
from drivers.ur5.kinematics import (
    ARM_LIMIT,
    HOME_JOINTS,
    REACH_TOLERANCE,
    forward_kinematics,
    solve_ik,
)
from skills.travel import ArmModel

#: m of TCP travel between two poses the check solves on the way to the first pose (a step the
#: DLS solve follows on the branch it starts on; the twin's arm and a UR track far finer)
REACH_STEP = 0.05
#: rad of tool rotation between two poses the check solves on the way to the first pose
REACH_TURN = math.radians(15.0)
#: DLS iterations per solve on the way; a step from the last solution converges in a few
REACH_ITERATIONS = 30
#: DLS iterations for a pose itself
DIRECT_ITERATIONS = 200
#: m (and m per rad of turn, as the solve's residual counts it) a joint move's goal may miss its
#: pose by: the moves after it start from there, the packing's reading of the hanging part and
#: the slot's view among them (the solve reaches about 1e-9)
JOINT_GOAL_TOLERANCE = 1e-4
#: the joints whose whole turns :func:`ur5_model` may drop: the base and the three wrists
WRAPPED_JOINTS = (0, 3, 4, 5)


def _first_unreached(poses: Sequence[Pose], q: NDArray[np.float64]) -> int | None:
    """The index of the first of ``poses`` not reached solving each from the joints of the one
    before, starting at ``q``, or None."""
    for i, pose in enumerate(poses):
        q, miss = solve_ik(pose, q, iterations=DIRECT_ITERATIONS)
        if miss > REACH_TOLERANCE:
            return i
    return None


def ur5_reach(poses: Sequence[Pose]) -> int | None:
    """The index of the first of ``poses`` the UR5 cannot reach at all, or None: each pose
    solved from the joints of the one before, starting at home. For fixtures and places,
    whichever branch reaches them; a plan the arm is to carry out from where it stands is
    checked by :func:`ur5_reach_along`."""
    return _first_unreached(poses, HOME_JOINTS)


def ur5_reach_along(poses: Sequence[Pose], start: ArrayLike) -> int | None:
    """The index of the first of ``poses`` the UR5 cannot reach from the joints ``start``
    (rad), or None. The TCP is followed from there to the first pose along a straight line
    (position) and a slerp (rotation), so the check takes the branch the arm keeps; the poses
    after it, each near the one before (a plan's approach, grasp and arc), are solved each from
    the last, as :func:`ur5_reach` does. Following every leg cost ten times as much, and the
    planner checks dozens of plans in one tick."""
    q = np.asarray(start, float)
    if poses:
        here, first = forward_kinematics(q), poses[0]
        distance, angle = here.distance(first)
        steps = max(1, math.ceil(max(distance / REACH_STEP, angle / REACH_TURN)))
        for k in range(1, steps):
            q, _ = solve_ik(here.interpolate(first, k / steps), q, iterations=REACH_ITERATIONS)
    return _first_unreached(poses, q)


def reach_from(joints: Callable[[], ArrayLike]) -> Callable[[Sequence[Pose]], int | None]:
    """:func:`ur5_reach_along` from the joints ``joints()`` reports when the check is made (the
    arm's :meth:`~drivers.arm.Arm.joint_positions`): a plan is checked from where the arm
    stands when it is made, not from home."""

    def reach(poses: Sequence[Pose]) -> int | None:
        return ur5_reach_along(poses, joints())

    return reach


def reach_from_or_home(
    joints: Callable[[], ArrayLike], home: ArrayLike
) -> Callable[[Sequence[Pose]], int | None]:
    """:func:`reach_from`, or else from ``home`` (rad): what a planner may choose when the
    arm can go home first by a joint move (a UR's moveJ follows no straight line, so it gets
    there from any configuration). The skill that carries the plan out checks
    :func:`reach_from` again and goes home first where only home reaches it."""
    here = reach_from(joints)
    q_home = np.asarray(home, float)

    def reach(poses: Sequence[Pose]) -> int | None:
        out = here(poses)
        return out if out is None else ur5_reach_along(poses, q_home)

    return reach


def _bearing(position: NDArray[np.float64]) -> float:
    return math.atan2(position[1], position[0])


def _turned(q: NDArray[np.float64], pose: Pose) -> NDArray[np.float64]:
    """``q`` with the base turned so that its TCP has ``pose``'s bearing about the base axis."""
    turn = _bearing(pose.position) - _bearing(forward_kinematics(q).position)
    seed = q.copy()
    seed[0] += (turn + math.pi) % math.tau - math.pi
    return seed


def _branch(q: NDArray[np.float64]) -> tuple[bool, bool]:
    """Which side the elbow and the wrist are on (the signs of sin of joints 3 and 5): a UR5's
    branches that a joint move between would fold the forearm or flip the wrist."""
    return bool(math.sin(q[2]) >= 0.0), bool(math.sin(q[4]) >= 0.0)


def _ur5_joints_for(pose: Pose, q: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """The UR5's joints at ``pose`` for a joint move from ``q`` (rad), on ``q``'s branch,
    or None. Seeds, in turn: ``q`` with the base turned to the pose's bearing (from ``q``
    itself a pose far round the base is solved across the TCP's straight line, which
    passes near the base axis, singular there, and the solve missed); ``q``."""
    for seed in (_turned(q, pose), q):
        goal, miss = solve_ik(pose, seed, iterations=DIRECT_ITERATIONS)
        if miss > JOINT_GOAL_TOLERANCE or _branch(goal) != _branch(q):
            continue
        # The base and the wrists turn +-360 deg: the same pose a whole turn nearer is
        # the shorter joint move (the solve turned the wrist 190-200 deg for 160-170).
        # Not the shoulder and elbow: a turn there folds the arm through itself.
        nearer = goal.copy()
        for j in WRAPPED_JOINTS:
            turned = goal[j] - round((goal[j] - q[j]) / math.tau) * math.tau
            if abs(turned) <= ARM_LIMIT:
                nearer[j] = turned
        return nearer
    return None


#: The UR5's kinematics as the skills take them, for travelling by a joint move.
UR5_MODEL = ArmModel(solve=_ur5_joints_for, forward=forward_kinematics)


__all__ = [
    "REACH_STEP", "REACH_TURN", "UR5_MODEL", "reach_from", "reach_from_or_home", "ur5_reach",
    "ur5_reach_along",
]
