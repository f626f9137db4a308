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

#: rad of the joint that moves most between two poses the swept path is checked at (the TCP
#: of a UR5 moved at most 13 mm between two checks over the cell's travels)
JOINT_CHECK_STEP = math.radians(1.0)
#: m the TCP may dip below the leg's lower end between checks and in the solve's residual
#: (numerical: the straight path itself is followed to a fraction of it)
HEIGHT_SLACK = 0.001
#: m the start may lie below the target and still count as risen to its height: a move is
#: reported done within about a millimetre of its goal (the twin's 1 mm), so a rise to the
#: travel height can end that much short of it, and the sweep is then allowed that much lower
#: than the straight path's travel height (the travel height's own margin takes it)
RISEN_SLACK = 0.005
#: rad the tool may tilt more than at either end (numerical, the slerp's own rounding)
TILT_SLACK = math.radians(0.5)


@dataclass(frozen=True)
class ArmModel:
    """The arm's kinematics as the skills use them, handed in by the cell."""

    #: joints (rad) putting the TCP at the pose, on the branch of the joints given (the ones the
    #: arm is at: elbow and wrist on the same side), or None where the arm does not reach it
    #: from there without changing branch (a change swings the forearm and wrist through room
    #: that only the TCP's check would not see)
    solve: Callable[[Pose, NDArray[np.float64]], NDArray[np.float64] | None]
    #: the TCP pose (base frame) at the joints given
    forward: Callable[[NDArray[np.float64]], Pose]


@dataclass(frozen=True)
class JointMove:
    """A joint move found clear: its goal and how fast its TCP goes for the joints' speed."""

    goal: NDArray[np.float64]  #: rad
    #: m of TCP travel per rad of the joint moving most, the largest along the sweep: the
    #: TCP's peak speed is this times that joint's speed
    tcp_per_rad: float

    def joint_speed(self, joint_speed: float, tcp_speed: float) -> float:
        """The joint speed (rad/s) at most ``joint_speed`` that keeps the TCP at or under
        ``tcp_speed`` (m/s) all along the sweep."""
        if self.tcp_per_rad <= 0:
            return joint_speed
        return min(joint_speed, tcp_speed / self.tcp_per_rad)


def _tilt(pose: Pose) -> float:
    """Angle (rad) between the tool's z axis and straight down."""
    return math.acos(float(np.clip(-pose.rotation[Z, Z], -1.0, 1.0)))


def sweep(
    model: ArmModel, q_start: ArrayLike, q_goal: ArrayLike, min_radius: float
) -> tuple[str | None, float]:
    """Why the joint move from ``q_start`` to ``q_goal`` (rad) is not as clear as a straight
    travel leg between its ends (None: it is), and :attr:`JointMove.tcp_per_rad`. The TCP
    along the joints' straight line is checked every :data:`JOINT_CHECK_STEP` of the joint
    moving most: never below the lower end, never tilted more than at either end, never nearer
    the base axis than the straight path may pass."""
    q0, q1 = np.asarray(q_start, float), np.asarray(q_goal, float)
    a, b = model.forward(q0), model.forward(q1)
    lowest = min(a.position[Z], b.position[Z]) - HEIGHT_SLACK
    tilt = max(_tilt(a), _tilt(b)) + TILT_SLACK
    radius = min(min_radius, *(float(np.linalg.norm(p.position[XY])) for p in (a, b)))
    span = float(np.max(np.abs(q1 - q0)))
    steps = max(1, math.ceil(span / JOINT_CHECK_STEP))
    per_rad, last = 0.0, a.position
    for k in range(1, steps + 1):
        pose = b if k == steps else model.forward(q0 + (k / steps) * (q1 - q0))
        per_rad = max(per_rad, float(np.linalg.norm(pose.position - last)) * steps / span)
        last = pose.position
        if k == steps:
            break
        if pose.position[Z] < lowest:
            dip = lowest - pose.position[Z]
            return f"the TCP would pass {dip:.3f} m below the leg", 0.0
        if _tilt(pose) > tilt:
            return f"the tool would tilt {math.degrees(_tilt(pose) - tilt):.1f} deg more", 0.0
        if float(np.linalg.norm(pose.position[XY])) < radius:
            return "the TCP would pass nearer the base axis than the straight path may", 0.0
    return None, per_rad


def joint_goal(
    model: ArmModel | None, q_start: ArrayLike, target: Pose, min_radius: float,
    rise_first: bool = True,
) -> JointMove | None:
    """The joint move to ``target`` from ``q_start``, or None where a joint move must not be
    made (no model, a start below the target while ``rise_first``, out of reach from there on
    the arm's branch, or its swept path not clear). ``rise_first`` False: the start is above
    every fixture already (an empty hand at a camera's view, or clear above the part it just
    let go), so the move may rise as it goes, never below the lower of its ends.

    What the check does not see: fixtures beside the straight path. The sweep is an arc about
    the base, up to about 0.2 m aside from the straight path in this cell, at or above the
    travel height: that height must clear every fixture the arm travels over, not only those
    under the straight line (the configuration's ``travel_z_m`` says so)."""
    if model is None:
        return None
    q0 = np.asarray(q_start, float)
    if rise_first and model.forward(q0).position[Z] < target.position[Z] - RISEN_SLACK:
        return None  # the rise comes first, straight up: a joint move would also go sideways
    q1 = model.solve(target, q0)
    if q1 is None:
        return None
    problem, per_rad = sweep(model, q0, q1, min_radius)
    return None if problem is not None else JointMove(q1, per_rad)


__all__ = ["ArmModel", "JointMove", "joint_goal", "sweep"]
