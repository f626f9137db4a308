"""The 2F-85 emulator: the manual's own example frames byte for byte, the RS-485 rules, the
URCap socket's replies, the real driver against it (over the twin's fingers), and the cable."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import numpy as np
import pytest

from drivers.pose import Pose
from drivers.robotiq_gripper import (
    Calibration,
    ModbusRtuTransport,
    Robotiq2F85,
)
from drivers.ur5.kinematics import HOME_TCP
from sim.emulate.gripper_server import (
    FingerBackend,
    Gripper2F85,
    LinearFingers,
    ModbusRtuServer,
    TwinFingers,
    UrcapServer,
)

from ..conftest import add_box, add_floor, run_motion
from .conftest import RealTimeStepper, crc16, wait_for

serial = pytest.importorskip("serial")
pytest.importorskip("pymodbus")  # the reference CRC


@pytest.fixture
def fingers() -> LinearFingers:
    return LinearFingers()


@pytest.fixture
def device(fingers: LinearFingers) -> Gripper2F85:
    return Gripper2F85(fingers, open_count=3, closed_count=228)


@pytest.fixture
def rtu(device: Gripper2F85) -> Iterator[ModbusRtuServer]:
    with ModbusRtuServer(device) as server:
        yield server


@pytest.fixture
def line(rtu: ModbusRtuServer) -> Iterator[serial.Serial]:
    with serial.Serial(rtu.port, 115200, timeout=0.1) as s:
        yield s


def ask(line: serial.Serial, hexframe: str, expect: int) -> bytes:
    line.reset_input_buffer()
    line.write(bytes.fromhex(hexframe))
    return line.read(expect)


def with_crc(hexbody: str) -> str:
    body = bytes.fromhex(hexbody)
    return (body + crc16(body).to_bytes(2, "little")).hex()


# --- the manual's example session, byte for byte --------------------------------------------

def test_the_manuals_activation_example_frames(line: serial.Serial, fingers: LinearFingers
                                               ) -> None:
    assert isinstance(fingers, FingerBackend)
    # Clear rACT, then set it (the manual's two activation requests and their answer).
    assert ask(line, "09 10 03 E8 00 03 06 00 00 00 00 00 00 73 30", 8) == bytes.fromhex(
        "09 10 03 E8 00 03 01 30")
    assert ask(line, "09 10 03 E8 00 03 06 01 00 00 00 00 00 72 E1", 8) == bytes.fromhex(
        "09 10 03 E8 00 03 01 30")
    # Status while activating: gACT = 1, gSTA = 1 (0x11), then activated (0x31).
    assert ask(line, "09 03 07 D0 00 01 85 CF", 7) == bytes.fromhex("09 03 02 11 00 55 D5")
    assert fingers.commands[0][0] == 0.0  # the activation stroke closes first ...
    assert wait_for(lambda: ask(line, "09 03 07 D0 00 01 85 CF", 7)
                    == bytes.fromhex("09 03 02 31 00 4C 15"), 4.0)
    assert fingers.commands[1][0] == pytest.approx(0.085)  # ... then opens fully
    # Close at full speed and force (the manual's example), read all three status registers.
    assert ask(line, "09 10 03 E8 00 03 06 09 00 00 FF FF FF 42 29", 8) == bytes.fromhex(
        "09 10 03 E8 00 03 01 30")
    reply = ask(line, "09 04 07 D0 00 03 B1 CE", 11)
    assert reply[:3] == bytes.fromhex("09 04 06") and crc16(reply[:-2]) == int.from_bytes(
        reply[-2:], "little")
    assert reply[3] == 0x39  # gACT, gGTO, gSTA = 3, gOBJ = 0: moving
    assert reply[5:7] == bytes([0x00, 0xFF])  # no fault, gPR echoes 255
    assert wait_for(lambda: ask(line, "09 04 07 D0 00 03 B1 CE", 11)[3] == 0xF9, 3.0)
    assert ask(line, "09 04 07 D0 00 03 B1 CE", 11)[7] == 228  # this unit's closed stop


def test_rs485_rules_other_units_broadcast_crc_and_exceptions(
    line: serial.Serial, rtu: ModbusRtuServer, device: Gripper2F85
) -> None:
    assert ask(line, with_crc("0A 03 07 D0 00 03"), 5) == b""  # unit 10: not us, silent
    assert rtu.other_units == 1
    bad = bytearray(bytes.fromhex("09 03 07 D0 00 01 85 CF"))
    bad[-1] ^= 0xFF
    assert ask(line, bad.hex(), 5) == b""  # damaged frame: dropped, no answer
    assert rtu.crc_errors >= 1
    # Broadcast (unit 0): executed, never answered.
    assert ask(line, with_crc("00 10 03 E8 00 03 06 01 00 00 00 00 00"), 8) == b""
    assert device.output_bytes()[0] == 0x01
    # An address outside the map: exception 02; an unknown function: exception 01.
    assert ask(line, with_crc("09 03 00 00 00 01"), 5) == bytes.fromhex(with_crc("09 83 02"))
    assert ask(line, with_crc("09 10 07 D0 00 01 02 00 00"), 5) == bytes.fromhex(
        with_crc("09 90 02"))
    assert ask(line, with_crc("09 05 00 01 FF 00"), 5) == bytes.fromhex(with_crc("09 85 01"))
    # Function 23 (read/write in one request) writes first, then reads.
    reply = ask(line, with_crc("09 17 07 D0 00 03 03 E8 00 03 06 00 00 00 00 00 00"), 11)
    assert reply[:3] == bytes.fromhex("09 17 06") and reply[3] == 0x00  # reset: gACT 0


def test_a_go_to_before_activation_is_fault_07_and_during_it_05_then_runs(
    device: Gripper2F85, fingers: LinearFingers
) -> None:
    device.write_output(0, bytes([0x08, 0, 0, 200, 255, 10]))  # rGTO without rACT
    assert device.input_bytes()[2] == 0x07 and fingers.commands == []
    device.write_output(0, bytes([0x00, 0, 0, 0, 0, 0]))  # reset clears it
    assert device.input_bytes()[2] == 0x00
    device.write_output(0, bytes([0x01, 0, 0, 0, 0, 0]))  # activate
    device.write_output(0, bytes([0x09, 0, 0, 100, 255, 10]))  # go-to while activating
    st = device.input_bytes()
    assert st[0] >> 4 & 3 == 1 and st[2] == 0x05
    assert wait_for(lambda: device.input_bytes()[2] == 0 and device.input_bytes()[4] == 100, 4.0)
    assert fingers.commands[-1][0] == pytest.approx(device.width_of(100))


def test_an_object_stops_the_fingers_with_gobj_2(device: Gripper2F85,
                                                 fingers: LinearFingers) -> None:
    device.write_output(0, bytes([0x01, 0, 0, 0, 0, 0]))
    assert wait_for(lambda: device.input_bytes()[0] >> 4 & 3 == 3, 4.0)
    fingers.object_width = 0.040
    device.write_output(0, bytes([0x09, 0, 0, 255, 255, 128]))
    assert wait_for(lambda: device.input_bytes()[0] >> 6 == 2, 3.0)
    st = device.input_bytes()
    assert st[4] == device.count_of(0.040) and st[5] > 0  # stopped at the part, current flows
    device.write_output(0, bytes([0x09, 0, 0, 0, 255, 128]))  # open: away from the part
    assert wait_for(lambda: device.input_bytes()[0] >> 6 == 3, 3.0)
    assert device.input_bytes()[4] == 3


# --- the URCap socket -----------------------------------------------------------------------

def test_urcap_answers_a_bare_ack_values_with_newline_and_question_mark(
    device: Gripper2F85,
) -> None:
    with UrcapServer(device, port=0) as urcap, socket.create_connection(
        (urcap.host, urcap.port), timeout=1.0
    ) as s:
        s.sendall(b"SET ACT 1\n")
        time.sleep(0.05)
        assert s.recv(100) == b"ack"  # three bytes, nothing after them
        s.sendall(b"GET STA\n")
        assert s.recv(100) in (b"STA 1\n", b"STA 3\n")
        s.sendall(b"GET COU\n")  # not a URCap variable
        assert s.recv(100) == b"?"
        s.sendall(b"SET POS 300\n")  # out of range: refused, nothing written
        assert s.recv(100) == b"?"
        assert wait_for(lambda: device.get_var("STA") == 3, 4.0)
        s.sendall(b"SET POS 128 SPE 255 FOR 0 GTO 1\n")
        assert s.recv(100) == b"ack"
        s.sendall(b"GET PRE\n")
        assert s.recv(100) == b"PRE 128\n"
        assert urcap.lines[-1] == "GET PRE"


# --- the real driver against the emulator, the twin's fingers -------------------------------

def test_the_driver_grips_a_box_with_the_twins_fingers_over_modbus(twin) -> None:  # noqa: ANN001
    world, robot = twin
    add_floor(world)
    add_box(world, [0.02, 0.015, 0.03], [0.5, 0.0, 0.03], mass=0.1)  # 40 mm along x
    robot.arm.move_to(Pose(np.array([0.5, 0.0, 0.04]), HOME_TCP.rotation), 0.2, 1.0)
    run_motion(world, robot)
    device = Gripper2F85(TwinFingers(robot.gripper, world))
    stepper = RealTimeStepper(world).start()
    server = ModbusRtuServer(device).start()
    # The unit's stops (3 and 228), as `calibrate` would measure them on an empty gripper.
    gripper = Robotiq2F85(ModbusRtuTransport(server.port, timeout=0.1), Calibration(3, 228),
                          poll_hz=50.0, stale_after=0.5)
    try:
        gripper.activate(timeout=10.0)  # the activation stroke runs on the twin's fingers
        assert robot.gripper.width() == pytest.approx(0.085, abs=2e-3)
        gripper.close(force=40.0, speed=0.05)
        assert wait_for(lambda: not gripper.moving(), 5.0)
        assert gripper.fault() is None
        assert gripper.object_detected()
        assert robot.gripper.object_detected()
        assert gripper.width() == pytest.approx(robot.gripper.width(), abs=0.6e-3)  # 1 count
        assert gripper.width() == pytest.approx(0.040, abs=2e-3)
    finally:
        gripper.disconnect()
        server.close()
        stepper.stop()


# --- the cable --------------------------------------------------------------------------------

def test_a_pulled_cable_makes_the_driver_report_stale_status_and_recovers(
    rtu: ModbusRtuServer,
) -> None:
    gripper = Robotiq2F85(ModbusRtuTransport(rtu.port, timeout=0.05, backoff_first=0.02),
                          poll_hz=50.0, stale_after=0.2)
    try:
        gripper.activate(timeout=5.0)
        assert gripper.fault() is None
        rtu.pull_cable()
        assert wait_for(lambda: gripper.fault() is not None, 2.0)
        assert "status stale" in (gripper.fault() or "")
        assert rtu.dropped_bytes > 0
        rtu.restore()
        assert wait_for(lambda: gripper.fault() is None, 4.0)
    finally:
        gripper.disconnect()


def test_an_injected_fault_code_reaches_the_driver(rtu: ModbusRtuServer, device: Gripper2F85
                                                   ) -> None:
    gripper = Robotiq2F85(ModbusRtuTransport(rtu.port, timeout=0.05), poll_hz=50.0)
    try:
        gripper.activate(timeout=5.0)
        device.inject_fault(0x0E)
        assert wait_for(lambda: (gripper.fault() or "").startswith("fault 0x0E"), 2.0)
    finally:
        gripper.disconnect()


def test_a_pulled_cable_fails_a_guarded_gripper_motion_with_its_code(
    rtu: ModbusRtuServer, twin  # noqa: ANN001
) -> None:
    from drivers.clock import WallClock
    from skills.motion import Guard, gripper_motion
    from skills.status import Failure, Status

    world, robot = twin
    gripper = Robotiq2F85(ModbusRtuTransport(rtu.port, timeout=0.05, backoff_first=0.02),
                          poll_hz=50.0, stale_after=0.2)
    try:
        gripper.activate(timeout=5.0)
        motion = gripper_motion("close", gripper, robot.arm, robot.ft, WallClock(), Guard(),
                                lambda: gripper.close(force=40.0, speed=0.02))
        assert motion.tick().status is Status.RUNNING
        rtu.pull_cable()
        assert wait_for(lambda: motion.tick().status is Status.FAILURE, 2.0)
        result = motion.tick()
        assert result.code is Failure.GRIPPER_FAULT and "status stale" in result.message
    finally:
        gripper.disconnect()
