"""The robot model: the URDF chain against the UR5's DH forward kinematics and PyBullet."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drivers.pose import Pose
from sim import robot_model as rm
from sim.robot import HOME_JOINTS, HOME_TCP, SimRobot
from sim.world import SimWorld

from .conftest import add_box

# UR5 Denavit-Hartenberg parameters (Universal Robots' published values), m and rad.
DH_D = (0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823)
DH_A = (0.0, -0.425, -0.39225, 0.0, 0.0, 0.0)
DH_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)


def dh_flange(q: np.ndarray) -> np.ndarray:
    """base_T_flange from the standard DH convention, independent of the URDF chain."""
    m = np.eye(4)
    for theta, d, a, alpha in zip(q, DH_D, DH_A, DH_ALPHA, strict=True):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        m = m @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0, sa, ca, d],
                [0, 0, 0, 1],
            ]
        )
    return m


def test_fk_matches_dh_for_random_joints() -> None:
    rng = np.random.default_rng(0)
    for q in rng.uniform(-2 * math.pi, 2 * math.pi, (200, 6)):
        ours = rm.flange_matrix(q)
        ref = dh_flange(q)
        assert np.linalg.norm(ours[:3, 3] - ref[:3, 3]) < 1e-6
        assert np.abs(ours[:3, :3] - ref[:3, :3]).max() < 1e-9


def test_tcp_is_on_the_tool_z_axis_past_the_fingertips_minus_5_mm() -> None:
    q = np.random.default_rng(1).uniform(-3, 3, 6)
    flange, tcp = rm.forward_kinematics(q, tcp=False), rm.forward_kinematics(q)
    offset = flange.inverse() @ tcp
    assert np.allclose(offset.position, [0, 0, rm.TCP_Z], atol=1e-12)
    assert np.allclose(offset.rotation, np.eye(3), atol=1e-12)
    assert rm.TCP_Z == pytest.approx(0.0375 + 0.09 + 0.055 - 0.005)


def test_jacobian_matches_finite_differences() -> None:
    q = np.random.default_rng(2).uniform(-3, 3, 6)
    jac, pose = rm.jacobian(q)
    eps = 1e-7
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = eps
        moved = rm.forward_kinematics(q + dq)
        lin = (moved.position - pose.position) / eps
        ang = Rotation.from_matrix(moved.rotation @ pose.rotation.T).as_rotvec() / eps
        assert np.allclose(jac[:3, i], lin, atol=1e-6)
        assert np.allclose(jac[3:, i], ang, atol=1e-6)


def test_pybullet_links_agree_with_the_model_at_a_placed_base() -> None:
    base = Pose(np.array([0.2, -0.3, 0.1]), Rotation.from_euler("z", 0.7).as_matrix())
    with SimWorld(seed=0) as world:
        robot = SimRobot(world, base_pose=base)
        q = np.random.default_rng(3).uniform(-2.5, 2.5, 6)
        robot.arm.reset_joints(q)
        for link, tcp in (("tcp", True), ("tool0", False)):
            expected = base @ rm.forward_kinematics(q, tcp=tcp)
            d, angle = robot.link_pose(link).distance(expected)
            assert d < 1e-6 and angle < 1e-5, link


def test_urdf_masses_limits_and_tool_geometry() -> None:
    root = ET.fromstring(rm.urdf_text())
    masses = {
        link.get("name"): float(link.find("inertial/mass").get("value"))
        for link in root.iter("link")
    }
    arm_links = ["shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link",
                 "wrist_3_link"]  # fmt: skip
    assert [masses[n] for n in arm_links] == list(rm.ARM_MASSES)
    assert masses["ft_sensor"] == 0.3 and masses["gripper_body"] == 0.9
    joints = {j.get("name"): j for j in root.iter("joint")}
    for name, effort in zip(rm.ARM_JOINTS, rm.ARM_EFFORT, strict=True):
        limit = joints[name].find("limit")
        assert float(limit.get("lower")) == pytest.approx(-2 * math.pi)
        assert float(limit.get("upper")) == pytest.approx(2 * math.pi)
        assert float(limit.get("velocity")) == pytest.approx(math.pi)
        assert float(limit.get("effort")) == effort
    assert joints["ft_joint"].get("type") == "fixed"
    for finger, axis in (("finger_a", "1 0 0"), ("finger_b", "-1 0 0")):
        assert joints[finger].get("type") == "prismatic"
        assert joints[finger].find("axis").get("xyz") == axis
        assert float(joints[finger].find("limit").get("upper")) == pytest.approx(0.0425)


def test_pad_faces_are_width_apart_and_the_tcp_between_the_tips(
    world: SimWorld, robot: SimRobot
) -> None:
    """Pads from the collision boxes: inner faces at +-width/2 along tool x; TCP 5 mm above
    the tips' end; pad 20 mm wide."""
    p = world.p
    for width in (0.085, 0.04):
        robot.gripper.reset_width(width)
        tcp = robot.link_pose("tcp")
        assert np.allclose(tcp.rotation @ [0, 0, 1], [0, 0, -1], atol=1e-6)  # home: tool down
        lo_a, hi_a = (np.array(v) for v in p.getAABB(robot.body_id, robot.link_index["finger_a"]))
        lo_b, hi_b = (np.array(v) for v in p.getAABB(robot.body_id, robot.link_index["finger_b"]))
        # Home has tool x = world x, so finger_a is on +x.
        inner = lo_a[0] - hi_b[0]
        assert inner == pytest.approx(width, abs=2e-4)  # AABB margins are ~0.1 mm
        assert robot.gripper.width() == pytest.approx(width, abs=1e-9)
        assert (lo_a[0] + hi_b[0]) / 2 == pytest.approx(tcp.position[0], abs=2e-4)
        assert hi_a[1] - lo_a[1] == pytest.approx(0.020, abs=4e-4)
        assert tcp.position[2] - lo_a[2] == pytest.approx(0.005, abs=2e-4)


def test_home_points_the_tool_down_in_front() -> None:
    home = rm.forward_kinematics(HOME_JOINTS)
    d, angle = home.distance(HOME_TCP)
    assert d < 1e-8 and angle < 1e-8
    assert HOME_TCP.position[0] == pytest.approx(0.5)
    assert np.allclose(HOME_TCP.rotation[:, 2], [0, 0, -1])


def test_urdf_file_is_cached_by_content(tmp_path) -> None:
    first = rm.write_urdf(tmp_path)
    assert rm.write_urdf(tmp_path) == first
    assert first.read_text() == rm.urdf_text()


def test_the_base_does_not_touch_a_floor_at_its_mounting_plane(world: SimWorld) -> None:
    add_box(world, [0.5, 0.5, 0.05], [0.0, 0.0, -0.05], mass=0.0)
    robot = SimRobot(world)
    for _ in range(5):
        world.step()
    assert world.p.getContactPoints(bodyA=robot.body_id) == ()
