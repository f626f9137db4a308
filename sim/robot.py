"""The twin's robot: the URDF loaded into a world, with its arm, gripper and wrist sensor.

``SimRobot(world, base_pose)`` places the UR5's base frame (UR ``Base``, z up) at ``base_pose``
in the world. The workspace is in front of the robot along the base's +x: at home
(:data:`drivers.ur5.kinematics.HOME_TCP`) the tool points straight down (tool z = -base z, tool
x = +base x) with the TCP at (0.5, 0, 0.3) m in the base frame, so a cell puts its bin about
0.5 m along the base's +x.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.gripper_spec import GripperSpec, default_gripper
from drivers.pose import Pose
from drivers.tool import FINGER_LENGTH
from drivers.ur5.kinematics import ARM_JOINTS, HOME_JOINTS, forward_kinematics
from sim.arm import SimArm
from sim.ft_sensor import SimForceTorqueSensor
from sim.gripper import FINGER_NAMES, LIFT_NAMES, SimGripper
from sim.robot_model import FINGER_THICKNESS, write_urdf
from sim.world import SimWorld, matrix_from_quaternion


class SimRobot:
    """A UR5 + FT300 + 2F-85 twin in ``world``: ``.arm``, ``.gripper``, ``.ft``, ``.body_id``."""

    def __init__(
        self,
        world: SimWorld,
        base_pose: Pose | None = None,
        home_joints: ArrayLike | None = None,
        gripper_self_locking: bool = True,
        gripper: GripperSpec | None = None,
        servo: tuple[float, float] | None = None,
    ) -> None:
        """Load the robot with its base frame at ``base_pose`` (world frame; default: origin),
        arm at ``home_joints`` (rad; default :data:`HOME_JOINTS`), gripper fully open.
        ``gripper_self_locking``: see :mod:`sim.gripper` (the 2F-85's fingers are not pushed
        back open by the part); ``gripper``: the gripper's description (the shipped 2F-85 by
        default): the fingers' sizes, force and speed ranges, position counts and linkage.
        ``servo``: servoj's (lookahead s, gain) by which the arm follows a streamed target, as
        a UR follows the driver's ``servoL`` (``sim.servoj``); None reaches each target within
        the step."""
        self.gripper_spec = gripper = gripper or default_gripper()
        self.world = world
        self.base_pose = base_pose or Pose()
        p = world.p
        self.body_id = p.loadURDF(
            str(write_urdf(spec=gripper)),
            self.base_pose.position.tolist(),
            self.base_pose.quaternion.tolist(),
            useFixedBase=True,
            flags=p.URDF_USE_INERTIA_FROM_FILE,
        )
        infos = [p.getJointInfo(self.body_id, j) for j in range(p.getNumJoints(self.body_id))]
        #: Joint name -> index, and child link name -> index (PyBullet: link i = joint i's child).
        self.joint_index = {info[1].decode(): j for j, info in enumerate(infos)}
        self.link_index = {info[12].decode(): j for j, info in enumerate(infos)}
        self.ft = SimForceTorqueSensor(world, self.body_id, self.joint_index["ft_joint"])
        self.gripper = SimGripper(
            world,
            self.body_id,
            {name: self.joint_index[name] for name in FINGER_NAMES + LIFT_NAMES},
            self_locking=gripper_self_locking,
            spec=gripper,
        )
        home = HOME_JOINTS if home_joints is None else np.asarray(home_joints, float)
        arm_joints = [self.joint_index[name] for name in ARM_JOINTS]
        self.arm = SimArm(world, self.body_id, arm_joints, self.ft, home_joints=home)
        if servo is not None:
            self.arm.set_servo_tracking(*servo)
        self.ft.limits.connect_stop(self.arm.stop)  # a sample over a motion's limit stops it
        self.arm.reset_joints(home)
        self.gripper.reset_width(self.gripper.stroke)

    def world_pose(self, base_pose: Pose) -> Pose:
        """A pose in the robot base frame, expressed in the world frame."""
        return self.base_pose @ base_pose

    def base_frame_pose(self, world_pose: Pose) -> Pose:
        """A pose in the world frame, expressed in the robot base frame."""
        return self.base_pose.inverse() @ world_pose

    def link_pose(self, link: str) -> Pose:
        """World pose of a link's frame (``tcp``, ``tool0``, ``finger_a``, ...)."""
        return Pose(*self._link_frame(link))

    def _link_frame(self, link: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(position, rotation)`` of :meth:`link_pose` without building a :class:`Pose` (the
        judge asks for the pad tips every control step); the same numbers as
        ``Pose.from_quaternion`` of the link state."""
        state = self.world.p.getLinkState(
            self.body_id, self.link_index[link], computeForwardKinematics=True
        )
        return np.asarray(state[4], float), matrix_from_quaternion(state[5])

    def _link_point(self, link: str, local: list[float]) -> NDArray[np.float64]:
        """A point given in a link's frame, in the world (as ``link_pose(link).transform``)."""
        position, rotation = self._link_frame(link)
        return np.asarray(local, float) @ rotation.T + position

    def fingertip(self, name: str) -> NDArray[np.float64]:
        """World position (m) of the centre of a finger's tip, 2 mm inside its end: the point the
        judge tests against the part's hole (a pad face alone can touch the rim from outside)."""
        outward = 1.0 if name == "finger_a" else -1.0
        local = [outward * 0.5 * FINGER_THICKNESS, 0.0, FINGER_LENGTH - 0.002]
        return self._link_point(name, local)

    def pad_tip(self, name: str) -> NDArray[np.float64]:
        """World position (m) of a finger's pad face at mid-width, 2 mm from its tip: the point
        that lies inside a part's hole when the finger is caught in it (the pad face of a
        finger on the outer wall lies outside the hole's radius)."""
        return self._link_point(name, [0.0, 0.0, FINGER_LENGTH - 0.002])

    def tcp_world(self) -> Pose:
        """The TCP pose in the world frame, from the model (same as ``link_pose("tcp")``)."""
        return self.base_pose @ forward_kinematics(self.arm.joint_positions())
