"""Helpers for the emulator tests: a twin stepped in real time on its own thread, and a
reference CRC apart from the emulators' own. (The fingers without physics for the protocol tests
are the emulator's own :class:`sim.emulate.gripper_server.LinearFingers`.)"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from sim.robot import SimRobot
from sim.world import SimWorld


class RealTimeStepper:
    """Steps ``world`` at its control rate against the wall clock on a thread (as the emulator's
    loop does), holding ``lock`` during each step so other threads may use PyBullet between
    steps. ``slowest`` records the largest lag behind real time (s)."""

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        self.lock = threading.Lock()
        self.lag = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="twin-stepper", daemon=True)

    def start(self) -> RealTimeStepper:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def _run(self) -> None:
        dt = self.world.settings.control_dt
        t_next = time.monotonic()
        while not self._stop.is_set():
            with self.lock:
                self.world.step()
            t_next += dt
            now = time.monotonic()
            self.lag = max(self.lag, now - t_next)
            if t_next > now:
                time.sleep(t_next - now)
            elif now - t_next > 0.5:
                t_next = now  # far behind (a slow machine): do not try to catch up in a burst


@pytest.fixture
def twin() -> Iterator[tuple[SimWorld, SimRobot]]:
    with SimWorld(seed=11) as world:
        yield world, SimRobot(world)


def wait_for(pred: Callable[[], bool], timeout: float = 3.0, tick: float = 0.005) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(tick)
    return pred()


def crc16(data: bytes) -> int:
    """The Modbus RTU CRC of ``data`` (its low byte is sent first), as pymodbus's RTU framer
    computes it: an implementation apart from the emulators' own, so a wrong CRC there fails
    here instead of agreeing with itself."""
    from pymodbus.framer import FramerRTU

    return int.from_bytes(FramerRTU.compute_CRC(data).to_bytes(2, "big"), "little")

