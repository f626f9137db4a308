"""Benchmark: real-time factor of the twin's robot (simulated seconds per wall second).

Run by hand:  python bench/robot_rtf.py [--seconds 20]
Loads the robot over a floor box and times three phases: holding still; moving back and forth
along a 10 cm line at 0.1 m/s; and the same with a 50 g box pinched in the gripper. Target for
the whole cell: >= 20x, so the robot alone should leave most of the budget to the rest.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable

from drivers.arm import MotionState
from drivers.pose import Pose
from drivers.ur5.kinematics import HOME_TCP
from sim.robot import SimRobot
from sim.world import SimWorld


def _floor(world: SimWorld) -> None:
    p = world.p
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.4, 0.4, 0.05])
    p.createMultiBody(0, shape, -1, [0.5, 0.0, -0.05])


def _run(world: SimWorld, seconds: float, each_step: Callable[[], None]) -> float:
    steps = int(round(seconds / world.settings.control_dt))
    start = time.perf_counter()
    for _ in range(steps):
        each_step()
        world.step()
    return steps * world.settings.control_dt / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per phase")
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")

    with SimWorld(seed=0) as world:
        _floor(world)
        robot = SimRobot(world)
        arm = robot.arm
        print(f"hold still:          {_run(world, args.seconds, lambda: None):6.1f}x")

        low = Pose(HOME_TCP.position + [0.0, 0.0, -0.2], HOME_TCP.rotation)
        ends = [Pose(low.position + [dx, 0.0, 0.0], low.rotation) for dx in (-0.05, 0.05)]

        moves = [0]

        def shuttle() -> None:
            if arm.status().state is not MotionState.MOVING:
                moves[0] += 1
                arm.move_to(ends[moves[0] % 2], 0.1, 0.5)

        arm.move_to(low, 0.25, 1.0)
        while arm.status().state is MotionState.MOVING:
            world.step()
        print(f"moving 0.1 m/s:      {_run(world, args.seconds, shuttle):6.1f}x")

        p = world.p
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.015, 0.015, 0.03])
        p.createMultiBody(0.05, shape, -1, [0.5, 0.0, 0.03])
        arm.move_to(Pose([0.5, 0.0, 0.04], low.rotation), 0.1, 0.5)
        while arm.status().state is MotionState.MOVING:
            world.step()
        robot.gripper.close(40.0)
        while robot.gripper.moving():
            world.step()
        assert robot.gripper.object_detected()
        print(f"moving with a pinch: {_run(world, args.seconds, shuttle):6.1f}x")


if __name__ == "__main__":
    main()
