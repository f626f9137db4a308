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
  as ``tool0``. The tool stack along z is the FT300 puck, the 2F-85's body and its fingers
  (their lengths: :mod:`drivers.tool`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from drivers.pose import Pose
from drivers.tool import TCP_Z

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
    """Joint axes and origins (in ``base``) and the flange rotation and position.

    :func:`_apply` and :func:`_mul` written out in the loop (the same expressions, so the same
    floats): the calls cost more than the arithmetic, and the twin's arm runs this every control
    step.
    """
    (r0, r1, r2, r3, r4, r5, r6, r7, r8), (p0, p1, p2) = _BASE
    axes, origins = [], []
    angles = q.tolist() if isinstance(q, np.ndarray) else q
    for (b, (o0, o1, o2)), about_z, angle in zip(_ORIGINS, _ABOUT_Z, angles, strict=True):
        p0, p1, p2 = (
            p0 + r0 * o0 + r1 * o1 + r2 * o2,
            p1 + r3 * o0 + r4 * o1 + r5 * o2,
            p2 + r6 * o0 + r7 * o1 + r8 * o2,
        )
        b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = (
            r0 * b0 + r1 * b3 + r2 * b6, r0 * b1 + r1 * b4 + r2 * b7, r0 * b2 + r1 * b5 + r2 * b8,
            r3 * b0 + r4 * b3 + r5 * b6, r3 * b1 + r4 * b4 + r5 * b7, r3 * b2 + r4 * b5 + r5 * b8,
            r6 * b0 + r7 * b3 + r8 * b6, r6 * b1 + r7 * b4 + r8 * b7, r6 * b2 + r7 * b5 + r8 * b8,
        )  # fmt: skip
        c, s = math.cos(angle), math.sin(angle)
        if about_z:
            axes.append((r2, r5, r8))
            r0, r1, r3, r4, r6, r7 = (c * r0 + s * r1, c * r1 - s * r0,
                                      c * r3 + s * r4, c * r4 - s * r3,
                                      c * r6 + s * r7, c * r7 - s * r6)  # fmt: skip
        else:
            axes.append((r1, r4, r7))
            r0, r2, r3, r5, r6, r8 = (c * r0 - s * r2, s * r0 + c * r2,
                                      c * r3 - s * r5, s * r3 + c * r5,
                                      c * r6 - s * r8, s * r6 + c * r8)  # fmt: skip
        origins.append((p0, p1, p2))
    r: Mat3 = (r0, r1, r2, r3, r4, r5, r6, r7, r8)
    p: Vec3 = (p0, p1, p2)
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


def forward_frame(q: ArrayLike, tcp: bool = True) -> tuple[list[float], NDArray[np.float64]]:
    """:func:`forward_kinematics` as ``(position list, rotation array)``, without the
    :class:`Pose` (for the per-step loops; the same numbers)."""
    _, _, r, p = _chain(q)
    return list(_end(r, p, tcp)), np.array(r).reshape(3, 3)


def jacobian(q: ArrayLike, tcp: bool = True) -> tuple[NDArray[np.float64], Pose]:
    """Geometric Jacobian (6x6: linear m/rad over angular rad/rad, in ``base``) and the pose.

    Column i is ``[a_i x (p - o_i); a_i]`` with the joint axis ``a_i`` and origin ``o_i``;
    returned with the TCP (or flange) pose so one chain evaluation serves the IK step.
    """
    jac, position, rotation = jacobian_frame(q, tcp)
    return jac, Pose(np.array(position), rotation)


def jacobian_frame(
    q: ArrayLike, tcp: bool = True
) -> tuple[NDArray[np.float64], list[float], NDArray[np.float64]]:
    """:func:`jacobian` with the pose as ``(position, rotation)``: position a list of floats,
    rotation a 3x3 array. Why: the twin's arm runs one IK step per control step, and building
    and checking a :class:`Pose` costs about as much as the chain itself. Same numbers as
    :func:`jacobian`, bit for bit."""
    axes, origins, r, p = _chain(q)
    e = _end(r, p, tcp)
    columns = []
    for (ax, ay, az), (ox, oy, oz) in zip(axes, origins, strict=True):
        dx, dy, dz = e[0] - ox, e[1] - oy, e[2] - oz
        columns.append((ay * dz - az * dy, az * dx - ax * dz, ax * dy - ay * dx, ax, ay, az))
    # The transpose of the row-built array, as before: the Jacobian's memory layout decides
    # which BLAS path ``jac @ jac.T`` takes, and so the last bits of the IK step.
    return np.array(columns).T, list(e), np.array(r).reshape(3, 3)


def _rotvec(m: NDArray[np.float64]) -> list[float]:
    """:func:`matrix_to_rotvec` as a list, in plain float arithmetic.

    The same operations in the same order as the numpy version it replaced (``math.acos`` and
    ``math.sin`` are the C library's, as numpy's scalar ``arccos`` and ``sin`` are), so the
    same bits, in a fifth of the time.
    """
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m.tolist()
    cos = min(max((m00 + m11 + m22 - 1.0) * 0.5, -1.0), 1.0)
    angle = math.acos(cos)
    w0, w1, w2 = m21 - m12, m02 - m20, m10 - m01
    if angle < 1e-6:
        return [0.5 * w0, 0.5 * w1, 0.5 * w2]
    if angle > PI - 1e-3:  # near a half turn the skew part vanishes: let scipy decide
        return Rotation.from_matrix(m).as_rotvec().tolist()  # type: ignore[no-any-return]
    k = angle / (2.0 * math.sin(angle))
    return [k * w0, k * w1, k * w2]


def matrix_to_rotvec(m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation vector (rad) of a rotation matrix; a scalar formula, several times faster than
    scipy's on one matrix, which matters in the per-step IK."""
    return np.array(_rotvec(np.asarray(m, float)))


def rotvec_to_matrix(v: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrix of a rotation vector (rad), Rodrigues' formula.

    ``I + sin(a) K + (1 - cos(a)) K K`` element by element in floats, in the order numpy
    evaluates the matrix expression (so the same bits); ``K K`` stays a numpy product, whose
    rounding plain arithmetic does not reproduce. The path follower calls this every control
    step.
    """
    x, y, z = _floats(v)
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-12:
        return np.eye(3)
    kx, ky, kz = x / angle, y / angle, z / angle
    km = np.array([[0.0, -kz, ky], [kz, 0.0, -kx], [-ky, kx, 0.0]])
    # One array times itself, as before: the same BLAS call.
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = (km @ km).tolist()
    s, c = math.sin(angle), 1.0 - math.cos(angle)
    return np.array(
        [
            [(1.0 + s * 0.0) + c * a00, (0.0 + s * -kz) + c * a01, (0.0 + s * ky) + c * a02],
            [(0.0 + s * kz) + c * a10, (1.0 + s * 0.0) + c * a11, (0.0 + s * -kx) + c * a12],
            [(0.0 + s * -ky) + c * a20, (0.0 + s * kx) + c * a21, (1.0 + s * 0.0) + c * a22],
        ]
    )


def _floats(v: ArrayLike) -> list[float]:
    """A 3-vector as floats: an array's own, or each element of a sequence made a float."""
    if isinstance(v, np.ndarray):
        return v.reshape(3).tolist()  # type: ignore[no-any-return]
    return [float(c) for c in v]  # type: ignore[union-attr]


def frame_error_list(
    target_position: ArrayLike,
    target_rotation: NDArray[np.float64],
    position: ArrayLike,
    rotation: NDArray[np.float64],
) -> list[float]:
    """:func:`pose_error` of ``(position, rotation)`` pairs, as a list of six floats.

    Why: the twin's arm measures two errors every control step and needs only the size of one
    of them; neither needs a :class:`Pose` built or an array assembled.
    """
    tx, ty, tz = _floats(target_position)
    px, py, pz = _floats(position)
    return [tx - px, ty - py, tz - pz, *_rotvec(target_rotation @ rotation.T)]


def pose_error(target: Pose, current: Pose) -> NDArray[np.float64]:
    """``[dp; dphi]``: position error (m) and rotation vector (rad), both in the base frame."""
    return np.array(
        frame_error_list(target.position, target.rotation, current.position, current.rotation)
    )


def residual(err: ArrayLike) -> float:
    """Size of a pose error (m): position error plus ``ROTATION_LENGTH`` times the angle.

    Plain float arithmetic: each sum of squares in the order numpy's dot of a 3-vector adds
    it (left to right, no fused multiply-add), the square root correctly rounded in both.
    """
    e0, e1, e2, e3, e4, e5 = err.tolist() if isinstance(err, np.ndarray) else err
    return math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) + ROTATION_LENGTH * math.sqrt(
        e3 * e3 + e4 * e4 + e5 * e5
    )


def largest_magnitude(values: list[float]) -> float:
    """``float(np.max(np.abs(values)))`` of a few floats, NaN if any is NaN as numpy's is;
    without numpy's per-call cost."""
    if any(map(math.isnan, values)):
        return math.nan
    return max(map(abs, values))


#: ``damping**2 * I`` for :func:`dls_step`'s default damping, built once (the same array).
_DEFAULT_DAMPING = 1e-3
_DAMPED_EYE = _DEFAULT_DAMPING**2 * np.eye(6)

try:  # LAPACK's gesv as np.linalg.solve calls it, without its per-call checks and errstate
    from numpy.linalg import _umath_linalg

    _SOLVE1 = _umath_linalg.solve1
except (ImportError, AttributeError):  # another numpy layout: the public function
    _SOLVE1 = None


def _solve(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``np.linalg.solve(a, b)`` for a 6x6 float ``a`` and a 6-vector ``b``: the same LAPACK
    call, without the wrapper's checks (about 10 us a call, more than the solve).

    ``J J^T + lambda^2 I`` is positive definite for any finite Jacobian, so the LU never meets
    a zero pivot; a non-finite answer goes back through ``np.linalg.solve``, which raises or
    returns as it always did.
    """
    if _SOLVE1 is None:
        return np.linalg.solve(a, b)
    x = _SOLVE1(a, b, signature="dd->d")
    if not math.isfinite(sum(x.tolist())):
        return np.linalg.solve(a, b)
    return x  # type: ignore[no-any-return]


def dls_step(
    jac: NDArray[np.float64], err: ArrayLike, damping: float = _DEFAULT_DAMPING
) -> NDArray[np.float64]:
    """Damped-least-squares joint step (rad) for a pose error; at most 0.3 rad per joint."""
    damped = _DAMPED_EYE if damping == _DEFAULT_DAMPING else damping**2 * np.eye(6)
    dq = jac.T @ _solve(jac @ jac.T + damped, np.asarray(err, float))
    biggest = largest_magnitude(dq.tolist())
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
    t_position, t_rotation = target.position, target.rotation
    q = np.array(seed, float)
    for _ in range(iterations):
        jac, position, rotation = jacobian_frame(q)
        err = frame_error_list(t_position, t_rotation, position, rotation)
        miss = residual(err)
        if miss < tolerance:
            return q, miss
        q = (q + dls_step(jac, err)).clip(-ARM_LIMIT, ARM_LIMIT)
    position, rotation = forward_frame(q)
    return q, residual(frame_error_list(t_position, t_rotation, position, rotation))


#: Home TCP pose in the base frame: 0.5 m in front, 0.3 m up, tool pointing down.
HOME_TCP = Pose(np.array([0.5, 0.0, 0.3]), np.diag([1.0, -1.0, -1.0]))
#: Joint angles (rad) of a home: elbow up, upper arm near vertical, wrist down (seed of the IK).
_HOME_SEED = np.array([2.9215, -1.5621, 1.4454, -1.4541, -1.5708, -1.7909])
HOME_JOINTS: NDArray[np.float64] = solve_ik(HOME_TCP, _HOME_SEED)[0]
