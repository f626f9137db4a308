"""The twin's robot: a UR5 with an FT300-like wrist sensor and a 2F-85-like parallel gripper.

This module writes the URDF that PyBullet loads: the arm's chain and limits come from
:mod:`drivers.ur5.kinematics` (the same chain the arm's inverse kinematics and the cell's reach
check run on, in plain numpy, so that they agree with PyBullet's links exactly), the tool stack's
sizes from :mod:`drivers.tool` (the ones the skills' clearance sweeps use); the masses,
inertias, collision shapes and the gripper's fingers are the twin's own and are set here.

Frames (all SI: m, rad, kg), besides ``base``, ``tool0`` and ``tcp`` of
:mod:`drivers.ur5.kinematics`:

* ``ft_sensor``: the FT300-like puck, fixed to ``tool0`` by ``ft_joint`` (same axes and origin).
* Tool axes (``tool0``, ``tcp``): z is the approach (out of the flange, towards the
  fingertips), x the closing axis with ``finger_a`` on +x and ``finger_b`` on -x.
* ``finger_a`` / ``finger_b``: tool axes, origin at the centre of the pad's inner face where the
  finger leaves the gripper body (tool z = :data:`drivers.tool.FINGER_BASE_Z`); the
  pad runs :data:`FINGER_LENGTH` along +z to the tip and is :data:`FINGER_THICKNESS` thick
  outwards. With both fingers at ``q`` the origins are at tool x = +q and -q.

Collision shapes are capsules, cylinders and boxes only, to keep the cell fast.
"""

from __future__ import annotations

import hashlib
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from drivers.gripper_spec import GripperSpec, default_gripper
from drivers.tool import FT_HEIGHT, FT_RADIUS, GRIPPER_BODY_SIZE, TCP_Z
from drivers.ur5.kinematics import (
    ARM_CHAIN,
    ARM_JOINTS,
    ARM_LIMIT,
    ARM_VELOCITY,
    BASE_FIXED,
    PI,
    TOOL0_FIXED,
    JointSpec,
)

#: ``ur_description`` link masses (kg), shoulder to wrist 3; the base is fixed (4.0 kg).
ARM_MASSES = (3.7, 8.393, 2.275, 1.219, 1.219, 0.1879)
#: Joint torque limits (N*m), base to wrist 3 (UR5: 150 N*m on the large, 28 N*m on the wrist).
ARM_EFFORT = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)

# Tool stack (its sizes are in drivers.tool).
FT_MASS = 0.3
GRIPPER_BODY_MASS = 0.9
#: The shipped gripper's facts (drivers/data/grippers/robotiq_2f85.yaml); a twin built for
#: another description takes them from it (:func:`urdf_text`).
_SHIPPED = default_gripper()
FINGER_THICKNESS = _SHIPPED.pad_thickness  # x
FINGER_WIDTH = _SHIPPED.pad_width  # y: the pad width w of the paper's Eq. 2
FINGER_MASS = 0.03
CARRIAGE_MASS = 0.005  #: the link between a finger's lift joint and its closing joint
FINGER_TRAVEL = 0.5 * _SHIPPED.stroke  # each finger 0..FINGER_TRAVEL from the tool axis
FINGER_EFFORT = _SHIPPED.force_max  # N, the largest grip force
FINGER_VELOCITY = _SHIPPED.speed_max  # m/s, the fastest finger speed
#: m each finger's lift joint may move along the approach (the linkage's tip travel is within)
LIFT_RANGE = (-0.005, 0.03)
LIFT_EFFORT = 2000.0  #: N: the linkage holds the pad along the approach (stiff, not backdriven)
#: Mass (kg) hanging on the wrist sensor: puck, gripper body, fingers (and the massless tcp link).
TOOL_MASS = FT_MASS + GRIPPER_BODY_MASS + 2 * (FINGER_MASS + CARRIAGE_MASS) + 1e-4


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


def _links(spec: GripperSpec) -> list[LinkSpec]:
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
        LinkSpec("finger_a_carriage", CARRIAGE_MASS),
        LinkSpec("finger_b_carriage", CARRIAGE_MASS),
        _finger_link("finger_a", +1.0, spec),
        _finger_link("finger_b", -1.0, spec),
        LinkSpec("tcp", 1e-4),  # in TOOL_MASS
    ]


