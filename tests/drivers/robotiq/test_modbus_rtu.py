"""The driver against the emulated 2F-85's Modbus RTU slave on a real pseudo-terminal."""

from __future__ import annotations

import time

import pytest

from drivers.gripper import Gripper
from drivers.health import DeviceError
from drivers.robotiq_gripper import ModbusRtuTransport, Robotiq2F85
from drivers.robotiq_gripper.registers import force_count, speed_count
from sim.emulate.gripper_server import ModbusRtuServer
from skills.motion import Guard, gripper_motion
from skills.status import Status
from tests.drivers.peers import gripper as peer_gripper
from tests.drivers.robotiq.conftest import STALE, TIMEOUT, Rig, settle, wait_for
from tests.skills.fakes import FakeArm, FakeClock, FakeFT

READ_FRAME = 8  # bytes of one RTU "read 3 registers" request: id, fc, addr 2, count 2, crc 2


def test_implements_the_gripper_interface(rtu: Rig) -> None:
    assert isinstance(rtu.gripper, Gripper)
    assert rtu.gripper.stroke == pytest.approx(0.085)


def test_activation_resets_then_activates_and_check_reports_it(rtu: Rig) -> None:
    g = rtu.gripper
    g.activate(timeout=2.0)
    assert g.activated()
    first_two = rtu.device.requests[:2]
    assert [(r.act, r.gto) for r in first_two] == [(False, False), (True, False)]
    result = g.check()
    assert result.ok, result
    assert result.device == "2F-85" and "unit 9" in result.address
    assert result.details["activation"] == "activation completed"
    assert result.details["fault"] == "none"
    assert result.details["position"].startswith("4/255")
    assert result.details["transport"] == "modbus-rtu"
    # The real gripper's functions: 16 to write the request, 4 to read the status.
    assert set(rtu.modbus.functions) == {4, 16}


def test_non_blocking_activation_is_polled_over_ticks(rtu: Rig) -> None:
    g = rtu.gripper.start()
    t0 = time.monotonic()
    g.start_activation()
    assert time.monotonic() - t0 < 0.005  # returns at once: the tick is not held
    assert not g.activated()
    assert wait_for(g.activated, timeout=2.0)


def test_check_without_activation_fails_with_the_reason(rtu: Rig) -> None:
    result = rtu.gripper.check()
    assert not result.ok
    assert "not activated" in result.error


def test_calibrate_then_open_and_close_to_a_width(rtu: Rig) -> None:
    g = rtu.gripper
    g.activate(timeout=2.0)
    cal = g.calibrate(timeout=3.0)
    assert (cal.open_count, cal.closed_count) == (4, 227)  # the peer unit's own limits
    t0 = time.monotonic()
    g.close(force=50.0, speed=0.15, width=0.030)
    assert time.monotonic() - t0 < 0.005
    assert g.moving()  # at once, before any status confirmed the new request
    settle(g)
    assert g.width() == pytest.approx(0.030, abs=0.0004)
    assert not g.object_detected()
    g.open(0.060, speed=0.15)
    settle(g)
    assert g.width() == pytest.approx(0.060, abs=0.0004)
    g.open()
    settle(g)
    assert g.width() == pytest.approx(0.085, abs=0.0004)
    assert rtu.device.requests[-1].position == 0


def test_closing_on_an_object_detects_it(rtu: Rig) -> None:
    g = rtu.gripper
    g.activate(timeout=2.0)
    g.calibrate(timeout=3.0)  # ends closed
    g.open()
    settle(g)
    rtu.fingers.object_width = 0.040
    g.close(force=80.0, speed=0.15)
    settle(g)
    assert g.object_detected()
    assert g.width() == pytest.approx(0.040, abs=0.0004)
    st, _ = g.status()
    assert st.obj == 2 and st.cu > 0
    g.open()  # a new motion clears the detection
    assert not g.object_detected()
    settle(g)
    assert not g.object_detected()


def test_force_and_speed_reach_the_registers_and_speed_sets_the_pace(rtu: Rig) -> None:
    g = rtu.gripper
    g.activate(timeout=2.0)
    durations = {}
    for speed, force in ((0.15, 235.0), (0.02, 20.0)):
        g.open()
        settle(g)
        t0 = time.monotonic()
        g.close(force=force, speed=speed, width=0.055)
        settle(g)
        durations[speed] = time.monotonic() - t0
        req = rtu.device.requests[-1]
        assert (req.speed, req.force) == (speed_count(speed), force_count(force))
    assert [(r.speed, r.force) for r in rtu.device.requests if r.gto][-3:] == [
        (255, 255), (speed_count(0.1), force_count(100.0)), (0, 0)]
    # 30 mm at 150 vs 20 mm/s a finger (the peer runs 5x fast): ~0.02 s vs ~0.15 s
    assert durations[0.02] > 0.1
    assert durations[0.02] > 2.5 * durations[0.15]


