"""Helpers for the emulator tests: a twin stepped in real time on its own thread, and plain
kinematic fingers for the protocol tests that need no physics."""

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


class LinearFingers:
    """Fingers that move at the commanded speed (opening changes at twice it) and stop on an
    object of ``object_width`` m when closing past it: a FingerBackend for protocol tests."""

    stroke = 0.085

    def __init__(self, width: float = 0.085, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.object_width: float | None = None
        self.commands: list[tuple[float, float, float]] = []
        self._lock = threading.Lock()
        self._w0, self._t0, self._target, self._rate = width, clock(), width, 0.0
        self._stop_at = width

    def command(self, width: float, speed: float, force: float) -> None:
        with self._lock:
            now = self.clock()
            w = self._at(now)
            self.commands.append((width, speed, force))
            self._w0, self._t0, self._target = w, now, width
            self._rate = 2 * speed
            self._stop_at = width
            ow = self.object_width
            if ow is not None and width < w and width < ow <= w:
                self._stop_at = ow

    def _at(self, now: float) -> float:
        span = self._stop_at - self._w0
        moved = self._rate * (now - self._t0)
        return self._stop_at if abs(span) <= moved else self._w0 + moved * (1 if span > 0 else -1)

    def width(self) -> float:
        with self._lock:
            return self._at(self.clock())

    def moving(self) -> bool:
        with self._lock:
            return self._at(self.clock()) != self._stop_at

    def tip_advance(self, width: float) -> float:
        return 0.0

    def object_detected(self) -> bool:
        with self._lock:
            return self._stop_at != self._target and not self.moving_unlocked()

    def moving_unlocked(self) -> bool:
        return self._at(self.clock()) != self._stop_at


def crc16(data: bytes) -> int:
    """The Modbus RTU CRC of ``data`` (its low byte is sent first), as pymodbus's RTU framer
    computes it: an implementation apart from the emulators' own, so a wrong CRC there fails
    here instead of agreeing with itself."""
    from pymodbus.framer import FramerRTU

    return int.from_bytes(FramerRTU.compute_CRC(data).to_bytes(2, "big"), "little")

