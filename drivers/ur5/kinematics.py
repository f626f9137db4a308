"""The UR5's kinematics with this cell's tool, in plain numpy: forward kinematics, the Jacobian,
inverse kinematics, and the home pose.

Why here, below the twin: the hardware path needs them too -- `cell run` checks every fixed pose
of the layout against the arm's reach before it connects to anything -- and must not import
PyBullet to do so. The twin (:mod:`sim.robot_model`, :mod:`sim.arm`) builds its URDF and its
arm control on this same chain, so the reach the cell checks is the reach the twin has.

Kinematics are the public ``ur_description`` UR5 joint origins (a test checks them against the
UR5 Denavit-Hartenberg parameters d1 0.089159, a2 -0.425, a3 -0.39225, d4 0.10915, d5 0.09465,
d6 0.0823 m). ``ur_description``'s ``base_link`` is turned by pi about z from the UR
controller's ``Base`` frame; the chain's root ``base`` is that controller frame, so every TCP
pose here is in the frame a real UR5 reports.

Frames (m, rad):

* ``base``: the robot base frame of :class:`drivers.arm.Arm` (UR ``Base``, z up).
* ``tool0``: the flange, z out of the flange (the UR tool frame with a zero TCP offset).
* ``tcp``: between the fingertips on the tool z axis, :data:`TCP_Z` beyond the flange; same axes
  as ``tool0``. The tool stack along z is the FT300 puck, the 2F-85's body and its fingers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from drivers.pose import Pose

PI = math.pi

#: Arm joint names, base to wrist 3 (the order of every joint vector).
ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
#: Joint speed limit (rad/s), every arm joint.
ARM_VELOCITY = PI
#: Joint position limit (rad), symmetric, every arm joint.
ARM_LIMIT = 2.0 * PI

# The tool stack along tool0's z (m): what puts the TCP where it is.
FT_HEIGHT = 0.0375  #: the FT300 puck
GRIPPER_BODY_HEIGHT = 0.090  #: the 2F-85's body, from the puck to where the fingers leave it
FINGER_LENGTH = 0.055  #: the fingers, hanging below the gripper body
FINGER_BASE_Z = FT_HEIGHT + GRIPPER_BODY_HEIGHT  #: where the fingers leave the body
FINGER_TIP_Z = FINGER_BASE_Z + FINGER_LENGTH
#: TCP offset from the flange along tool z (m): 5 mm above the fingertips' end.
TCP_Z = FINGER_TIP_Z - 0.005
#: Pose of the TCP in the flange frame ``tool0``.
TOOL0_T_TCP = Pose(np.array([0.0, 0.0, TCP_Z]), np.eye(3))

ROTATION_LENGTH = 0.1  #: m of path length per rad of rotation (couples turning to speed)
REACH_TOLERANCE = 0.005  #: m: an IK residual above this is "target unreachable"


@dataclass(frozen=True)
class JointSpec:
    """One URDF joint: origin in the parent link frame (m, rad, fixed-axis roll-pitch-yaw)."""

    name: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    kind: str = "revolute"


#: The UR controller Base -> ur_description base_link (pi about z), then the six arm joints.
BASE_FIXED = JointSpec("base_link_joint", "base", "base_link", (0, 0, 0), (0, 0, PI), kind="fixed")
ARM_CHAIN = (
    JointSpec(ARM_JOINTS[0], "base_link", "shoulder_link", (0, 0, 0.089159), axis=(0, 0, 1)),
    JointSpec(
        ARM_JOINTS[1], "shoulder_link", "upper_arm_link", (0, 0.13585, 0), (0, PI / 2, 0), (0, 1, 0)
    ),
    JointSpec(ARM_JOINTS[2], "upper_arm_link", "forearm_link", (0, -0.1197, 0.425), axis=(0, 1, 0)),
    JointSpec(
        ARM_JOINTS[3], "forearm_link", "wrist_1_link", (0, 0, 0.39225), (0, PI / 2, 0), (0, 1, 0)
    ),
    JointSpec(ARM_JOINTS[4], "wrist_1_link", "wrist_2_link", (0, 0.093, 0), axis=(0, 0, 1)),
    JointSpec(ARM_JOINTS[5], "wrist_2_link", "wrist_3_link", (0, 0, 0.09465), axis=(0, 1, 0)),
)
TOOL0_FIXED = JointSpec(
    "wrist_3_link-tool0_fixed_joint", "wrist_3_link", "tool0", (0, 0.0823, 0), (-PI / 2, 0, 0),
    kind="fixed",
)


def _homogeneous(xyz: ArrayLike, rpy: ArrayLike) -> NDArray[np.float64]:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()  # URDF: fixed-axis roll, pitch, yaw
    m[:3, 3] = xyz
    return m


def _rows(m: NDArray[np.float64]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """A 4x4 transform as (rotation row-major, translation) float tuples."""
    return tuple(float(v) for v in m[:3, :3].ravel()), tuple(float(v) for v in m[:3, 3])


# The chain as float tuples: the per-step IK evaluates it every control step, and plain float
# arithmetic on six 3x3 matrices is about 3x faster than numpy's per-call overhead.
_BASE = _rows(_homogeneous(BASE_FIXED.xyz, BASE_FIXED.rpy))
_ORIGINS = [_rows(_homogeneous(j.xyz, j.rpy)) for j in ARM_CHAIN]
_ABOUT_Z = [j.axis == (0, 0, 1) for j in ARM_CHAIN]  # otherwise about y (checked below)
_TOOL0 = _rows(_homogeneous(TOOL0_FIXED.xyz, TOOL0_FIXED.rpy))
assert all(j.axis in ((0, 0, 1), (0, 1, 0)) for j in ARM_CHAIN)

Mat3 = tuple[float, float, float, float, float, float, float, float, float]
Vec3 = tuple[float, float, float]


def _mul(a: Mat3, b: Mat3) -> Mat3:
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
    return (
        a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
        a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
        a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
    )  # fmt: skip


def _apply(r: Mat3, p: Vec3, v: Vec3) -> Vec3:
    """``p + r v``."""
    return (
        p[0] + r[0] * v[0] + r[1] * v[1] + r[2] * v[2],
        p[1] + r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
        p[2] + r[6] * v[0] + r[7] * v[1] + r[8] * v[2],
    )


def _chain(q: ArrayLike) -> tuple[list[Vec3], list[Vec3], Mat3, Vec3]:
    """Joint axes and origins (in ``base``) and the flange rotation and position."""
    r, p = _BASE
    axes, origins = [], []
    for (r_o, p_o), about_z, angle in zip(_ORIGINS, _ABOUT_Z, q, strict=True):
        p = _apply(r, p, p_o)
        r = _mul(r, r_o)
        c, s = math.cos(angle), math.sin(angle)
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = r
        if about_z:
            axes.append((r2, r5, r8))
            r = (c * r0 + s * r1, c * r1 - s * r0, r2,
                 c * r3 + s * r4, c * r4 - s * r3, r5,
                 c * r6 + s * r7, c * r7 - s * r6, r8)  # fmt: skip
        else:
            axes.append((r1, r4, r7))
            r = (c * r0 - s * r2, r1, s * r0 + c * r2,
                 c * r3 - s * r5, r4, s * r3 + c * r5,
                 c * r6 - s * r8, r7, s * r6 + c * r8)  # fmt: skip
        origins.append(p)
    p = _apply(r, p, _TOOL0[1])
    return axes, origins, _mul(r, _TOOL0[0]), p


def _end(r: Mat3, p: Vec3, tcp: bool) -> Vec3:
    if not tcp:
        return p
    return (p[0] + TCP_Z * r[2], p[1] + TCP_Z * r[5], p[2] + TCP_Z * r[8])


def flange_matrix(q: ArrayLike) -> NDArray[np.float64]:
    """``base_T_tool0`` (4x4) for joint angles ``q`` (rad)."""
    _, _, r, p = _chain(q)
    m = np.eye(4)
    m[:3, :3] = np.array(r).reshape(3, 3)
    m[:3, 3] = p
    return m


def forward_kinematics(q: ArrayLike, tcp: bool = True) -> Pose:
    """Pose of the TCP (or of ``tool0`` with ``tcp=False``) in ``base`` for joints ``q`` (rad)."""
    _, _, r, p = _chain(q)
    return Pose(np.array(_end(r, p, tcp)), np.array(r).reshape(3, 3))


def jacobian(q: ArrayLike, tcp: bool = True) -> tuple[NDArray[np.float64], Pose]:
    """Geometric Jacobian (6x6: linear m/rad over angular rad/rad, in ``base``) and the pose.

    Column i is ``[a_i x (p - o_i); a_i]`` with the joint axis ``a_i`` and origin ``o_i``;
    returned with the TCP (or flange) pose so one chain evaluation serves the IK step.
    """
    axes, origins, r, p = _chain(q)
    e = _end(r, p, tcp)
    columns = []
    for (ax, ay, az), (ox, oy, oz) in zip(axes, origins, strict=True):
        dx, dy, dz = e[0] - ox, e[1] - oy, e[2] - oz
        columns.append((ay * dz - az * dy, az * dx - ax * dz, ax * dy - ay * dx, ax, ay, az))
    return np.array(columns).T, Pose(np.array(e), np.array(r).reshape(3, 3))


def matrix_to_rotvec(m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation vector (rad) of a rotation matrix; a scalar formula, several times faster than
    scipy's on one matrix, which matters in the per-step IK."""
    cos = min(max((m[0, 0] + m[1, 1] + m[2, 2] - 1.0) * 0.5, -1.0), 1.0)
    angle = float(np.arccos(cos))
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    if angle < 1e-6:
        return 0.5 * w
    if angle > np.pi - 1e-3:  # near a half turn the skew part vanishes: let scipy decide
        return Rotation.from_matrix(m).as_rotvec()
    return (angle / (2.0 * np.sin(angle))) * w


