"""The twin's arm: reach, straight-line tracking, faults, stop, servo and force mode."""

from __future__ import annotations

import numpy as np
import pytest

import drivers
from drivers.arm import MotionState
from drivers.pose import Pose, rot_y
from drivers.ur5.arm import SERVO_GAIN, SERVO_LOOKAHEAD
from drivers.ur5.kinematics import ARM_JOINTS, HOME_TCP
from sim.arm import SimArm
from sim.robot import SimRobot
from sim.world import SimWorld

from .conftest import add_floor, run_motion


def test_implements_the_interfaces(robot: SimRobot) -> None:
    assert isinstance(robot.arm, drivers.Arm)
    assert isinstance(robot.gripper, drivers.Gripper)
    assert isinstance(robot.ft, drivers.ForceTorqueSensor)
    assert isinstance(robot.world.clock, drivers.Clock)
    assert robot.arm.status().state is MotionState.IDLE


def test_commands_return_at_once_and_only_stepping_moves(world: SimWorld, robot: SimRobot) -> None:
    arm = robot.arm
    start = arm.tool_pose()
    arm.move_to(Pose(start.position + [0.05, 0, 0], start.rotation), 0.1, 0.5)
    assert arm.status().state is MotionState.MOVING
    assert arm.tool_pose().distance(start)[0] < 1e-9
    world.step()
    assert arm.tool_pose().distance(start)[0] > 0


def test_straight_line_10_cm_at_5_cm_per_s(world: SimWorld, robot: SimRobot) -> None:
    arm = robot.arm
    start = arm.tool_pose()
    goal = Pose(start.position + [0.0, 0.1, 0.0], start.rotation)
    arm.move_to(goal, 0.05, 0.5)
    direction = (goal.position - start.position) / 0.1
    deviation, angle = 0.0, 0.0
    while arm.status().state is MotionState.MOVING:
        world.step()
        pose = arm.tool_pose()
        rel = pose.position - start.position
        deviation = max(deviation, float(np.linalg.norm(rel - (rel @ direction) * direction)))
        angle = max(angle, pose.distance(start)[1])
    elapsed = world.clock.now()
    assert arm.status().state is MotionState.DONE
    assert arm.tool_pose().distance(goal)[0] < 1e-3
    assert deviation < 2e-3
    assert deviation < 1e-4  # what it does: tens of micrometres
    assert angle < np.radians(0.1)
    # Trapezoid: 0.1 m at 0.05 m/s plus one acceleration time (0.1 s), then settling.
    assert 2.1 <= elapsed < 2.4


def test_arc_of_5_cm_radius_with_the_tool_turning(world: SimWorld, robot: SimRobot) -> None:
    """The pivot skill's motion: the TCP on a 5 cm circle about a horizontal axis, the tool
    turning with it by 90 deg."""
    arm = robot.arm
    start = Pose(HOME_TCP.position + [0.0, 0.0, -0.15], HOME_TCP.rotation)
    arm.move_to(start, 0.2, 1.0)
    run_motion(world, robot)
    pivot = start.position + [0.05, 0.0, 0.0]

    def arc(beta: float) -> Pose:
        turn = rot_y(-beta)
        return Pose(pivot + turn @ (start.position - pivot), turn @ start.rotation)

    waypoints = [arc(b) for b in np.linspace(0, np.pi / 2, 46)[1:]]
    arm.move_path(waypoints, 0.05, 0.5)
    radial, off_plane = 0.0, 0.0
    while arm.status().state is MotionState.MOVING:
        world.step()
        rel = arm.tool_pose().position - pivot
        radial = max(radial, abs(np.hypot(rel[0], rel[2]) - 0.05))
        off_plane = max(off_plane, abs(rel[1]))
    assert arm.status().state is MotionState.DONE
    d, angle = arm.tool_pose().distance(waypoints[-1])
    assert d < 1e-3 and angle < np.radians(0.5)
    assert radial < 1e-4 and off_plane < 1e-4  # chords of 2 deg sag 8 um


