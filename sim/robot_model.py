"""The twin's robot: a UR5 with an FT300-like wrist sensor and a 2F-85-like parallel gripper.

This module is the single source of the robot's geometry. It writes the URDF that PyBullet loads
and gives the same chain to numpy (:func:`forward_kinematics`, :func:`jacobian`) so that the arm's
inverse kinematics runs without a simulator round trip and agrees with PyBullet's links exactly.

Kinematics are the public ``ur_description`` UR5 joint origins; a test checks them against the
UR5 Denavit-Hartenberg parameters (d1 0.089159, a2 -0.425, a3 -0.39225, d4 0.10915, d5 0.09465,
d6 0.0823 m). ``ur_description``'s ``base_link`` is turned by pi about z from the UR controller's
``Base`` frame; the URDF's root link ``base`` is that controller frame, so every TCP pose of the
twin is in the frame a real UR5 reports.

Frames (all SI: m, rad, kg):

* ``base``: the robot base frame of :class:`drivers.arm.Arm` (UR ``Base``, z up).
* ``tool0``: the flange, z out of the flange (the UR tool frame with a zero TCP offset).
* ``ft_sensor``: the FT300-like puck, fixed to ``tool0`` by ``ft_joint`` (same axes and origin).
* ``tcp``: between the fingertips, on the tool z axis, :data:`TCP_Z` beyond the flange; same axes
  as ``tool0``. Tool frame convention: z is the approach (out of the flange, towards the
  fingertips), x the closing axis with ``finger_a`` on +x and ``finger_b`` on -x.
* ``finger_a`` / ``finger_b``: tool axes, origin at the centre of the pad's inner face where the
  finger leaves the gripper body (tool z = :data:`FINGER_BASE_Z`); the pad runs
  :data:`FINGER_LENGTH` along +z to the tip and is :data:`FINGER_THICKNESS` thick outwards. With
  both fingers at ``q`` the origins are at tool x = +q and -q.

Collision shapes are capsules, cylinders and boxes only, to keep the cell fast.
"""

from __future__ import annotations

import hashlib
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from drivers.pose import Pose

PI = math.pi

#: Arm joint names, base to wrist 3 (the order of every joint vector in the twin).
ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
#: ``ur_description`` link masses (kg), shoulder to wrist 3; the base is fixed (4.0 kg).
ARM_MASSES = (3.7, 8.393, 2.275, 1.219, 1.219, 0.1879)
#: Joint torque limits (N*m), base to wrist 3 (UR5: 150 N*m on the large, 28 N*m on the wrist).
ARM_EFFORT = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)
#: Joint speed limit (rad/s), every arm joint.
ARM_VELOCITY = PI
#: Joint position limit (rad), symmetric, every arm joint.
ARM_LIMIT = 2.0 * PI

# Tool stack along tool0's z (m).
FT_RADIUS = 0.0375
FT_HEIGHT = 0.0375
FT_MASS = 0.3
GRIPPER_BODY_SIZE = (0.075, 0.035, 0.090)  # x (closing axis), y, z (approach)
GRIPPER_BODY_MASS = 0.9
FINGER_THICKNESS = 0.008  # x
FINGER_WIDTH = 0.020  # y: the pad width w of the paper's Eq. 2
FINGER_LENGTH = 0.055  # z, hanging below the gripper body
FINGER_MASS = 0.03
FINGER_TRAVEL = 0.0425  # each finger 0..FINGER_TRAVEL from the tool axis; opening = sum
FINGER_EFFORT = 235.0  # N, the 2F-85's largest grip force
FINGER_VELOCITY = 0.15  # m/s, the 2F-85's fastest finger speed
FINGER_BASE_Z = FT_HEIGHT + GRIPPER_BODY_SIZE[2]  # where the fingers leave the body
FINGER_TIP_Z = FINGER_BASE_Z + FINGER_LENGTH
#: TCP offset from the flange along tool z (m): 5 mm above the fingertips' end.
TCP_Z = FINGER_TIP_Z - 0.005
#: Pose of the TCP in the flange frame ``tool0``.
TOOL0_T_TCP = Pose(np.array([0.0, 0.0, TCP_Z]), np.eye(3))
#: Mass (kg) hanging on the wrist sensor: puck, gripper body, fingers (and the massless tcp link).
TOOL_MASS = FT_MASS + GRIPPER_BODY_MASS + 2 * FINGER_MASS + 1e-4


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


# ---------------------------------------------------------------------------------------------
# URDF text
# ---------------------------------------------------------------------------------------------


def _f(values: ArrayLike) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.atleast_1d(np.asarray(values, float)))


def _cylinder_inertia(mass: float, radius: float, length: float) -> tuple[float, float, float]:
    """Principal inertia (kg*m^2) of a solid cylinder along z."""
    ixx = mass * (3 * radius**2 + length**2) / 12.0
    return ixx, ixx, 0.5 * mass * radius**2


