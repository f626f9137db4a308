"""The FT300 emulator: the manual's request frames, the stream's format, rate and noise, the real
driver reading the twin's wrist through it, and the cable."""

from __future__ import annotations

import struct
import time
from collections.abc import Iterator

import numpy as np
import pytest

from drivers.ft300 import FT300
from drivers.health import DeviceError
from drivers.pose import Pose
from drivers.ur5.kinematics import HOME_TCP
from sim.emulate.ft300_stream import SCALE, FT300Emulator, TwinWrist, WrenchBackend
from skills.motion import Guard, arm_motion
from skills.status import Failure, Status

from .conftest import RealTimeStepper, crc16, wait_for

serial = pytest.importorskip("serial")
pytest.importorskip("pymodbus")  # the reference CRC

LOAD = np.array([1.5, -2.0, -20.0, 0.10, -0.05, 0.02])


class FixedLoad:
    def __init__(self, load: np.ndarray = LOAD) -> None:
        self.load = np.array(load, float)

    def wrench(self) -> np.ndarray:
        return self.load.copy()


def near(a: np.ndarray, b: np.ndarray, force: float, moment: float) -> None:
    err = np.abs(np.asarray(a) - np.asarray(b))
    assert np.all(err[:3] <= force) and np.all(err[3:] <= moment), f"{a} vs {b}"


@pytest.fixture
def load() -> FixedLoad:
    return FixedLoad()


@pytest.fixture
def emu(load: FixedLoad) -> Iterator[FT300Emulator]:
    with FT300Emulator(load, seed=5) as e:
        yield e


@pytest.fixture
def line(emu: FT300Emulator) -> Iterator[serial.Serial]:
    with serial.Serial(emu.port, 19200, timeout=0.2) as s:
        yield s


def test_modbus_read_of_registers_180_to_185_the_manuals_example(
    line: serial.Serial, emu: FT300Emulator, load: FixedLoad
) -> None:
    assert isinstance(load, WrenchBackend)
    line.write(bytes.fromhex("09 03 00 B4 00 06 84 A6"))  # the manual's read request
    reply = line.read(17)
    assert reply[:3] == bytes.fromhex("09 03 0C")
    assert crc16(reply[:-2]) == int.from_bytes(reply[-2:], "little")
    values = np.array(struct.unpack(">6h", reply[3:15])) / SCALE
    near(values, LOAD + emu.offset, 0.5, 0.025)
    line.write(bytes.fromhex("0A 03 00 B4 00 06") + crc16(bytes.fromhex("0A 03 00 B4 00 06"))
               .to_bytes(2, "little"))
    assert line.read(5) == b""  # another unit: silent
    assert not emu.streaming.is_set()


def test_the_tests_reference_crc_is_the_modbus_one() -> None:
    assert crc16(b"123456789") == 0x4B37  # the CRC-16/MODBUS check value
    frame = bytes.fromhex("09 03 00 B4 00 06 84 A6")  # the FT300 manual's read request
    assert crc16(frame[:-2]).to_bytes(2, "little") == frame[-2:]


def test_the_stream_frames_rate_and_noise(line: serial.Serial, emu: FT300Emulator) -> None:
    line.write(bytes.fromhex("09 10 01 9A 00 01 02 02 00 CD CA"))  # the manual's start request
    assert line.read(8) == bytes.fromhex("09 10 01 9A 00 01") + crc16(
        bytes.fromhex("09 10 01 9A 00 01")).to_bytes(2, "little")
    line.reset_input_buffer()
    t0 = time.monotonic()
    data = b""
    while time.monotonic() - t0 < 1.5:
        data += line.read(1600)
    elapsed = time.monotonic() - t0
    assert len(data) % 16 in range(16)
    frames = [data[i:i + 16] for i in range(data.index(b"\x20\x4e"), len(data) - 15, 16)]
    assert all(f[:2] == b"\x20\x4e" for f in frames)
    assert all(crc16(f[:14]) == int.from_bytes(f[14:], "little") for f in frames)
    assert 90 <= len(frames) / elapsed <= 105  # 100 Hz (16 bytes take 8.3 ms at 19200 bit/s)
    values = np.array([struct.unpack("<6h", f[2:14]) for f in frames]) / SCALE
    near(values.mean(axis=0), LOAD + emu.offset, 0.05, 0.003)
    std = values.std(axis=0)
    assert np.all((std[:3] > 0.07) & (std[:3] < 0.13))  # the datasheet's 0.1 N
    assert np.all((std[3:] > 0.0035) & (std[3:] < 0.0065))  # and 0.005 N*m
    # While streaming the sensor answers no request; a run of 0xFF ends the stream.
    line.write(b"\xff" * 50)
    assert wait_for(lambda: not emu.streaming.is_set(), 1.0)
    time.sleep(0.05)
    line.reset_input_buffer()
    line.write(bytes.fromhex("09 03 00 B4 00 06 84 A6"))
    assert line.read(17)[:3] == bytes.fromhex("09 03 0C")  # a Modbus slave again


