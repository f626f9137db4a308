"""The twin's wrist sensor: offset and bias, sign convention, torque origin, noise, age."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.pose import Pose
from drivers.tool import FINGER_BASE_Z, FINGER_LENGTH, FT_HEIGHT, TCP_Z
from drivers.ur5.kinematics import HOME_TCP
from sim import ft_sensor as fts
from sim import robot_model as rm
from sim.robot import SimRobot
from sim.world import SimWorld

from .conftest import add_floor, run_motion

TOOL_MASS = (rm.FT_MASS + rm.GRIPPER_BODY_MASS + 2 * (rm.FINGER_MASS + rm.CARRIAGE_MASS)
             + 1e-4)  # below ft_joint, kg
G = 9.81


def settle(world: SimWorld, steps: int = 30) -> None:
    for _ in range(steps):
        world.step()


def test_bias_removes_the_power_up_offset(world: SimWorld, robot: SimRobot) -> None:
    ft = robot.ft
    assert ft.age() == np.inf
    settle(world)
    raw = ft.wrench()
    offset = raw - ft.true_load()
    assert np.max(np.abs(offset[:3])) > 0.5  # a few newtons of offset before bias
    assert np.max(np.abs(offset[:3])) <= fts.FORCE_OFFSET + 1.0
    ft.bias()
    settle(world, 5)
    assert np.all(np.abs(ft.wrench()[:3]) < 5 * fts.FORCE_NOISE)
    assert np.all(np.abs(ft.wrench()[3:]) < 5 * fts.TORQUE_NOISE)
    assert ft.age() == pytest.approx(0.0)


def test_tool_weight_pulls_along_plus_tool_z_when_pointing_down(
    world: SimWorld, robot: SimRobot
) -> None:
    """The load the tool puts on the sensor: hanging straight down it is +m g along tool z."""
    settle(world)
    load = robot.ft.true_load()
    assert load[2] == pytest.approx(TOOL_MASS * G, rel=2e-3)
    assert np.allclose(load[[0, 1, 3, 4, 5]], 0.0, atol=1e-2)


def test_torque_is_about_the_sensor_origin(world: SimWorld, robot: SimRobot) -> None:
    """Tool horizontal: the weight's moment about the flange is m g times the tool's centre of
    mass distance along tool z.

    The torque about the child's centre of mass instead of the flange would be 0.23 N*m off.
    """
    q = robot.arm.home_joints.copy()
    q[3] += np.pi / 2  # wrist 1: turn the tool from pointing down to horizontal
    robot.arm.reset_joints(q)
    settle(world, 60)
    pose = robot.arm.tool_pose()
    assert abs(pose.rotation[2, 2]) < 1e-4  # tool z horizontal (to 0.1 mrad of sag)
    com_z = (
        rm.FT_MASS * FT_HEIGHT / 2
        + rm.GRIPPER_BODY_MASS * (FT_HEIGHT + rm.GRIPPER_BODY_SIZE[2] / 2)
        + 2 * rm.FINGER_MASS * (FINGER_BASE_Z + FINGER_LENGTH / 2)
        + 1e-4 * TCP_Z
    ) / TOOL_MASS
    load = robot.ft.true_load()
    gravity_tool = pose.rotation.T @ np.array([0.0, 0.0, -TOOL_MASS * G])
    assert np.allclose(load[:3], gravity_tool, atol=0.25)
    expected_torque = np.cross([0.0, 0.0, com_z], gravity_tool)
    assert np.allclose(load[3:], expected_torque, atol=0.04)


def test_pressing_the_fingertips_into_a_floor_gives_negative_fz(world: SimWorld) -> None:
    add_floor(world)
    robot = SimRobot(world)
    arm, ft = robot.arm, robot.ft
    arm.move_to(Pose(np.array([0.5, 0.0, 0.02]), HOME_TCP.rotation), 0.25, 1.0)
    run_motion(world, robot)
    robot.gripper.reset_width(0.0)  # closed: the tips at their reference, as the TCP says
    ft.bias()
    # Fingertips are 5 mm beyond the TCP: 3 mm into the floor, a stiff position servo against
    # a rigid floor; the arm's protective stop (150 N) ends it.
    arm.move_to(Pose(np.array([0.5, 0.0, 0.002]), HOME_TCP.rotation), 0.02, 0.5)
    run_motion(world, robot)
    assert arm.status().protective_stop
    w = ft.wrench()
    assert w[2] < -10.0  # the floor pushes the tool back towards the flange
    assert abs(w[0]) < 0.2 * abs(w[2]) and abs(w[1]) < 0.2 * abs(w[2])


def test_noise_level(world: SimWorld, robot: SimRobot) -> None:
    settle(world)
    samples = []
    for _ in range(400):
        world.step()
        samples.append(robot.ft.wrench() - robot.ft.true_load())
    std = np.std(samples, axis=0)
    assert np.allclose(std[:3], fts.FORCE_NOISE, rtol=0.2)
    assert np.allclose(std[3:], fts.TORQUE_NOISE, rtol=0.2)


def test_samples_once_per_control_step(world: SimWorld, robot: SimRobot) -> None:
    settle(world, 3)
    first = robot.ft.wrench()
    assert np.array_equal(robot.ft.wrench(), first)  # no new sample without a step
    world.step()
    assert not np.array_equal(robot.ft.wrench(), first)
    assert robot.ft.age() == pytest.approx(0.0)


def test_same_seed_same_readings() -> None:
    readings = []
    for _ in range(2):
        with SimWorld(seed=3) as world:
            robot = SimRobot(world)
            settle(world, 10)
            readings.append(robot.ft.wrench())
    assert np.array_equal(readings[0], readings[1])


def test_a_part_hanging_in_the_hole_grasp_reads_its_whole_weight() -> None:
    """What the pads carry reaches the sensor: the part hangs on the pads, the pads on their
    lift joints (the linkage's travel) and closing joints, and the sum of the contact forces on
    the tool's links must come out as the part's weight (the slot's and the box's weight checks
    rest on it)."""
    from tests.skills.twin import BIN_SPOTS, make_twin, take_hole_grasp

    tw = make_twin(7)
    try:
        assert take_hole_grasp(tw, BIN_SPOTS[0]) is None
        tw.settle(0.5)
        load = tw.robot.ft.true_load()
        part_weight = tw.part.mass * G
        assert load[2] - TOOL_MASS * G == pytest.approx(part_weight, rel=0.1)
    finally:
        tw.close()


def test_the_row_wise_cross_product_is_numpys_bit_for_bit() -> None:
    # The wrist load sums these every step: a different last bit would change the twin's noise
    # draws' thresholds and so its outcomes.
    from sim.ft_sensor import _cross

    rng = np.random.default_rng(3)
    a = rng.normal(size=(40, 3)) * rng.uniform(1e-3, 1e2, size=(40, 1))
    b = rng.normal(size=(40, 3)) * rng.uniform(1e-3, 1e2, size=(40, 1))
    assert np.array_equal(_cross(a, b), np.cross(a, b))