def test_unreachable_target_faults_without_moving(world: SimWorld, robot: SimRobot) -> None:
    arm = robot.arm
    start = arm.tool_pose()
    arm.move_to(Pose(start.position + [1.5, 0, 0], start.rotation), 0.1, 0.5)
    status = arm.status()
    assert status.state is MotionState.FAULT
    assert status.message == "target unreachable"
    for _ in range(50):
        world.step()
    assert arm.tool_pose().distance(start)[0] < 1e-4
    arm.stop()  # a stop does not hide the fault
    assert arm.status().state is MotionState.FAULT
    # A new, reachable motion clears it.
    arm.move_to(Pose(start.position + [0.02, 0, 0], start.rotation), 0.1, 0.5)
    run_motion(world, robot)
    assert arm.status().state is MotionState.DONE


def test_servo_to_an_unreachable_target_faults(world: SimWorld, robot: SimRobot) -> None:
    arm = robot.arm
    start = arm.tool_pose()
    arm.servo(Pose(start.position + [0, 0, 2.0], start.rotation))
    world.step()
    assert arm.status() == drivers.ArmStatus(MotionState.FAULT, "target unreachable")


def test_a_stream_out_of_reach_faults_where_the_arm_is(world: SimWorld, robot: SimRobot) -> None:
    """servoj trails the stream: the fault holds the arm where it is, not at the goal ahead."""
    arm = robot.arm
    arm.set_servo_tracking(SERVO_LOOKAHEAD, SERVO_GAIN)
    start = arm.tool_pose()
    for k in range(1, 1000):  # up at 0.25 m/s until out of reach
        arm.servo(Pose(start.position + [0, 0, 0.002 * k], start.rotation))
        world.step()
        if arm.status().state is MotionState.FAULT:
            break
    assert arm.status().message == "target unreachable"
    at_fault = arm.tool_pose()
    for _ in range(30):
        world.step()
    assert arm.tool_pose().distance(at_fault)[0] < 1e-3


def test_stop_holds_where_it_is(world: SimWorld, robot: SimRobot) -> None:
    arm = robot.arm
    start = arm.tool_pose()
    arm.move_to(Pose(start.position + [0.1, 0, 0], start.rotation), 0.05, 0.5)
    for _ in range(100):
        world.step()
    arm.stop()
    assert arm.status().state is MotionState.STOPPED
    world.step()
    held = arm.tool_pose()
    travelled = held.position[0] - start.position[0]
    assert 0.02 < travelled < 0.06
    for _ in range(200):
        world.step()
    assert arm.tool_pose().distance(held)[0] < 1e-4
    assert arm.status().state is MotionState.STOPPED
    arm.stop()  # idempotent
    assert arm.status().state is MotionState.STOPPED


def test_the_speed_slider_holds_a_move_where_it_is_and_resumes_it(
    world: SimWorld, robot: SimRobot
) -> None:
    """The UR's speed slider as its controller applies it: 0 freezes the trajectory's
    timing (the move stays MOVING, the arm stands), a later 1 finishes the same move."""
    arm = robot.arm
    start = arm.tool_pose()
    goal = Pose(start.position + [0.1, 0, 0], start.rotation)
    arm.move_to(goal, 0.05, 0.5)
    for _ in range(100):
        world.step()
    arm.set_speed_fraction(0.0)
    for _ in range(5):  # the tracking catches up with the frozen target
        world.step()
    held = arm.tool_pose()
    assert 0.02 < held.position[0] - start.position[0] < 0.06
    for _ in range(300):
        world.step()
    assert arm.tool_pose().distance(held)[0] < 1e-4
    assert arm.status().state is MotionState.MOVING
    arm.set_speed_fraction(1.0)
    run_motion(world, robot)
    assert arm.status().state is MotionState.DONE
    assert arm.tool_pose().distance(goal)[0] < 1e-3
    with pytest.raises(ValueError, match="speed fraction"):
        arm.set_speed_fraction(1.5)


