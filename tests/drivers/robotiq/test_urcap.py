"""The driver through the URCap socket transport against the emulated 2F-85's URCap socket on
localhost."""

from __future__ import annotations

import time

import pytest

from drivers.health import DeviceError
from drivers.robotiq_gripper import Robotiq2F85, UrcapSocketTransport, make_gripper
from sim.emulate.gripper_server import UrcapServer
from tests.addresses import free_port
from tests.drivers.robotiq.conftest import STALE, TIMEOUT, Rig, settle, wait_for


def test_activation_open_close_and_object_over_the_socket(urcap: Rig) -> None:
    g = urcap.gripper
    g.activate(timeout=2.0)
    lines = urcap.urcap.lines
    assert "SET GTO 0 ATR 0 ACT 0" in lines
    assert lines.index("SET GTO 0 ATR 0 ACT 0") < lines.index("SET POS 0 SPE 0 FOR 0 ATR 0 ACT 1 "
                                                             "GTO 0")
    result = g.check()
    assert result.ok, result
    assert result.details["transport"] == "urcap-socket"
    assert f":{urcap.urcap.port}" in result.address
    g.calibrate(timeout=3.0)
    g.open()
    settle(g)
    g.close(force=60.0, speed=0.15, width=0.020)
    settle(g)
    assert g.width() == pytest.approx(0.020, abs=0.0004)
    assert not g.object_detected()
    g.open()
    settle(g)
    urcap.fingers.object_width = 0.050
    g.close(force=235.0, speed=0.15)
    settle(g)
    assert g.object_detected()
    assert g.width() == pytest.approx(0.050, abs=0.0004)
    assert lines[-1].startswith("GET ")
    go = [ln for ln in lines if ln.startswith("SET POS")][-1]
    assert go == "SET POS 255 SPE 255 FOR 255 ATR 0 ACT 1 GTO 1"


def test_fault_code_over_the_socket(urcap: Rig) -> None:
    g = urcap.gripper
    g.activate(timeout=2.0)
    urcap.device.inject_fault(0x0E)
    assert wait_for(lambda: g.fault() == "fault 0x0E: overcurrent triggered")


def test_a_silent_controller_costs_bounded_tries(urcap_server: UrcapServer) -> None:
    urcap_server.pull_cable()  # reads every command, answers none
    transport = UrcapSocketTransport(urcap_server.host, urcap_server.port, timeout=TIMEOUT,
                                     retries=2, backoff_first=0.02)
    try:
        t0 = time.monotonic()
        with pytest.raises(DeviceError) as err:
            transport.read_status()
        elapsed = time.monotonic() - t0
    finally:
        transport.close()
    assert f"127.0.0.1:{urcap_server.port}" in err.value.address
    assert "no reply within" in err.value.cause and "3 tries" in err.value.cause
    assert urcap_server.lines == ["GET ACT"] * 3  # one try per reconnect, then give up
    assert urcap_server.connections == 3
    assert elapsed < 3 * TIMEOUT + 0.02 + 0.04 + 0.1


def test_refused_connection_names_the_address() -> None:
    port = free_port()
    g = Robotiq2F85(UrcapSocketTransport("127.0.0.1", port, timeout=TIMEOUT, retries=1,
                                         backoff_first=0.01))
    result = g.check()
    assert not result.ok
    assert result.address == f"127.0.0.1:{port} (URCap socket)"
    assert "cannot connect" in result.error and "refused" in result.error.lower()


def test_a_hung_controller_makes_the_status_stale(urcap: Rig) -> None:
    g = urcap.gripper
    g.activate(timeout=2.0)
    urcap.urcap.pull_cable()
    assert wait_for(lambda: (g.fault() or "").startswith("status stale"), timeout=2.0)
    assert wait_for(lambda: "no reply within" in (g.fault() or ""), timeout=2.0)
    urcap.urcap.restore()
    assert wait_for(lambda: g.fault() is None, timeout=3.0)  # reconnects by itself


def test_make_gripper_picks_the_transport() -> None:
    g = make_gripper("urcap-socket", host="10.0.0.2")
    assert isinstance(g.transport, UrcapSocketTransport) and g.poll_hz == 25.0
    assert g.stale_after == STALE + 0.3
    g = make_gripper("modbus-rtu", port="/dev/ttyUSB3", unit_id=9, open_count=3,
                     closed_count=228)
    assert "/dev/ttyUSB3 unit 9 (115200 baud)" == g.transport.address
    assert (g.calibration.open_count, g.calibration.closed_count) == (3, 228)
    with pytest.raises(ValueError, match="needs host"):
        make_gripper("urcap-socket")
    with pytest.raises(ValueError, match="unknown gripper transport"):
        make_gripper("ethercat")
