"""The twin's robot model: its URDF and PyBullet's links against the chain of
:mod:`drivers.ur5.kinematics` (tested against the UR5's DH parameters in tests/drivers/ur5)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drivers.pose import Pose
from drivers.ur5 import kinematics as kin
from sim import robot_model as rm
from sim.robot import SimRobot
from sim.world import SimWorld

from .conftest import add_box


def test_pybullet_links_agree_with_the_model_at_a_placed_base() -> None:
    base = Pose(np.array([0.2, -0.3, 0.1]), Rotation.from_euler("z", 0.7).as_matrix())
    with SimWorld(seed=0) as world:
        robot = SimRobot(world, base_pose=base)
        q = np.random.default_rng(3).uniform(-2.5, 2.5, 6)
        robot.arm.reset_joints(q)
        for link, tcp in (("tcp", True), ("tool0", False)):
            expected = base @ kin.forward_kinematics(q, tcp=tcp)
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
    for name, effort in zip(kin.ARM_JOINTS, rm.ARM_EFFORT, strict=True):
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
    the tips' end when closed, the linkage's tip travel at other openings; pad 20 mm wide."""
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
        assert robot.gripper.true_width() == pytest.approx(width, abs=1e-9)
        assert robot.gripper.width() == pytest.approx(width, abs=robot.gripper.spec.count_step)
        assert (lo_a[0] + hi_b[0]) / 2 == pytest.approx(tcp.position[0], abs=2e-4)
        assert hi_a[1] - lo_a[1] == pytest.approx(0.020, abs=4e-4)
        advance = robot.gripper.spec.tip_advance(width)
        assert tcp.position[2] - lo_a[2] == pytest.approx(0.005 + advance, abs=2e-4)


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
