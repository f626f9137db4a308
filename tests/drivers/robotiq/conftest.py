"""Fixtures: the emulated 2F-85 (sim/emulate/gripper_server.py, its fingers without physics and
5x faster than real: tests/drivers/peers.py) as a Modbus RTU slave on a pseudo-terminal or
behind the URCap's localhost socket, and the driver connected to it. Every fixture stops its
servers and joins their threads on teardown."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from drivers.robotiq_gripper import ModbusRtuTransport, Robotiq2F85, UrcapSocketTransport
from sim.emulate.gripper_server import Gripper2F85, LinearFingers, ModbusRtuServer, UrcapServer
from tests.drivers.peers import gripper as peer_gripper

TIMEOUT = 0.05  # s per answer: the peers answer in ~2 ms, so failure tests stay short
STALE = 0.2  # s


def wait_for(pred: Callable[[], bool], timeout: float = 2.0, tick: float = 0.008) -> bool:
    """Poll ``pred`` like the tree does (one cheap call per tick) until it holds or time is up."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(tick)
    return pred()


def settle(gripper: Robotiq2F85, timeout: float = 3.0) -> None:
    """Tick until the fingers stop (as gripper_motion does); fail the test on a fault."""
    assert wait_for(lambda: not gripper.moving() or gripper.fault() is not None, timeout)
    assert gripper.fault() is None, gripper.fault()


@dataclass
class Rig:
    device: Gripper2F85
    gripper: Robotiq2F85
    modbus: ModbusRtuServer | None = None
    urcap: UrcapServer | None = None

    @property
    def fingers(self) -> LinearFingers:
        fingers = self.device.fingers
        assert isinstance(fingers, LinearFingers)
        return fingers


@pytest.fixture
def device() -> Gripper2F85:
    return peer_gripper()


@pytest.fixture
def rtu_server(device: Gripper2F85) -> Iterator[ModbusRtuServer]:
    with ModbusRtuServer(device, unit_id=9) as server:
        yield server


@pytest.fixture
def rtu(rtu_server: ModbusRtuServer, device: Gripper2F85) -> Iterator[Rig]:
    transport = ModbusRtuTransport(rtu_server.port, unit_id=9, timeout=TIMEOUT, retries=2,
                                   backoff_first=0.02)
    gripper = Robotiq2F85(transport, poll_hz=100.0, stale_after=STALE)
    yield Rig(device, gripper, modbus=rtu_server)
    gripper.disconnect()


@pytest.fixture
def urcap_server(device: Gripper2F85) -> Iterator[UrcapServer]:
    with UrcapServer(device, port=0) as server:
        yield server


@pytest.fixture
def urcap(urcap_server: UrcapServer, device: Gripper2F85) -> Iterator[Rig]:
    transport = UrcapSocketTransport(urcap_server.host, urcap_server.port, timeout=TIMEOUT,
                                     retries=2, backoff_first=0.02)
    gripper = Robotiq2F85(transport, poll_hz=50.0, stale_after=STALE)
    yield Rig(device, gripper, urcap=urcap_server)
    gripper.disconnect()