def _box_inertia(mass: float, size: tuple[float, float, float]) -> tuple[float, float, float]:
    x, y, z = size
    return mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12, mass * (x * x + y * y) / 12


@dataclass(frozen=True)
class Shape:
    """A collision and visual shape: ``box`` (size), ``cylinder`` or ``capsule`` (radius, length
    along the shape's z), at ``xyz``/``rpy`` in the link frame."""

    kind: str
    dims: tuple[float, ...]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def geometry(self) -> str:
        if self.kind == "box":
            return f'<box size="{_f(self.dims)}"/>'
        return f'<{self.kind} radius="{self.dims[0]:.9g}" length="{self.dims[1]:.9g}"/>'


@dataclass(frozen=True)
class LinkSpec:
    """A link: mass (kg), centre of mass (m, link frame), principal inertia (kg*m^2), shapes."""

    name: str
    mass: float
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: tuple[float, float, float] = (1e-6, 1e-6, 1e-6)
    shapes: tuple[Shape, ...] = ()
    color: str = "0.7 0.7 0.7 1"


_ALONG_Y = (-PI / 2, 0.0, 0.0)  # turns a shape's z onto the link's y


def _links() -> list[LinkSpec]:
    """Masses from ur_description; inertias of cylinders (as ur_description does); simple shapes."""
    m = ARM_MASSES
    body_h = GRIPPER_BODY_SIZE[2]
    return [
        LinkSpec("base", 1e-3),
        LinkSpec(
            "base_link", 4.0, (0, 0, 0.04), _cylinder_inertia(4.0, 0.06, 0.05),
            # 3 mm clear of the mounting plane: a fixed base resting on a static floor would
            # only feed the solver contacts that can do nothing.
            (Shape("cylinder", (0.075, 0.083), (0, 0, 0.0445)),),
        ),
        LinkSpec(
            "shoulder_link", m[0], (0, 0, 0), _cylinder_inertia(m[0], 0.06, 0.15),
            (Shape("cylinder", (0.06, 0.15), (0, 0.06, 0), _ALONG_Y),),
        ),
        LinkSpec(
            "upper_arm_link", m[1], (0, 0, 0.28), _cylinder_inertia(m[1], 0.06, 0.56),
            (
                Shape("capsule", (0.054, 0.33), (0, 0, 0.2125)),
                Shape("cylinder", (0.06, 0.12), (0, -0.06, 0.425), _ALONG_Y),
            ),
        ),
        LinkSpec(
            "forearm_link", m[2], (0, 0, 0.25), _cylinder_inertia(m[2], 0.06, 0.5),
            (Shape("capsule", (0.04, 0.31), (0, 0, 0.196)),),
        ),
        LinkSpec(
            "wrist_1_link", m[3], (0, 0, 0), _cylinder_inertia(m[3], 0.06, 0.12),
            (Shape("cylinder", (0.045, 0.12), (0, 0.05, 0), _ALONG_Y),),
        ),
        LinkSpec(
            "wrist_2_link", m[4], (0, 0, 0), _cylinder_inertia(m[4], 0.06, 0.12),
            (Shape("cylinder", (0.045, 0.11), (0, 0, 0.045)),),
        ),
        LinkSpec(
            "wrist_3_link", m[5], (0, 0, 0), _cylinder_inertia(m[5], 0.0375, 0.0345),
            (Shape("cylinder", (0.0375, 0.03), (0, 0.066, 0), _ALONG_Y),),
        ),
        LinkSpec("tool0", 1e-4),
        LinkSpec(
            "ft_sensor", FT_MASS, (0, 0, FT_HEIGHT / 2),
            _cylinder_inertia(FT_MASS, FT_RADIUS, FT_HEIGHT),
            (Shape("cylinder", (FT_RADIUS, FT_HEIGHT), (0, 0, FT_HEIGHT / 2)),),
            "0.2 0.2 0.2 1",
        ),
        LinkSpec(
            "gripper_body", GRIPPER_BODY_MASS, (0, 0, body_h / 2),
            _box_inertia(GRIPPER_BODY_MASS, GRIPPER_BODY_SIZE),
            (Shape("box", GRIPPER_BODY_SIZE, (0, 0, body_h / 2)),),
            "0.15 0.15 0.15 1",
        ),
        _finger_link("finger_a", +1.0),
        _finger_link("finger_b", -1.0),
        LinkSpec("tcp", 1e-4),  # in TOOL_MASS
    ]


