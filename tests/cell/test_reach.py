"""The UR5's reach as the plans get it: from the joints the arm is at, along the way."""

from __future__ import annotations

import math

import numpy as np

from cell.reach import reach_from, reach_from_or_home, ur5_reach, ur5_reach_along
from drivers.pose import Pose, rot_z
from drivers.ur5.kinematics import ARM_LIMIT, HOME_JOINTS, forward_kinematics


def _turned(q: np.ndarray, angle: float) -> Pose:
    """The TCP pose at ``q`` turned by ``angle`` about the tool's own z axis."""
    here = forward_kinematics(q)
    return Pose(here.position, here.rotation @ rot_z(angle))


def test_reaches_what_home_reaches_along_the_way() -> None:
    home = forward_kinematics(HOME_JOINTS)
    near = Pose(home.position + np.array([0.05, -0.2, -0.15]), home.rotation)
    assert ur5_reach_along([near, home], HOME_JOINTS) is None
    assert ur5_reach([near, home]) is None


def test_out_of_reach_is_named_by_index() -> None:
    home = forward_kinematics(HOME_JOINTS)
    far = Pose(np.array([1.3, 0.0, 0.1]), home.rotation)
    assert ur5_reach_along([home, far], HOME_JOINTS) == 1
    assert ur5_reach([home, far]) == 1


def test_a_wound_up_wrist_cannot_turn_on_though_home_reaches_the_pose() -> None:
    """A wrist 3 a few degrees short of its +2 pi limit cannot turn the tool on by 30 deg:
    the arm's own branch runs into the limit, while a solve from home finds the pose on
    another turn of the wrist. The check must say what the arm can do from where it is."""
    q = HOME_JOINTS.copy()
    q[5] = ARM_LIMIT - math.radians(3.0)
    for sign in (1.0, -1.0):
        target = _turned(q, sign * math.radians(30.0))
        blocked = ur5_reach_along([target], q)
        if blocked is not None:
            break
    assert blocked == 0
    assert ur5_reach([target]) is None
    # the other way round the wrist has room: reached from the same joints
    assert ur5_reach_along([_turned(q, -sign * math.radians(30.0))], q) is None


def test_reach_from_reads_the_joints_when_asked() -> None:
    joints = {"q": HOME_JOINTS.copy()}
    reach = reach_from(lambda: joints["q"])
    wound = HOME_JOINTS.copy()
    wound[5] = ARM_LIMIT - math.radians(3.0)
    turned = [_turned(wound, math.radians(30.0)), _turned(wound, -math.radians(30.0))]
    assert all(reach([pose]) is None for pose in turned)  # from home: either way
    joints["q"] = wound
    assert any(reach([pose]) == 0 for pose in turned)  # from the wound-up wrist: one is not


def test_reach_from_or_home_takes_what_a_joint_move_home_makes_reachable() -> None:
    """The wound-up wrist's blocked turn is reachable after a moveJ home: the planner's reach
    says so, the straight reach from here does not (the grasp then goes home first)."""
    wound = HOME_JOINTS.copy()
    wound[5] = ARM_LIMIT - math.radians(3.0)
    turned = [_turned(wound, math.radians(30.0)), _turned(wound, -math.radians(30.0))]
    here = reach_from(lambda: wound)
    either = reach_from_or_home(lambda: wound, HOME_JOINTS)
    blocked = [pose for pose in turned if here([pose]) is not None]
    assert blocked
    assert all(either([pose]) is None for pose in blocked)
    # beyond the arm's reach from anywhere stays out of reach
    far = Pose(np.array([1.3, 0.0, 0.1]), turned[0].rotation)
    assert either([far]) == 0