def _finger_link(name: str, side: float, spec: GripperSpec) -> LinkSpec:
    """A finger whose link frame is on the tool axis at the body's end; the pad faces the axis."""
    size = (spec.pad_thickness, spec.pad_width, spec.pad_length)
    centre = (side * spec.pad_thickness / 2, 0.0, spec.pad_length / 2)
    return LinkSpec(
        name, FINGER_MASS, centre, _box_inertia(FINGER_MASS, size),
        (Shape("box", size, centre),), "0.8 0.5 0.1 1",
    )


def _joints() -> list[JointSpec]:
    """Each finger hangs on two prismatic joints: ``<finger>_lift`` along the approach (tool z),
    which :class:`sim.gripper.SimGripper` drives to follow the linkage's tip travel as the
    opening changes (the coupled second joint), and ``<finger>`` along the closing axis."""
    return [
        BASE_FIXED,
        *ARM_CHAIN,
        TOOL0_FIXED,
        JointSpec("ft_joint", "tool0", "ft_sensor", (0, 0, 0), kind="fixed"),
        JointSpec("ft_gripper_joint", "ft_sensor", "gripper_body", (0, 0, FT_HEIGHT), kind="fixed"),
        JointSpec(
            "finger_a_lift", "gripper_body", "finger_a_carriage", (0, 0, GRIPPER_BODY_SIZE[2]),
            axis=(0, 0, 1), kind="prismatic",
        ),
        JointSpec(
            "finger_b_lift", "gripper_body", "finger_b_carriage", (0, 0, GRIPPER_BODY_SIZE[2]),
            axis=(0, 0, 1), kind="prismatic",
        ),
        JointSpec(
            "finger_a", "finger_a_carriage", "finger_a", (0, 0, 0),
            axis=(1, 0, 0), kind="prismatic",
        ),
        JointSpec(
            "finger_b", "finger_b_carriage", "finger_b", (0, 0, 0),
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


def _joint_xml(joint: JointSpec, spec: GripperSpec) -> str:
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
    elif joint.kind == "prismatic" and joint.name.endswith("_lift"):
        out += [
            f'    <axis xyz="{_f(joint.axis)}"/>',
            f'    <limit lower="{LIFT_RANGE[0]:.9g}" upper="{LIFT_RANGE[1]:.9g}"'
            f' effort="{LIFT_EFFORT:.9g}" velocity="1"/>',
            '    <dynamics damping="0" friction="0"/>',
        ]
    elif joint.kind == "prismatic":
        out += [
            f'    <axis xyz="{_f(joint.axis)}"/>',
            f'    <limit lower="0" upper="{0.5 * spec.stroke:.9g}" effort="{spec.force_max:.9g}"'
            f' velocity="{spec.speed_max:.9g}"/>',
            '    <dynamics damping="0" friction="0"/>',
        ]
    out.append("  </joint>")
    return "\n".join(out)


def urdf_text(spec: GripperSpec | None = None) -> str:
    """The robot's URDF (UR5 + FT puck + the gripper ``spec``, the 2F-85 by default), as text."""
    spec = spec or _SHIPPED
    parts = ['<?xml version="1.0"?>', '<robot name="ur5_ft300_2f85">']
    parts += [_link_xml(link) for link in _links(spec)]
    parts += [_joint_xml(joint, spec) for joint in _joints()]
    parts.append("</robot>")
    return "\n".join(parts) + "\n"


def write_urdf(directory: Path | None = None, spec: GripperSpec | None = None) -> Path:
    """Write the URDF once per content (named by its hash) and return its path.

    PyBullet loads URDFs from files; a content-addressed name in the temp directory lets parallel
    test processes share the file without races (same content, atomic rename).
    """
    text = urdf_text(spec)
    digest = hashlib.sha1(text.encode()).hexdigest()[:12]
    directory = directory or Path(tempfile.gettempdir()) / "pivot_cell_urdf"
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"ur5_ft300_2f85_{digest}.urdf"
    if not path.exists():
        with tempfile.NamedTemporaryFile("w", dir=directory, suffix=".tmp", delete=False) as tmp:
            tmp.write(text)
        Path(tmp.name).replace(path)
    return path
