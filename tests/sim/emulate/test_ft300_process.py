"""The FT300 emulator in its own process: the real driver reads the twin's wrist through it at
the stream's rate, a load step injected in the parent reaches the stream, and the cable."""

from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.ft300 import FT300
from sim.emulate.ft300_process import FT300Process

from .conftest import RealTimeStepper, wait_for

pytest.importorskip("serial")


def test_the_driver_reads_the_twins_wrist_from_the_sensors_own_process(twin) -> None:  # noqa: ANN001
    world, robot = twin
    stepper = RealTimeStepper(world).start()
    emu = FT300Process(robot.ft, world, seed=1).start()
    ft = FT300(emu.port, stale_after=0.05)
    try:
        ft.start()
        time.sleep(0.6)
        stats = ft.stats()
        assert 90 <= stats["rate_hz"] <= 110 and stats["crc_errors"] == 0
        ft.bias()
        time.sleep(0.1)
        assert np.all(np.abs(ft.wrench()[:3]) < 0.5)
        # a collision as the sensor reads it, injected in the emulator's process
        emu.wrist.inject(np.array([0.0, 0.0, 40.0, 0.0, 0.0, 0.0]))
        assert wait_for(lambda: ft.wrench()[2] > 35.0, 1.0)
        assert emu.wrist.first_stepped is not None
        emu.wrist.clear()
        assert wait_for(lambda: abs(ft.wrench()[2]) < 1.0, 1.0)
        frames, gap, late = emu.stats()
        assert frames > 50 and 0.0 < gap < 0.2
        emu.pull_cable()  # nothing streams: the driver's reading goes stale
        assert wait_for(lambda: ft.age() > 0.1, 2.0)
    finally:
        ft.stop()
        emu.close()
        stepper.stop()


def test_a_port_it_cannot_listen_on_is_an_error_in_the_parent(twin) -> None:  # noqa: ANN001
    world, robot = twin
    with pytest.raises(OSError):
        FT300Process(robot.ft, world, listen=("203.0.113.7", 1)).start()  # not this host's
