"""Fake devices for tick-level skill tests: they obey the interfaces and move by rules, not physics.

A fake arm reaches each commanded pose after a fixed number of ticks; a fake gripper closes onto a
configurable object width. Tests advance them with ``tick()``, as the world's step would.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from drivers.arm import ArmStatus, MotionState
from drivers.pose import Pose


class FakeClock:
    def __init__(self, dt: float = 0.008) -> None:
        self.t, self.dt = 0.0, dt

    def now(self) -> float:
        return self.t


class FakeArm:
    def __init__(self, pose: Pose | None = None, ticks_per_move: int = 3) -> None:
        self.pose = pose or Pose(np.array([0.4, 0.0, 0.3]))
        self.ticks_per_move = ticks_per_move
        self.queue: list[Pose] = []
        self.remaining = 0
        self.state = MotionState.IDLE
        self.commands: list[tuple[str, object]] = []
        self.speeds: list[float] = []  #: each move's speed, as asked
        self.stops = 0
        #: force mode: (selection, wrench, speed limits) while it runs, else None
        self.force: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        #: in force mode the TCP moves at its speed limit unless something holds it (the test)
        self.blocked = False
        self.dt = 0.008
        #: joints -> TCP pose: given, a joint move ends at that pose (else where it started)
        self.forward = None
        #: (pose, joints) -> joints: given, a Cartesian move's end updates the joints too
        self.inverse = None
        self.q = np.zeros(6)  #: joints, as the last joint move left them

    def tool_pose(self) -> Pose:
        return self.pose

    def move_path(self, waypoints: Sequence[Pose], speed: float, acceleration: float) -> None:
        self.commands.append(("path", list(waypoints)))
        self.speeds.append(speed)
        self.queue = list(waypoints)
        self.remaining = self.ticks_per_move
        self.state = MotionState.MOVING

    def move_to(self, pose: Pose, speed: float, acceleration: float) -> None:
        self.move_path([pose], speed, acceleration)

    def move_joints(self, q, speed: float, acceleration: float) -> None:
        self.commands.append(("joints", tuple(q)))
        if self.forward is not None:  # a test that gives the arm's kinematics moves the TCP
            self.q = np.asarray(q, float)
            self.queue = [self.forward(self.q)]
        else:
            self.queue = [self.pose]
        self.remaining = self.ticks_per_move
        self.state = MotionState.MOVING

    def servo(self, target: Pose) -> None:
        self.pose = target

    def servo_lag(self) -> float:
        return 0.0

    def force_mode(self, selection, wrench, speed_limits) -> None:
        self.commands.append(("force", tuple(wrench)))
        self.force = (np.asarray(selection, bool), np.asarray(wrench, float),
                      np.asarray(speed_limits, float))
        self.queue = []
        self.state = MotionState.MOVING

    def stop(self) -> None:
        self.stops += 1
        self.queue = []
        self.force = None
        self.state = MotionState.STOPPED

    def status(self) -> ArmStatus:
        return ArmStatus(self.state)

    def joint_positions(self) -> np.ndarray:
        return self.q

    def tick(self) -> None:
        if self.state is MotionState.MOVING and self.force is not None:
            if not self.blocked:
                sel, wrench, limits = self.force
                step = np.where(sel[:3], np.sign(wrench[:3]) * limits[:3], 0.0) * self.dt
                self.pose = Pose(self.pose.position + step, self.pose.rotation)
            return
        if self.state is MotionState.MOVING and self.queue:
            self.remaining -= 1
            if self.remaining <= 0:
                self.pose = self.queue[-1]
                self.queue = []
                self.state = MotionState.DONE
                if self.inverse is not None:
                    self.q = self.inverse(self.pose, self.q)


class FakeGripper:
    stroke = 0.085
    finger_width = 0.020

    def __init__(self, object_width: float | None = 0.003) -> None:
        self.object_width = object_width
        self._width = 0.085
        self._target = 0.085
        self._moving = False
        self.closed_on: float | None = None
        #: m per tick the jaws move; None: they reach the target in one tick
        self.step: float | None = None

    def open(self, width: float | None = None, speed: float = 0.1) -> None:
        self._target = self.stroke if width is None else width
        self._moving = True
        self.closed_on = None

    def close(self, force: float, speed: float = 0.05, width: float = 0.0) -> None:
        self._target = max(width, self.object_width if self.object_width is not None else 0.0)
        self._moving = True
        self.closed_on = self.object_width

    def width(self) -> float:
        return self._width

    def moving(self) -> bool:
        return self._moving

    def object_detected(self) -> bool:
        return self.closed_on is not None and not self._moving

    def tip_advance(self, width: float) -> float:
        return 0.0  # fingers on a slide

    def fault(self) -> str | None:
        return None

    def tick(self) -> None:
        if self._moving:
            gap = self._target - self._width
            if self.step is not None and abs(gap) > self.step:
                self._width += math.copysign(self.step, gap)
                return
            self._width = self._target
            self._moving = False


class FakeFT:
    def __init__(self) -> None:
        self.value = np.zeros(6)

    def wrench(self) -> np.ndarray:
        return self.value.copy()

    def bias(self) -> None:
        self.value = np.zeros(6)

    def age(self) -> float:
        return 0.0


def run(skill, devices, max_ticks: int = 2000, on_tick=None):
    """Tick ``skill`` until it is done; advance the fakes between ticks like the world would."""
    clock = devices["clock"]
    for i in range(max_ticks):
        if on_tick:
            on_tick(i)
        result = skill.tick()
        if result.done:
            return result, i
        devices["arm"].tick()
        devices["gripper"].tick()
        clock.t += clock.dt
    raise AssertionError("skill did not finish")
