"""The hardware backend: the real UR5, 2F-85, FT300 and D435 behind the same interfaces as the
twin, and `cell check-hardware`.

Opened only after the configuration validated. Start-up is safe by construction: every device is
connected and checked before the tree may command a motion, and any failed check refuses the run
with the device, its address and the cause. Shut-down stops the arm, leaves the gripper as it is
(a part held is safer held) and closes every link. The drivers' libraries (ur_rtde, pymodbus,
pyserial, pyrealsense2) are imported here, on the hardware path only.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from drivers.clock import WallClock
from drivers.devices import Devices
from drivers.health import CheckResult, DeviceError
from drivers.machine import TimedMachine
from trees.yaml_lines import ConfigError

DEVICES = ("arm", "gripper", "ft", "camera")
SWITCH_INTERVAL_S = 0.0005  #: the interpreter's thread switch interval on hardware (s)
#: m and rad the controller's TCP pose may differ from the UR5 model's at the same joints: the
#: joint moves' goals and every reach check are solved on the model (its TCP `TCP_Z` along the
#: flange's z axis, drivers/tool.py); a controller with another TCP set lands them elsewhere
TCP_MATCH_M = 0.002
TCP_MATCH_RAD = math.radians(1.0)
_ADDRESS = {
    "arm": lambda d: f"{d.arm.host}:30004",
    "gripper": lambda d: (
        f"{d.gripper.port} unit {d.gripper.slave_id}"
        if d.gripper.transport == "modbus"
        else f"{d.arm.host}:{d.gripper.urcap_port}"
    ),
    "ft": lambda d: f"{d.ft.port} unit {d.ft.slave_id}",
    "camera": lambda d: (f"D435 stream {d.camera.stream}" if d.camera.stream
                         else f"D435 {d.camera.serial or '(the only one)'}"),
}
_NAMES = {"arm": "UR5", "gripper": "2F-85", "ft": "FT300", "camera": "D435"}


def _open_arm(cfg: Any, layout: Any, clock: Any) -> Any:
    from drivers.ur5.arm import UR5Arm, UR5Settings

    d = cfg.arm
    return UR5Arm.connect(
        d.host,
        clock=clock,
        settings=UR5Settings(
            frequency=d.rtde_frequency_hz,
            watchdog_hz=d.watchdog_hz,
            servo_lookahead=d.servo_lookahead_s,
            servo_gain=d.servo_gain,
        ),
        dashboard_timeout=d.connect_timeout_s,
    )


def _open_gripper(cfg: Any, layout: Any, clock: Any) -> Any:
    from drivers.robotiq_gripper import make_gripper

    g = cfg.gripper
    gripper = make_gripper(
        "modbus-rtu" if g.transport == "modbus" else "urcap-socket",
        port=g.port,
        unit_id=g.slave_id,
        baudrate=g.baudrate,
        host=cfg.arm.host,
        urcap_port=g.urcap_port,
        timeout=g.timeout_s,
        **({} if g.open_count is None else
           {"open_count": g.open_count, "closed_count": g.closed_count}),
    )
    return gripper.start()


def _open_ft(cfg: Any, layout: Any, clock: Any) -> Any:
    from drivers.ft300 import FT300

    f = cfg.ft
    ft = FT300(f.port, baudrate=f.baudrate, unit_id=f.slave_id, stale_after=f.stale_after_s)
    ft.start()
    return ft


def _open_camera(cfg: Any, layout: Any, clock: Any) -> Any:
    from drivers.realsense import RealSenseD435

    c = cfg.camera
    if c.stream:  # a streamed camera (the emulator's): frames over a socket, same frame path
        host, _, port = c.stream.rpartition(":")
        return RealSenseD435.from_stream(host, int(port), timeout_ms=c.timeout_ms,
                                         tool_T_camera=layout.tool_T_camera(), clock=clock)
    cam = RealSenseD435(
        c.serial,
        width=c.width,
        height=c.height,
        fps=c.fps,
        timeout_ms=c.timeout_ms,
        tool_T_camera=layout.tool_T_camera(),  # the calibrated mount (`cell calibrate`)
        clock=clock,
    )
    cam.start()
    return cam


OPENERS: dict[str, Callable[[Any, Any, Any], Any]] = {
    "arm": _open_arm,
    "gripper": _open_gripper,
    "ft": _open_ft,
    "camera": _open_camera,
}


def _close(name: str, dev: Any) -> None:
    """Close one device the safe way; never raises (shut-down must reach every device)."""
    try:
        if name == "arm":
            dev.stop()
            dev.close()
        elif name == "gripper":
            dev.disconnect()  # the fingers keep their state
        else:
            dev.stop()
    except Exception:  # noqa: BLE001 -- closing the others matters more than this one's error
        pass


def _check(name: str, dev: Any) -> CheckResult:
    if name == "gripper":
        return dev.check(activate=True)
    if name == "camera":
        # Starting, the camera must stream; how much depth it sees depends on where the arm
        # stands (after a stop mid-pivot it looks at the part from 8 cm, all closer than its
        # minimum range). `cell check-hardware` judges the depth, from its check pose.
        return dev.check(min_valid_fraction=0.0)
    return dev.check()


def check_hardware(
    config: Any,
    layout: Any,
    move_test: bool = False,
    openers: dict[str, Callable[[Any, Any, Any], Any]] | None = None,
) -> list[CheckResult]:
    """Connect to each configured device in turn, check it, close it. Never moves the arm
    unless ``move_test``; a device that cannot be reached is a failed row, not an exception."""
    openers = openers or OPENERS
    clock = WallClock()
    rows = []
    for name in DEVICES:
        address = _ADDRESS[name](config.devices)
        try:
            dev = openers[name](config.devices, layout, clock)
        except DeviceError as exc:
            rows.append(CheckResult(_NAMES[name], exc.address, False, error=exc.cause))
            continue
        except (OSError, RuntimeError, TimeoutError) as exc:
            rows.append(CheckResult(_NAMES[name], address, False, error=str(exc)))
            continue
        try:
            row = _check(name, dev)
            if name == "arm" and move_test and row.ok:
                _move_test(dev, row, clock)
            rows.append(row)
        except DeviceError as exc:
            rows.append(CheckResult(_NAMES[name], exc.address, False, error=exc.cause))
        finally:
            _close(name, dev)
    return rows


def _move_test(
    arm: Any, row: CheckResult, clock: Any, degrees: float = 2.0, timeout: float = 10.0
) -> None:
    """Turn the last wrist joint by ``degrees`` and back, slowly (the only motion a check makes).
    Blocking on purpose: this is a start-up check, not a tick."""
    from drivers.arm import MotionState

    q0 = list(arm.joint_positions())
    for target in (q0[:5] + [q0[5] + math.radians(degrees)], q0):
        arm.move_joints(target, 0.2, 0.5)
        t_end = time.monotonic() + timeout
        while True:
            st = arm.status()
            if st.state is MotionState.DONE:
                break
            if st.state in (MotionState.FAULT, MotionState.STOPPED) or time.monotonic() > t_end:
                arm.stop()
                row.ok = False
                row.error = f"move test: {st.message or st.state.value}"
                return
            time.sleep(0.01)
    row.details["move_test"] = f"wrist 3 turned {degrees:g} deg and back"


def format_table(rows: list[CheckResult]) -> str:
    lines = [f"{'device':<7} {'address':<34} {'result':<6} details"]
    for r in rows:
        detail = (
            r.error
            if not r.ok and r.error
            else "; ".join(f"{k}: {v}" for k, v in r.details.items())
        )
        lines.append(f"{r.device:<7} {r.address:<34} {'ok' if r.ok else 'FAIL':<6} {detail}")
    return "\n".join(lines)


@dataclass
class HardwareBackend:
    """The real cell behind the interfaces, for `cell run`."""

    devices: Devices
    machine: Any
    opened: dict[str, Any] = field(default_factory=dict)
    name: str = "hw"
    watchdog_started: bool = False

    @property
    def clock(self) -> Any:
        return self.devices.clock

    def step(self) -> None:
        """Poll the arm once per tick even when no motion runs: it is the heartbeat that lets a
        controller-side watchdog (`devices.arm.watchdog_hz`) stop the arm if this process dies
        or the link drops. The watchdog is armed after the first tick, not at start-up (the
        checks and the gripper's calibration poll the arm less often than it needs). The
        drivers run their own I/O; the tick loop paces wall time."""
        if not self.watchdog_started:
            self.watchdog_started = True
            start = getattr(self.devices.arm, "start_watchdog", None)
            if start is not None:
                try:
                    start()
                except DeviceError as exc:  # the run goes on as without one, and says so
                    print(f"warning: no controller watchdog: {exc}", file=sys.stderr)
        self.devices.arm.status()

    def judge(self, kind: str, data: dict[str, Any]) -> dict[str, Any] | None:
        return None  # no ground truth on a real cell

    def close(self) -> None:
        # The arm first: it is what can hurt; then the rest. The gripper keeps its state.
        for name in DEVICES:
            if name in self.opened:
                _close(name, self.opened[name])


def _refuse(prep: Any, opened: dict[str, Any], why: str) -> ConfigError:
    """Close every device opened so far and say why the start was refused (raise it)."""
    for name, dev in opened.items():
        _close(name, dev)
    return ConfigError(prep.doc.source, prep.doc.line_of(("devices",)), "devices",
                       f"start-up checks failed, nothing moved: {why}")


def _tcp_mismatch(arm: Any) -> str | None:
    """Why the controller's TCP is not the model's (None: it is), read at the joints the arm
    reports: the skills' joint moves and reach checks are solved on the model."""
    from drivers.tool import TCP_Z
    from drivers.ur5.kinematics import forward_kinematics

    try:
        off, turn = forward_kinematics(arm.joint_positions()).distance(arm.tool_pose())
    except (DeviceError, RuntimeError) as exc:
        return f"reading the arm's joints and TCP: {exc}"
    if off <= TCP_MATCH_M and turn <= TCP_MATCH_RAD:
        return None
    return (
        f"the controller's TCP is {1e3 * off:.1f} mm and {math.degrees(turn):.1f} deg from the "
        f"UR5 model's at the same joints (limit {1e3 * TCP_MATCH_M:.0f} mm, "
        f"{math.degrees(TCP_MATCH_RAD):.0f} deg): set the TCP in PolyScope to "
        f"z = {1e3 * TCP_Z:.1f} mm, no offset or rotation otherwise"
    )


def open_hardware(prep: Any) -> HardwareBackend:
    """Connect and check every device before anything moves; refuse with the reasons. (The
    configuration's gripper values were checked against the gripper's description when it was
    loaded.)"""
    config = prep.config
    # The drivers' reader threads (FT300 stream, gripper poll, camera feed) wake on their line
    # and then wait for the interpreter; with the default 5 ms switch interval, beside the tick
    # loop and each other, the FT300's samples reached the guards more than 50 ms apart
    # (`cell run` against `cell emulate`). 0.5 ms bounds that wait; it also bounds how long the
    # FT300's reader waits to stop the arm on a sample over a limit (bench/guard_latency.py).
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    clock = WallClock()
    opened: dict[str, Any] = {}
    problems: list[str] = []
    try:
        for name in DEVICES:
            try:
                opened[name] = OPENERS[name](config.devices, prep.layout, clock)
            except DeviceError as exc:
                problems.append(str(exc))
                continue
            row = _check(name, opened[name])
            if not row.ok:
                problems.append(f"{row.device} at {row.address}: {row.error}")
    except BaseException:
        for name, dev in opened.items():
            _close(name, dev)
        raise
    if problems:
        raise _refuse(prep, opened, "; ".join(problems))
    tcp = _tcp_mismatch(opened["arm"])
    if tcp is not None:
        raise _refuse(prep, opened, tcp)
    # Every width the skills command or read goes through the gripper's calibration: the counts
    # where this unit's fingers stop. Nominal counts (0 and 255) put a 2F-85 that stops at 3 and
    # 228 up to 10 mm off (the emulated cell opened 7 mm where it asked for 13 and struck the
    # rim of the part in the slot). Measured here when the configuration has none; the check
    # just ran the activation, which drops anything held, so the fingers are empty.
    if config.devices.gripper.open_count is None:
        try:
            if opened["gripper"].object_detected():
                raise DeviceError("2F-85", "start-up", "it holds something, and measuring its "
                                  "calibration opens it: empty it, or put open_count and "
                                  "closed_count (printed at an earlier start) under "
                                  "devices.gripper")
            cal = opened["gripper"].calibrate()
            opened["gripper"].open()
        except (DeviceError, RuntimeError) as exc:
            raise _refuse(prep, opened, f"the 2F-85's calibration: {exc}") from None
        print(f"2F-85 calibrated: open_count {cal.open_count}, closed_count {cal.closed_count} "
              "(put them under devices.gripper to skip this)", file=sys.stderr)
    # The wrist sensor reads the tool's weight and the puck's power-up offset until it is zeroed;
    # the twin zeroes its sensor once when it is built, at rest, and the guards' limits and the
    # pivot's compliance thresholds are set on readings zeroed so. Here the arm has not moved
    # since it was found at rest by its check. Without it the emulated cell's Tilt started from
    # an offset of 9-13 N and aborted on its force limit at every try.
    try:
        opened["ft"].bias()
    except (DeviceError, RuntimeError) as exc:
        raise _refuse(prep, opened, f"zeroing the wrist sensor: {exc}") from None
    # The driver works in the configured description's widths and tip travel.
    if hasattr(opened["gripper"], "spec"):
        opened["gripper"].spec = prep.gripper
    # Each motion's force-torque limit is also checked against every FT300 sample on the
    # sensor's reader thread, which stops the arm itself: a long tick cannot delay the stop.
    limits = getattr(opened["ft"], "limits", None)  # the FT300 has one; a test's fake may not
    if limits is not None:
        limits.connect_stop(opened["arm"].stop)
    devices = Devices(opened["arm"], opened["gripper"], opened["ft"], clock, opened["camera"])
    machine = TimedMachine(clock, config.workflow.machining_time_s)
    return HardwareBackend(devices, machine, opened)


__all__ = [
    "HardwareBackend", "check_hardware",
    "format_table", "open_hardware",
]
