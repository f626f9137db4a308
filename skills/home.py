"""The cell's plain moves: home, and putting a failed pick back. Skills like the others, so their
speeds and limits come from the configuration (``skills.go_home``, ``skills.put_back``) and the
tree node's guard, never from a behaviour."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from drivers.devices import Devices
from drivers.pose import Pose
from skills.motion import Guard, Sequence
from skills.params import guard_field, si

#: rad in one degree (exact: a half turn is 180 degrees), for the ranges written in degrees
DEG = math.pi / 180.0


@dataclass(frozen=True)
class HomeParams:
    """A joint move to the home joints: it also unwinds the wrist that Cartesian moves wind up
    (a straight TCP line that keeps the tool's yaw turns the last joint towards its limit)."""

    joint_speed: float = si(1.0, "rad/s", 3.0 * DEG, 180.0 * DEG, "of the joints on the way home")
    joint_acceleration: float = si(
        2.0, "rad/s^2", 6.0 * DEG, 600.0 * DEG, "of the joints on the way home"
    )
    guard: Guard = field(default_factory=Guard)


@dataclass(frozen=True)
class PutBackParams:
    rise: float = si(0.10, "m", 0.0, 0.3, "up, jaws open, before going home")
    rise_speed: float = si(0.1, "m/s", 0.01, 0.5, "of the TCP rising")
    rise_acceleration: float = si(0.5, "m/s^2", 0.05, 3.0, "of the TCP rising")
    #: The opening and the rise run under the node's limits (high in the shipped tree: after an
    #: abort the fingers may still press hard on the part, and rising out of a part wedged
    #: against a neighbour or a wall drags them along it: measured 97 N in a bin tipped full);
    #: the way home, clear of the bin, does not need them.
    guard: Guard = field(default_factory=Guard)
    move_guard: Guard = guard_field(80.0, 10.0, "the way home after the rise")


def go_home(dev: Devices, home_joints: ArrayLike, params: HomeParams) -> Sequence:
    joints = np.asarray(home_joints, float)
    g = params.guard
    return Sequence(
        "go home",
        [
            dev.move(
                "home",
                g,
                lambda: dev.arm.move_joints(joints, params.joint_speed, params.joint_acceleration),
            )
        ],
    )


def put_back(
    dev: Devices, home_joints: ArrayLike, params: PutBackParams, home: HomeParams
) -> Sequence:
    """Open the jaws (the part stays in the bin), rise, go home.

    After an abort the fingers may still press hard on the part: the tree gives this skill a
    high force limit so that opening is allowed under that load, or no recovery could start."""
    joints = np.asarray(home_joints, float)
    g, m = params.guard, params.move_guard

    def up() -> None:
        tool = dev.arm.tool_pose()
        lifted = Pose(tool.position + np.array([0.0, 0.0, params.rise]), tool.rotation)
        dev.arm.move_to(lifted, params.rise_speed, params.rise_acceleration)

    return Sequence(
        "put back",
        [
            dev.grip("open", g, lambda: dev.gripper.open()),
            dev.move("rise", g, up),
            dev.move(
                "home",
                m,
                lambda: dev.arm.move_joints(joints, home.joint_speed, home.joint_acceleration),
            ),
        ],
    )


__all__ = ["HomeParams", "PutBackParams", "go_home", "put_back"]