def test_servo_follows_a_streamed_line(world: SimWorld, robot: SimRobot) -> None:
    arm = robot.arm
    arm.set_servo_tracking(None)  # each target within the step
    start = arm.tool_pose()
    lag = 0.0
    for s in np.linspace(0.0, 0.05, 250):  # 5 cm in 2 s
        target = Pose(start.position + [0, 0, -s], start.rotation)
        arm.servo(target)
        world.step()
        lag = max(lag, arm.tool_pose().distance(target)[0])
        assert arm.status().state is MotionState.MOVING
    assert lag < 1e-3
    for _ in range(20):
        arm.servo(target)
        world.step()
    assert arm.tool_pose().distance(target)[0] < 1e-4
    arm.stop()
    assert arm.status().state is MotionState.STOPPED


def _stream(world: SimWorld, arm: SimArm, per_step: list[int]) -> list[float]:
    """A line of 0.1 mm targets at 125 Hz, ``per_step[k]`` of them arriving before step k
    (0, 1 or 2: the sender's and the controller's clocks drifting); the TCP's z per step."""
    start = arm.tool_pose()
    sent, z = 0, []
    for n in per_step:
        sent += n
        arm.servo(Pose(start.position + [0, 0, -1e-4 * sent], start.rotation))
        world.step()
        z.append(float(arm.tool_pose().position[2]))
    return z


def test_servoj_smooths_an_uneven_stream_and_trails_by_its_lookahead(
    world: SimWorld, robot: SimRobot
) -> None:
    """Two targets in one controller cycle and none in the next: reached within the step,
    the TCP jumps 0.2 mm, then stands or even backs off; by servoj's law it moves evenly,
    lookahead x speed behind the stream."""
    uneven = [1] * 60 + [2, 0] * 30 + [1] * 60
    arm = robot.arm
    arm.set_servo_tracking(None)
    exact = -np.diff(_stream(world, arm, uneven))[62:118]
    assert np.max(exact) > 2e-4 and np.min(exact) < 0.2e-4  # jumps, then stands or backs
    arm.stop()
    arm.set_servo_tracking(0.1, 300.0)
    start = float(arm.tool_pose().position[2])
    z = _stream(world, arm, uneven)
    steps = -np.diff(z)[62:118]  # 0.1 mm a step on average
    assert np.all(steps > 0.7e-4) and np.all(steps < 1.3e-4)
    trail = start - 1e-4 * sum(uneven[:60]) - z[59]
    assert trail == pytest.approx(-(0.1 - 0.008) * 1e-4 / 0.008, rel=0.15)  # at 12.5 mm/s


def test_with_servoj_the_twins_arm_trails_a_stream_by_the_drivers_lookahead(
    world: SimWorld, robot: SimRobot
) -> None:
    """With ``sim.servoj`` the twin's UR follows a stream as the driver's servoL makes a UR
    follow it: about ``SERVO_LOOKAHEAD`` seconds behind, not within the step (the default)."""
    arm = robot.arm
    assert arm.servo_lag() == 0.0
    arm.set_servo_tracking(SERVO_LOOKAHEAD, SERVO_GAIN)
    assert arm.servo_lag() == SERVO_LOOKAHEAD
    start = float(arm.tool_pose().position[2])
    z = _stream(world, arm, [1] * 100)  # 12.5 mm/s
    trail = start - 1e-4 * 100 - z[-1]
    # a step's target is followed from the step before: lookahead less one step behind
    assert trail == pytest.approx(-(SERVO_LOOKAHEAD - 0.008) * 1e-4 / 0.008, rel=0.15)


def test_servoj_tracking_rejects_a_law_outside_its_range(robot: SimRobot) -> None:
    with pytest.raises(ValueError, match="servoj"):
        robot.arm.set_servo_tracking(0.0, 300.0)


def test_move_path_requires_positive_speed(robot: SimRobot) -> None:
    with pytest.raises(ValueError, match="speed"):
        robot.arm.move_to(robot.arm.tool_pose(), 0.0, 1.0)


def test_joint_positions_and_reset(world: SimWorld, robot: SimRobot) -> None:
    q = robot.arm.home_joints + [0.1, -0.1, 0.1, -0.1, 0.1, -0.1]
    robot.arm.reset_joints(q)
    assert np.allclose(robot.arm.joint_positions(), q)
    for _ in range(50):
        world.step()
    assert np.allclose(robot.arm.joint_positions(), q, atol=1e-4)