def test_fault_codes_surface_as_text_and_fail_the_guarded_motion(rtu: Rig) -> None:
    g = rtu.gripper
    g.activate(timeout=2.0)
    rtu.device.inject_fault(0x08)
    assert wait_for(lambda: g.fault() is not None)
    assert g.fault() == ("fault 0x08: maximum operating temperature exceeded (>= 85 C "
                         "internally); let it cool below 80 C")
    arm, clock = FakeArm(), FakeClock()
    motion = gripper_motion("grip", g, arm, FakeFT(), clock, Guard(), lambda: g.close(50.0))
    result = motion.tick()
    assert result.status is Status.FAILURE
    assert "gripper fault: fault 0x08: maximum operating temperature" in result.message
    check = g.check()
    assert not check.ok and "0x08" in check.error


def test_motion_before_activation_reports_fault_07(rtu: Rig) -> None:
    g = rtu.gripper.start()
    g.close(force=50.0)
    assert wait_for(lambda: g.fault() is not None and "0x07" in g.fault())
    assert "activation bit must be set" in g.fault()
    assert not g.moving()  # gGTO with no motion: nothing to wait for


def test_wrong_unit_id_gets_no_answer_and_names_port_and_unit(
        rtu_server: ModbusRtuServer) -> None:
    transport = ModbusRtuTransport(rtu_server.port, unit_id=10, timeout=TIMEOUT, retries=2,
                                   backoff_first=0.02)
    transport.connect()
    try:
        t0 = time.monotonic()
        with pytest.raises(DeviceError) as err:
            transport.read_status()
        elapsed = time.monotonic() - t0
    finally:
        transport.close()
    assert err.value.device == "2F-85"
    assert rtu_server.port in err.value.address and "unit 10" in err.value.address
    assert "no answer" in err.value.cause and "3 tries" in err.value.cause
    assert rtu_server.received_bytes == 3 * READ_FRAME  # exactly retries + 1 requests
    assert rtu_server.requests == 0 and not rtu_server.functions  # unit 9 stayed silent
    assert rtu_server.other_units == 3
    assert elapsed < 3 * TIMEOUT + 0.02 + 0.04 + 0.1


def test_a_peer_that_never_answers_costs_bounded_tries_with_back_off(
        rtu_server: ModbusRtuServer) -> None:
    # The gripper's cable is out: every request goes unanswered.
    rtu_server.pull_cable()
    transport = ModbusRtuTransport(rtu_server.port, timeout=TIMEOUT, retries=2,
                                   backoff_first=0.02)
    g = Robotiq2F85(transport, poll_hz=100.0, stale_after=STALE)
    result = g.check(timeout=0.5)
    assert not result.ok
    assert "no answer to the status request" in result.error
    assert rtu_server.port in result.address
    time.sleep(1.0)
    frames = rtu_server.received_bytes // READ_FRAME
    g.disconnect()
    # At 100 Hz polling a retry storm would send ~100+ frames a second; the back-off (after
    # each failed 3-try cycle: 0.02, 0.04, 0.08, ... s) keeps it to a few cycles.
    assert 3 <= frames <= 8 * 3, frames
    assert g.fault() is not None and "no status received yet" in g.fault()


def test_a_pulled_cable_makes_the_status_stale_and_recovers(rtu: Rig) -> None:
    g = rtu.gripper
    g.activate(timeout=2.0)
    assert g.fault() is None
    rtu.modbus.pull_cable()
    t_cut = time.monotonic()
    assert wait_for(lambda: g.fault() is not None, timeout=2.0)
    assert time.monotonic() - t_cut >= STALE - 0.01
    assert g.fault().startswith("status stale: newest is")
    # once the transport's bounded tries are spent, the cause rides along
    assert wait_for(lambda: "no answer to the status request" in (g.fault() or ""))
    rtu.modbus.restore()
    assert wait_for(lambda: g.fault() is None, timeout=3.0)


def test_an_undeliverable_command_is_dropped_and_reported(rtu: Rig) -> None:
    g = rtu.gripper
    g.activate(timeout=2.0)
    rtu.modbus.pull_cable()
    g.close(force=50.0)
    assert wait_for(lambda: not g.moving(), timeout=2.0)  # given up: nothing to wait for
    assert g.fault() is not None  # stale, then the cause
    rtu.modbus.restore()
    assert wait_for(lambda: g.status()[1] < 0.05)  # fresh status again
    assert g.fault().startswith("command not delivered: 2F-85 at")
    time.sleep(0.1)
    assert all(not r.gto for r in rtu.device.requests)  # never replayed late
    g.open()  # the next command clears it
    assert g.fault() is None


def test_status_function_3_also_works(rtu_server: ModbusRtuServer) -> None:
    transport = ModbusRtuTransport(rtu_server.port, timeout=TIMEOUT, status_function=3)
    transport.connect()
    try:
        assert transport.read_status().po == 4
    finally:
        transport.close()
    assert rtu_server.functions == {3: 1}


def test_wrong_port_names_it() -> None:
    transport = ModbusRtuTransport("/dev/does-not-exist-2f85", timeout=TIMEOUT)
    with pytest.raises(DeviceError) as err:
        transport.connect()
    assert "/dev/does-not-exist-2f85" in str(err.value)
    g = Robotiq2F85(ModbusRtuTransport("/dev/does-not-exist-2f85"))
    result = g.check()
    assert not result.ok and "cannot open serial port" in result.error


def test_the_peer_gripper_works_without_hardware() -> None:
    assert peer_gripper().get_var("STA") == 0
