"""Travel between fixtures by a joint move (UR ``moveJ``) where its swept path is as clear as
the straight one.

Why: a Cartesian travel path is slow where the tool turns. Feeding the slot and packing turn the
wrist by up to 180 deg between the bin, the machine and the box; a straight TCP line timed by
the TCP speed bounds the turn by that speed too, and faster lines ran the UR5's wrist into its
joint speed limit. A joint move drives every joint to its goal at a joint speed the arm allows,
so the turn costs no more than the longest joint's travel. What it gives up is the straight
line: the TCP sweeps a curve. So a joint move is only made when that curve is checked, before
the move starts, against what kept the straight path clear: the TCP never below the lower end
of the leg (the travel height was chosen to clear every fixture there), the tool never tilted
more than at either end (a held part hangs no lower), and never nearer the base axis than the
straight path's limit. Where the check fails, or the arm's kinematics are not known to the
skills, the Cartesian path is used as before.

The rise to the travel height stays a straight vertical move: the joint move starts at that
height, so a part still inside the bin (or the slot) never moves sideways.

The arm's kinematics come from the cell (:class:`ArmModel`, a UR5's in the shipped cell): skills
know no particular arm.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.pose import Pose
from skills.axes import XY, Z

#: rad of the joint that moves most between two poses the swept path is checked at: the TCP,
#: at most about 1 m from the base, moves under 18 mm between two checks
JOINT_CHECK_STEP = math.radians(1.0)
#: m the TCP may dip below the leg's lower end between checks and in the solve's residual
#: (numerical: the straight path itself is followed to a fraction of it)
HEIGHT_SLACK = 0.001
#: m the start may lie below the target and still count as risen to its height: a move is
#: reported done within about a millimetre of its goal (the twin's 1 mm), so a rise to the
#: travel height can end that much short of it
RISEN_SLACK = 0.005
#: rad the tool may tilt more than at either end (numerical, the slerp's own rounding)
TILT_SLACK = math.radians(0.5)


@dataclass(frozen=True)
class ArmModel:
    """The arm's kinematics as the skills use them, handed in by the cell."""

    #: joints (rad) putting the TCP at the pose, on the branch of the joints given (the ones the
    #: arm is at), or None where the arm does not reach it from there
    solve: Callable[[Pose, NDArray[np.float64]], NDArray[np.float64] | None]
    #: the TCP pose (base frame) at the joints given
    forward: Callable[[NDArray[np.float64]], Pose]


def _tilt(pose: Pose) -> float:
    """Angle (rad) between the tool's z axis and straight down."""
    return math.acos(float(np.clip(-pose.rotation[Z, Z], -1.0, 1.0)))


def swept_problem(
    model: ArmModel, q_start: ArrayLike, q_goal: ArrayLike, min_radius: float
) -> str | None:
    """Why the joint move from ``q_start`` to ``q_goal`` (rad) is not as clear as a straight
    travel leg between its ends, or None: the TCP along the joints' straight line is checked
    every :data:`JOINT_CHECK_STEP` of the joint moving most."""
    q0, q1 = np.asarray(q_start, float), np.asarray(q_goal, float)
    a, b = model.forward(q0), model.forward(q1)
    lowest = min(a.position[Z], b.position[Z]) - HEIGHT_SLACK
    tilt = max(_tilt(a), _tilt(b)) + TILT_SLACK
    radius = min(min_radius, *(float(np.linalg.norm(p.position[XY])) for p in (a, b)))
    steps = max(1, math.ceil(float(np.max(np.abs(q1 - q0))) / JOINT_CHECK_STEP))
    for k in range(1, steps):
        pose = model.forward(q0 + (k / steps) * (q1 - q0))
        if pose.position[Z] < lowest:
            return f"the TCP would pass {1e3 * (lowest - pose.position[Z]):.0f} mm below the leg"
        if _tilt(pose) > tilt:
            return f"the tool would tilt {math.degrees(_tilt(pose) - tilt):.1f} deg more"
        if float(np.linalg.norm(pose.position[XY])) < radius:
            return "the TCP would pass nearer the base axis than the straight path may"
    return None


def joint_goal(
    model: ArmModel | None, q_start: ArrayLike, target: Pose, min_radius: float,
    rise_first: bool = True,
) -> NDArray[np.float64] | None:
    """The joints to move to ``target`` by a joint move from ``q_start``, or None where a joint
    move must not be made (no model, a start below the target while ``rise_first``, out of
    reach from there, or its swept path not clear). ``rise_first`` False: the start is above
    every fixture already (an empty hand at a camera's view, or clear above the part it just
    let go), so the move may rise as it goes, never below its start."""
    if model is None:
        return None
    q0 = np.asarray(q_start, float)
    if rise_first and model.forward(q0).position[Z] < target.position[Z] - RISEN_SLACK:
        return None  # the rise comes first, straight up: a joint move would also go sideways
    q1 = model.solve(target, q0)
    if q1 is None or swept_problem(model, q0, q1, min_radius) is not None:
        return None
    return q1


__all__ = ["ArmModel", "joint_goal", "swept_problem"]
