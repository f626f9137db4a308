"""Fixtures: a 2F-85 peer on a pty null modem (Modbus RTU) or on a localhost socket (URCap), and
the driver connected to it. Every fixture stops its servers and joins its threads on teardown."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from drivers.robotiq_gripper import ModbusRtuTransport, Robotiq2F85, UrcapSocketTransport
from tests.drivers.peers.gripper_modbus_peer import GripperModbusPeer, GripperModel, PtyNullModem
from tests.drivers.peers.urcap_peer import UrcapPeer

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
    model: GripperModel
    gripper: Robotiq2F85
    cable: PtyNullModem | None = None
    modbus: GripperModbusPeer | None = None
    urcap: UrcapPeer | None = None


@pytest.fixture
def model() -> GripperModel:
    return GripperModel(min_count=4, max_count=227, activation_time=1.0, time_scale=10.0)


@pytest.fixture
def cable() -> Iterator[PtyNullModem]:
    c = PtyNullModem()
    yield c
    c.close()


@pytest.fixture
def modbus_peer(cable: PtyNullModem, model: GripperModel) -> Iterator[GripperModbusPeer]:
    peer = GripperModbusPeer(cable.peer_path, model, unit_id=9)
    yield peer
    peer.stop()


@pytest.fixture
def rtu(cable: PtyNullModem, modbus_peer: GripperModbusPeer, model: GripperModel
        ) -> Iterator[Rig]:
    transport = ModbusRtuTransport(cable.driver_path, unit_id=9, timeout=TIMEOUT, retries=2,
                                   backoff_first=0.02)
    gripper = Robotiq2F85(transport, poll_hz=100.0, stale_after=STALE)
    yield Rig(model, gripper, cable=cable, modbus=modbus_peer)
    gripper.disconnect()


@pytest.fixture
def urcap_peer(model: GripperModel) -> Iterator[UrcapPeer]:
    peer = UrcapPeer(model)
    yield peer
    peer.stop()


@pytest.fixture
def urcap(urcap_peer: UrcapPeer, model: GripperModel) -> Iterator[Rig]:
    transport = UrcapSocketTransport(urcap_peer.host, urcap_peer.port, timeout=TIMEOUT,
                                     retries=2, backoff_first=0.02)
    gripper = Robotiq2F85(transport, poll_hz=50.0, stale_after=STALE)
    yield Rig(model, gripper, urcap=urcap_peer)
    gripper.disconnect()
