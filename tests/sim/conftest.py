"""Shared fixtures for the twin's tests: a fresh world per test, the robot, a floor box."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from drivers.arm import MotionState
from sim.robot import SimRobot
from sim.world import SimWorld

#: Top of the floor box in the world (= robot base) frame, m; the robot stands at the origin.
FLOOR_TOP = 0.0


@pytest.fixture
def world() -> Iterator[SimWorld]:
    with SimWorld(seed=7) as w:
        yield w


@pytest.fixture
def robot(world: SimWorld) -> SimRobot:
    return SimRobot(world)


def add_floor(world: SimWorld, top: float = FLOOR_TOP) -> int:
    """A static box 0.8 x 0.8 x 0.1 m in front of the robot, its top face at ``top`` (m)."""
    p = world.p
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.4, 0.4, 0.05])
    return p.createMultiBody(0, shape, -1, [0.5, 0.0, top - 0.05])


def add_box(world: SimWorld, half_extents: list[float], position: list[float], mass: float) -> int:
    p = world.p
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half_extents)
    return p.createMultiBody(mass, shape, -1, position)


def run_until(world: SimWorld, done: Callable[[], bool], limit_s: float = 10.0) -> float:
    """Step until ``done()`` or ``limit_s`` simulated seconds; the simulated time it took."""
    start = world.clock.now()
    while not done():
        assert world.clock.now() - start < limit_s, "timed out"
        world.step()
    return world.clock.now() - start


def run_motion(world: SimWorld, robot: SimRobot, limit_s: float = 10.0) -> float:
    return run_until(world, lambda: robot.arm.status().state is not MotionState.MOVING, limit_s)