def _finger_link(name: str, side: float) -> LinkSpec:
    """A finger whose link frame is on the tool axis at the body's end; the pad faces the axis."""
    size = (FINGER_THICKNESS, FINGER_WIDTH, FINGER_LENGTH)
    centre = (side * FINGER_THICKNESS / 2, 0.0, FINGER_LENGTH / 2)
    return LinkSpec(
        name, FINGER_MASS, centre, _box_inertia(FINGER_MASS, size),
        (Shape("box", size, centre),), "0.8 0.5 0.1 1",
    )


def _joints() -> list[JointSpec]:
    return [
        BASE_FIXED,
        *ARM_CHAIN,
        TOOL0_FIXED,
        JointSpec("ft_joint", "tool0", "ft_sensor", (0, 0, 0), kind="fixed"),
        JointSpec("ft_gripper_joint", "ft_sensor", "gripper_body", (0, 0, FT_HEIGHT), kind="fixed"),
        JointSpec(
            "finger_a", "gripper_body", "finger_a", (0, 0, GRIPPER_BODY_SIZE[2]),
            axis=(1, 0, 0), kind="prismatic",
        ),
        JointSpec(
            "finger_b", "gripper_body", "finger_b", (0, 0, GRIPPER_BODY_SIZE[2]),
            axis=(-1, 0, 0), kind="prismatic",
        ),
        JointSpec("tcp_joint", "gripper_body", "tcp", (0, 0, TCP_Z - FT_HEIGHT), kind="fixed"),
    ]


def _link_xml(link: LinkSpec) -> str:
    ixx, iyy, izz = link.inertia
    out = [
        f'  <link name="{link.name}">',
        "    <inertial>",
        f'      <origin xyz="{_f(link.com)}" rpy="0 0 0"/>',
        f'      <mass value="{link.mass:.9g}"/>',
        f'      <inertia ixx="{ixx:.9g}" ixy="0" ixz="0" iyy="{iyy:.9g}" iyz="0" izz="{izz:.9g}"/>',
        "    </inertial>",
    ]
    for shape in link.shapes:
        origin = f'<origin xyz="{_f(shape.xyz)}" rpy="{_f(shape.rpy)}"/>'
        out += [
            f"    <visual>{origin}<geometry>{shape.geometry()}</geometry>",
            f'      <material name="{link.name}_color"><color rgba="{link.color}"/></material>',
            "    </visual>",
            f"    <collision>{origin}<geometry>{shape.geometry()}</geometry></collision>",
        ]
    out.append("  </link>")
    return "\n".join(out)


def _joint_xml(joint: JointSpec) -> str:
    out = [
        f'  <joint name="{joint.name}" type="{joint.kind}">',
        f'    <parent link="{joint.parent}"/>',
        f'    <child link="{joint.child}"/>',
        f'    <origin xyz="{_f(joint.xyz)}" rpy="{_f(joint.rpy)}"/>',
    ]
    if joint.kind == "revolute":
        effort = ARM_EFFORT[ARM_JOINTS.index(joint.name)]
        out += [
            f'    <axis xyz="{_f(joint.axis)}"/>',
            f'    <limit lower="{-ARM_LIMIT:.9g}" upper="{ARM_LIMIT:.9g}" effort="{effort:.9g}"'
            f' velocity="{ARM_VELOCITY:.9g}"/>',
            '    <dynamics damping="0" friction="0"/>',
        ]
    elif joint.kind == "prismatic":
        out += [
            f'    <axis xyz="{_f(joint.axis)}"/>',
            f'    <limit lower="0" upper="{FINGER_TRAVEL:.9g}" effort="{FINGER_EFFORT:.9g}"'
            f' velocity="{FINGER_VELOCITY:.9g}"/>',
            '    <dynamics damping="0" friction="0"/>',
        ]
    out.append("  </joint>")
    return "\n".join(out)


def urdf_text() -> str:
    """The robot's URDF (UR5 + FT puck + gripper), as text."""
    parts = ['<?xml version="1.0"?>', '<robot name="ur5_ft300_2f85">']
    parts += [_link_xml(link) for link in _links()]
    parts += [_joint_xml(joint) for joint in _joints()]
    parts.append("</robot>")
    return "\n".join(parts) + "\n"


def write_urdf(directory: Path | None = None) -> Path:
    """Write the URDF once per content (named by its hash) and return its path.

    PyBullet loads URDFs from files; a content-addressed name in the temp directory lets parallel
    test processes share the file without races (same content, atomic rename).
    """
    text = urdf_text()
    digest = hashlib.sha1(text.encode()).hexdigest()[:12]
    directory = directory or Path(tempfile.gettempdir()) / "pivot_cell_urdf"
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"ur5_ft300_2f85_{digest}.urdf"
    if not path.exists():
        with tempfile.NamedTemporaryFile("w", dir=directory, suffix=".tmp", delete=False) as tmp:
            tmp.write(text)
        Path(tmp.name).replace(path)
    return path
