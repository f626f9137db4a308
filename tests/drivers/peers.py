"""The driver tests' protocol peers: the device emulators of ``sim/emulate`` (written from the
devices' manuals), set up as the driver tests need them.

Nothing here speaks a protocol. Framing, register maps, the CRC, replies and state machines are
the emulators' own, and neither they nor this module import a driver's protocol code
(tests/drivers/test_peers.py checks it), so a driver is never checked against itself. The
RTDE receive side runs the emulated controller in its own process:
:class:`sim.emulate.ur_standalone.URAloneProcess` with ``arm="still"``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from sim.emulate.ft300_stream import FT300Emulator
from sim.emulate.gripper_server import Gripper2F85, LinearFingers
from sim.emulate.ur_controller import ControllerSettings, DashboardServer, StillArm, URController

#: The FT300 peer's reading unless a test gives its own (N, N*m)
FT300_LOAD = (1.0, -2.0, 3.5, 0.1, -0.2, 0.3)


class SequenceLoad:
    """A :class:`~sim.emulate.ft300_stream.WrenchBackend` whose n-th reading (from 1) is
    ``wrench_of(n)``. The emulator takes one reading per stream frame (and one per register
    read, which the driver never asks for), so n numbers the frames."""

    def __init__(self, wrench_of: Callable[[int], Sequence[float]]) -> None:
        self.wrench_of = wrench_of
        self.n = 0

    def wrench(self) -> NDArray[np.float64]:
        self.n += 1
        return np.asarray(self.wrench_of(self.n), float)


def ft300_peer(wrench_of: Callable[[int], Sequence[float]] = lambda n: FT300_LOAD,
               unit_id: int = 9) -> FT300Emulator:
    """An FT300 on a pseudo-terminal (not started): the emulator without noise or power-up
    offset, so each frame carries ``wrench_of(n)`` to the count, with every frame logged."""
    return FT300Emulator(SequenceLoad(wrench_of), unit_id=unit_id, force_noise=0.0,
                         moment_noise=0.0, force_offset=0.0, moment_offset=0.0, log_frames=True)


#: Where the peer gripper's fingers stop, fully open and fully closed (position counts)
GRIPPER_OPEN, GRIPPER_CLOSED = 4, 227


def gripper(time_scale: float = 5.0) -> Gripper2F85:
    """A 2F-85 whose fingers (:class:`LinearFingers`, ``.fingers``) stop at counts 4 and 227 and
    move ``time_scale`` times faster than real, so activations and strokes stay short."""
    t0 = time.monotonic()
    fingers = LinearFingers(clock=lambda: t0 + (time.monotonic() - t0) * time_scale)
    return Gripper2F85(fingers, open_count=GRIPPER_OPEN, closed_count=GRIPPER_CLOSED)


def dashboard_peer(**settings: object) -> DashboardServer:
    """The emulated controller's dashboard server alone (not started: ``with`` it), on
    127.0.0.1 and a free port, over a still arm. By default a controller just booted
    (POWER_OFF), serial ``2018300123``, whose protective stop unlocks at once; ``settings``:
    other :class:`ControllerSettings`."""
    values: dict[str, object] = {"serial": "2018300123", "robot_mode": "POWER_OFF",
                                 "unlock_delay": 0.0}
    values.update(settings)
    controller = URController(StillArm(), ControllerSettings(**values))  # type: ignore[arg-type]
    return DashboardServer(controller, "127.0.0.1", 0)


def protective_stop(server: DashboardServer, reason: str = "injected by the test") -> None:
    """Trip the controller's protective stop and run the cycle that takes it."""
    server.controller.raise_protective_stop(reason)
    server.controller.cycle()