def test_pushing_into_the_floor_trips_the_protective_stop(world: SimWorld) -> None:
    add_floor(world)
    robot = SimRobot(world)
    robot.gripper.reset_width(0.0)  # closed: the tips 5 mm past the TCP (the linkage's reference)
    arm = robot.arm
    above = Pose(np.array([0.5, 0.0, 0.01]), HOME_TCP.rotation)  # fingertips 5 mm up
    arm.move_to(above, 0.25, 1.0)
    run_motion(world, robot)
    arm.move_to(Pose(np.array([0.5, 0.0, -0.01]), HOME_TCP.rotation), 0.02, 0.5)
    run_motion(world, robot)
    status = arm.status()
    assert status.state is MotionState.FAULT and status.protective_stop
    assert status.message.startswith("protective stop: tool force")
    # It stopped within a millimetre or so of touching (the pads ride on their lift joints), and
    # holds there.
    depth = 0.005 - arm.tool_pose().position[2]  # fingertips below the floor's top (m)
    assert -1e-3 < depth < 1.5e-3
    held = arm.tool_pose()
    for _ in range(50):
        world.step()
    assert arm.tool_pose().distance(held)[0] < 2e-4
    assert arm.status().protective_stop  # stays faulted
    arm.move_to(above, 0.05, 0.5)  # a new command clears it
    assert not arm.status().protective_stop
    run_motion(world, robot)
    assert arm.status().state is MotionState.DONE


def test_force_mode_presses_a_floor_with_the_commanded_force(world: SimWorld) -> None:
    add_floor(world)
    robot = SimRobot(world)
    arm, ft = robot.arm, robot.ft
    above = Pose(np.array([0.5, 0.0, 0.015]), HOME_TCP.rotation)  # fingertips 1 cm up
    arm.move_to(above, 0.25, 1.0)
    run_motion(world, robot)
    ft.bias()
    arm.force_mode([False, False, True, False, False, False], [0, 0, -20.0, 0, 0, 0],
                   [0.1, 0.1, 0.02, 0.5, 0.5, 0.5])  # fmt: skip
    forces = []
    for _ in range(250):  # 2 s
        world.step()
        forces.append(arm.applied_wrench()[2])
    assert arm.status().state is MotionState.MOVING
    assert np.mean(forces[-50:]) == pytest.approx(-20.0, abs=1.0)
    # The sensor says the same in its own frame: tool z points down, so Fz = -20 N.
    assert ft.wrench()[2] == pytest.approx(-20.0, abs=1.5)
    # Held axes stayed put.
    pose = arm.tool_pose()
    assert np.linalg.norm(pose.position[:2] - above.position[:2]) < 1e-3
    assert pose.distance(above)[1] < np.radians(1.0)
    arm.stop()
    assert arm.status().state is MotionState.STOPPED
    # Back to position control: it can leave.
    arm.move_to(above, 0.05, 0.5)
    run_motion(world, robot)
    assert arm.status().state is MotionState.DONE


def test_force_mode_in_free_space_moves_at_the_speed_limit(
    world: SimWorld, robot: SimRobot
) -> None:
    arm = robot.arm
    for _ in range(10):
        world.step()
    robot.ft.bias()
    start = arm.tool_pose()
    arm.force_mode([True, False, False, False, False, False], [10.0, 0, 0, 0, 0, 0],
                   [0.03, 0.1, 0.1, 0.5, 0.5, 0.5])  # fmt: skip
    for _ in range(125):  # 1 s
        world.step()
    pose = arm.tool_pose()
    travelled = pose.position - start.position
    assert travelled[0] == pytest.approx(0.03 * 1.0, abs=0.004)
    assert np.linalg.norm(travelled[1:]) < 1e-3


def test_rejects_force_mode_without_a_sensor(world: SimWorld, robot: SimRobot) -> None:
    bare = SimArm(world, robot.body_id, [robot.joint_index[n] for n in ARM_JOINTS])
    with pytest.raises(RuntimeError, match="sensor"):
        bare.force_mode([True] + [False] * 5, [1.0] + [0.0] * 5, [0.1] * 6)
