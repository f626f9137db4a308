"""The 2F-85 driver against the emulator (sim/emulate/gripper_server.py), which answers as
Robotiq's manual and URCap do: the URCap's bare ``ack``, its ``?``, its variable names, and the
pymodbus release the driver needs to address its unit at all."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import pymodbus
import pytest

from drivers.health import DeviceError
from drivers.robotiq_gripper import ModbusRtuTransport, Robotiq2F85, UrcapSocketTransport
from sim.emulate.gripper_server import Gripper2F85, LinearFingers, ModbusRtuServer, UrcapServer
from tests.drivers.robotiq.conftest import wait_for

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def fingers() -> LinearFingers:
    return LinearFingers()


@pytest.fixture
def device(fingers: LinearFingers) -> Gripper2F85:
    return Gripper2F85(fingers)


@pytest.fixture
def urcap(device: Gripper2F85) -> Iterator[UrcapServer]:
    with UrcapServer(device, port=0) as server:
        yield server


def urcap_gripper(server: UrcapServer, stale_after: float = 0.5) -> Robotiq2F85:
    return Robotiq2F85(UrcapSocketTransport(server.host, server.port, timeout=0.1,
                                            backoff_first=0.02),
                       poll_hz=25.0, stale_after=stale_after)


def test_urcap_activation_and_a_grip_with_the_bare_ack(urcap: UrcapServer,
                                                       fingers: LinearFingers) -> None:
    gripper = urcap_gripper(urcap)
    try:
        gripper.activate(timeout=5.0)  # every SET is answered "ack" with no newline
        fingers.object_width = 0.030
        gripper.close(force=50.0, speed=0.15)
        assert wait_for(lambda: not gripper.moving(), 3.0)
        assert gripper.fault() is None and gripper.object_detected()
        st, _ = gripper.status()
        assert st is not None and st.cu is None  # the URCap has no current variable
        assert gripper.check().details["current"] == "not readable here"
    finally:
        gripper.disconnect()
    gets = {line.split()[1] for line in urcap.lines if line.startswith("GET")}
    assert gets == {"ACT", "GTO", "STA", "OBJ", "FLT", "PRE", "POS"}  # never GET COU


def test_a_question_mark_is_an_answer_not_a_timeout(urcap: UrcapServer) -> None:
    transport = UrcapSocketTransport(urcap.host, urcap.port, timeout=0.5, retries=2)
    transport.connect()
    try:
        t0 = time.monotonic()
        with pytest.raises(DeviceError, match="answered '\\?': the URCap does not know COU"):
            transport._get("COU")
        assert time.monotonic() - t0 < 0.4  # no wait for a newline, no retries
        assert transport._get("STA") == 0  # the link stays in step after it
    finally:
        transport.close()


def test_a_pulled_cable_on_the_urcap_socket_makes_the_status_stale(urcap: UrcapServer) -> None:
    gripper = urcap_gripper(urcap, stale_after=0.3).start()
    try:
        assert wait_for(lambda: gripper.status()[0] is not None, 2.0)
        urcap.pull_cable()
        assert wait_for(lambda: "status stale" in (gripper.fault() or ""), 2.0)
        urcap.restore()
        assert wait_for(lambda: gripper.fault() is None, 5.0)
    finally:
        gripper.disconnect()


def test_the_driver_addresses_its_own_unit(device: Gripper2F85) -> None:
    with ModbusRtuServer(device, unit_id=7) as rtu:
        gripper = Robotiq2F85(ModbusRtuTransport(rtu.port, unit_id=7, timeout=0.1))
        try:
            gripper.activate(timeout=5.0)
        finally:
            gripper.disconnect()
    assert rtu.requests > 3 and rtu.other_units == 0


def test_an_old_pymodbus_is_refused_by_name(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pymodbus, "__version__", "3.9.2")
    with pytest.raises(DeviceError, match="pymodbus 3.9.2 is too old.*>= 3.10"):
        ModbusRtuTransport("/dev/null")


#: Folders holding an older pymodbus (os.pathsep-separated), e.g. made with
#: ``pip install --no-deps --target DIR pymodbus==3.9.2``; the test below runs once per folder.
OLD_PYMODBUS = [p for p in os.environ.get("PIVOT_OLD_PYMODBUS", "").split(os.pathsep) if p]

_SCRIPT = textwrap.dedent("""
    import pymodbus
    from drivers.health import DeviceError
    from drivers.robotiq_gripper import ModbusRtuTransport, Robotiq2F85
    from sim.emulate.gripper_server import Gripper2F85, ModbusRtuServer
    from sim.emulate.gripper_server import LinearFingers
    with ModbusRtuServer(Gripper2F85(LinearFingers())) as rtu:
        try:
            transport = ModbusRtuTransport(rtu.port, timeout=0.05)
        except DeviceError as exc:
            print("REFUSED", pymodbus.__version__, exc)
            raise SystemExit(0)
        gripper = Robotiq2F85(transport, poll_hz=50.0, stale_after=0.2)
        try:
            gripper.activate(timeout=2.0)
            print("ACTIVATED", pymodbus.__version__)
        except DeviceError as exc:
            print("FAILED", pymodbus.__version__, exc, "| unit-9 requests:", rtu.requests)
        finally:
            gripper.disconnect()
""")


@pytest.mark.skipif(not OLD_PYMODBUS, reason="PIVOT_OLD_PYMODBUS names no older pymodbus")
@pytest.mark.parametrize("folder", OLD_PYMODBUS)
def test_with_an_older_pymodbus_the_driver_refuses_to_start(folder: str) -> None:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([folder, str(ROOT)]))
    out = subprocess.run([sys.executable, "-c", _SCRIPT], cwd=ROOT, env=env, text=True,
                         capture_output=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("REFUSED"), out.stdout