def test_the_driver_reads_the_twins_wrist_through_the_emulator(twin) -> None:  # noqa: ANN001
    world, robot = twin
    stepper = RealTimeStepper(world).start()
    emu = FT300Emulator(TwinWrist(robot.ft), seed=1).start()
    ft = FT300(emu.port, stale_after=0.05)
    try:
        ft.start()
        time.sleep(0.6)
        stats = ft.stats()
        assert 90 <= stats["rate_hz"] <= 110 and stats["crc_errors"] == 0
        # The raw mean is the twin's load on the sensor plus the emulated offset.
        raw = ft.raw_mean()
        near(raw, robot.ft.sampled_true_load() + emu.offset, 0.15, 0.01)
        assert abs(robot.ft.sampled_true_load()[2]) > 5.0  # the tool's weight hangs on it
        ft.bias()
        time.sleep(0.1)
        assert np.all(np.abs(ft.wrench()[:3]) < 0.5)
    finally:
        ft.stop()
        emu.close()
        stepper.stop()


def test_a_pulled_cable_is_a_lost_stream_for_the_driver_and_the_guard(twin) -> None:  # noqa: ANN001
    world, robot = twin
    stepper = RealTimeStepper(world).start()
    emu = FT300Emulator(TwinWrist(robot.ft), seed=2).start()
    ft = FT300(emu.port, stale_after=0.05)
    try:
        ft.start()
        ft.bias()
        target = Pose(HOME_TCP.position + np.array([0.0, 0.0, -0.05]), HOME_TCP.rotation)
        motion = arm_motion("lower", robot.arm, ft, world.clock, Guard(),
                            lambda: robot.arm.move_to(target, 0.05, 0.5))
        with stepper.lock:
            assert motion.tick().status is Status.RUNNING
        emu.pull_cable()
        assert wait_for(lambda: ft.age() > 0.1, 1.0)
        with pytest.raises(DeviceError, match="stale stream"):
            ft.wrench()
        with stepper.lock:
            result = motion.tick()
        assert result.status is Status.FAILURE and result.code is Failure.DEVICE_LOST
        # Plugged back, the sensor powers up silent (a Modbus slave): the stream stays lost
        # until the driver starts it again, and the new power-up offset needs a new bias.
        offset = emu.offset.copy()
        emu.restore()
        time.sleep(0.2)
        assert ft.age() > 0.2 and not emu.streaming.is_set()
        ft.stop()
        ft.start()
        assert ft.age() < 0.05 and not np.allclose(emu.offset, offset)
    finally:
        ft.stop()
        emu.close()
        stepper.stop()


def test_the_stream_through_a_serial_device_servers_tcp_port(load: FixedLoad) -> None:
    """``listen=``: the line is a gateway's raw TCP port; the real driver opens it by its
    ``socket://`` URL (pyserial's serial_for_url), starts the stream with the manual's request
    and reads the load; a second client replaces the first, as a one-client gateway does."""
    with FT300Emulator(load, seed=5, listen=("127.0.0.1", 0)) as emu:
        assert emu.port.startswith("socket://127.0.0.1:")
        with FT300(emu.port, stale_after=0.5, bias_samples=50) as ft:
            assert wait_for(lambda: ft.stats()["frames"] >= 60, timeout=5.0)
            near(ft.raw_mean(), load.load + emu.offset, 0.05, 0.005)
            assert ft.stats()["crc_errors"] == 0
            rate = ft.stats()["rate_hz"]
            assert 80.0 <= rate <= 110.0, rate
        assert wait_for(lambda: not emu.streaming.is_set(), timeout=2.0)  # the 0xFF run stopped it
        with FT300(emu.port, stale_after=0.5) as ft:
            assert wait_for(lambda: ft.stats()["frames"] >= 5, timeout=5.0)
        assert emu.clients == 2


def test_a_force_step_adds_to_the_twins_load_and_stamps_its_first_reading() -> None:
    from sim.emulate.ft300_stream import TwinWrist

    class Twin:
        def sampled_true_load(self) -> np.ndarray:
            return np.array([0.0, 0.0, -12.0, 0.1, 0.0, 0.0])

    wrist = TwinWrist(Twin())
    assert wrist.first_stepped is None and wrist.wrench()[2] == -12.0
    wrist.inject(np.array([0.0, 0.0, 150.0, 0.0, 0.0, 0.0]))
    assert wrist.first_stepped is None  # not read yet: no sample carried it
    assert wrist.wrench()[2] == pytest.approx(138.0)
    first = wrist.first_stepped
    assert first is not None
    wrist.wrench()
    assert wrist.first_stepped == first  # the first reading's time, kept
    wrist.clear()
    assert wrist.wrench()[2] == -12.0