def rotvec_to_matrix(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrix of a rotation vector (rad), Rodrigues' formula."""
    angle = float(np.sqrt(v @ v))
    if angle < 1e-12:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)


def pose_error(target: Pose, current: Pose) -> NDArray[np.float64]:
    """``[dp; dphi]``: position error (m) and rotation vector (rad), both in the base frame."""
    rotation = matrix_to_rotvec(target.rotation @ current.rotation.T)
    return np.concatenate([target.position - current.position, rotation])


def residual(err: NDArray[np.float64]) -> float:
    """Size of a pose error (m): position error plus ``ROTATION_LENGTH`` times the angle."""
    return float(np.sqrt(err[:3] @ err[:3]) + ROTATION_LENGTH * np.sqrt(err[3:] @ err[3:]))


def dls_step(
    jac: NDArray[np.float64], err: NDArray[np.float64], damping: float = 1e-3
) -> NDArray[np.float64]:
    """Damped-least-squares joint step (rad) for a pose error; at most 0.3 rad per joint."""
    dq = jac.T @ np.linalg.solve(jac @ jac.T + damping**2 * np.eye(6), err)
    biggest = float(np.max(np.abs(dq)))
    if biggest > 0.3:
        dq *= 0.3 / biggest
    return dq


def solve_ik(
    target: Pose, seed: ArrayLike, iterations: int = 50, tolerance: float = 1e-9
) -> tuple[NDArray[np.float64], float]:
    """Joints (rad) putting the TCP at ``target`` (base frame), and the residual (m).

    Damped least squares from ``seed``, each step at most 0.3 rad, joints kept in +-2 pi. The
    residual is the position error plus ``ROTATION_LENGTH`` times the angle error.
    """
    q = np.array(seed, float)
    for _ in range(iterations):
        jac, pose = jacobian(q)
        err = pose_error(target, pose)
        if residual(err) < tolerance:
            return q, residual(err)
        q = np.clip(q + dls_step(jac, err), -ARM_LIMIT, ARM_LIMIT)
    return q, residual(pose_error(target, forward_kinematics(q)))


#: Home TCP pose in the base frame: 0.5 m in front, 0.3 m up, tool pointing down.
HOME_TCP = Pose(np.array([0.5, 0.0, 0.3]), np.diag([1.0, -1.0, -1.0]))
#: Joint angles (rad) of a home: elbow up, upper arm near vertical, wrist down (seed of the IK).
_HOME_SEED = np.array([2.9215, -1.5621, 1.4454, -1.4541, -1.5708, -1.7909])
HOME_JOINTS: NDArray[np.float64] = solve_ik(HOME_TCP, _HOME_SEED)[0]
