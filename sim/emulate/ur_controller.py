"""A UR5 CB3 controller as ``ur_rtde`` (1.6.5) sees it, on loopback sockets, its arm the twin's.

Written from Universal Robots' RTDE guide (message framing, recipes, data packages) and from
ur_rtde's own sources (``RTDEControlInterface``, ``ScriptClient``, ``DashboardClient`` and the
control script ``rtde_control.script`` it uploads), so the real, installed
``rtde_control.RTDEControlInterface`` and ``rtde_receive.RTDEReceiveInterface`` connect to it
unchanged. Three servers on one host (ur_rtde fixes the ports, so tests use a loopback alias of
their own, 127.x.y.z):

* **RTDE, 30004** (:class:`RTDEServer`): ``uint16 size, uint8 type, payload`` frames, big-endian.
  Protocol version 2 only; ``v`` controller version (a CB3, 3.15.7 by default); ``O`` output
  recipes (double frequency + names -> recipe id and types, ``NOT_FOUND`` for unknown names);
  ``I`` input recipes (ids counted per connection from 1, which ur_rtde hard-codes; ``IN_USE``
  when another connection holds a register, as the controller answers); ``S``/``P``; data
  packages out at each output recipe's frequency, packages in written to the input registers.
* **Script, 30003** (:class:`ScriptServer`): the uploaded program is *recognised, not
  interpreted*: only ur_rtde's control script is accepted (its marker line); the register offset
  (``reg_offset_int``) and the move path ur_rtde injects after ``# inject move path`` are read from
  it. Anything else is refused loudly (logged, the running program stopped): there is no URScript
  interpreter here.
* **Dashboard, 29999** (:class:`DashboardServer`): greeting, ``stop``, ``PolyscopeVersion``,
  ``robotmode``, ``safetystatus`` (from software 3.11/5.4) and ``safetymode``, ``unlock
  protective stop`` (refused within ``unlock_delay`` of the stop, as the controller does),
  ``close safety popup``, ``close popup``, ``power on`` (POWER_OFF -> IDLE), ``brake release``
  (IDLE -> RUNNING), ``power off``, ``get serial number``, ``get robot model``,
  ``programState``, ``running``, ``quit``; anything else ``could not understand``. The robot
  mode it changes is the one RTDE publishes, and a program starts only in RUNNING.

:class:`URController` is the control script's behaviour, cycle by cycle (one
``sync()`` per controller cycle): the command word ``input_int_register_0`` with the ready (1) /
done (2) handshake on ``output_int_register_0``; the real-time commands acknowledged by *ready*;
the command ids :data:`COMMANDS` (moveJ 1, moveL 3, forceMode 6, forceModeStop 7,
zeroFtSensor 8, servoStop 16, servoL 24, stopL 33, stopJ 34, setWatchdog 35, movePath 45, stop
script 255); the async progress word on ``output_int_register_2`` with its change count, running
bit and operation id. Any other id *fails loudly*: logged, counted in :attr:`URController.errors`
and the program stopped (the real script would silently acknowledge it).

The script's quirks are modelled on purpose, because the driver must live with them:

* A command that cancels a running async operation writes "finished" and the new operation's
  "started" in the same cycle, so only the start is ever published: no -1 between two moves.
* ``signal_async_progress(0)``, which ur_rtde injects before a path's first waypoint, counts as a
  new operation: a path's operation id is two above the one before it.
* Every *async* stop runs ``stopl`` (``stop_type = 1`` whatever the command), so an async stopJ's
  deceleration is applied in m/s^2; a *sync* stop uses the last ``stop_type`` (``stopj`` until
  the first async stop).
* An async stop's thread writes "finished" when it ends, whatever operation is current by then.
* The watchdog (``setWatchdog``) belongs to one script run: a re-uploaded script has none.
* A program starts ``script_start_delay`` after its upload (the controller compiles it first).

What the twin cannot give: stops halt the twin's arm within one control step (the stop thread
lasts the deceleration time computed from the TCP speed at the stop); force mode only in the base
frame (type 2), which is all this cell's driver sends; no IK failures beyond the twin's reach check.

Backend interface (:class:`ArmBackend`), called from the thread that owns the physics only.
:class:`TwinArmBackend` implements it on the twin's :class:`sim.arm.SimArm`; :class:`StillArm`
without physics (an arm that stays where it is put), for the wires alone: the driver tests' RTDE
receive side and dashboard.
"""

from __future__ import annotations

import logging
import math
import re
import socket
import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

log = logging.getLogger(__name__)

RTDE_PORT = 30004
SCRIPT_PORT = 30003
DASHBOARD_PORT = 29999

# RTDE message types (the guide's "package types").
REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")

#: RTDE type name -> struct format of its value (big-endian).
FORMATS = {
    "DOUBLE": ">d", "VECTOR3D": ">3d", "VECTOR6D": ">6d", "INT32": ">i", "UINT32": ">I",
    "UINT64": ">Q", "VECTOR6INT32": ">6i", "VECTOR6UINT32": ">6I", "BOOL": ">?", "UINT8": ">B",
}

#: Controller outputs (names and types from UR's RTDE guide, CB3 3.15).
OUTPUT_TYPES: dict[str, str] = {
    "timestamp": "DOUBLE", "target_q": "VECTOR6D", "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D", "target_current": "VECTOR6D", "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D", "actual_qd": "VECTOR6D", "actual_current": "VECTOR6D",
    "joint_control_output": "VECTOR6D", "actual_TCP_pose": "VECTOR6D",
    "actual_TCP_speed": "VECTOR6D", "actual_TCP_force": "VECTOR6D", "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D", "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D", "actual_execution_time": "DOUBLE", "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32", "safety_mode": "INT32", "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D", "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE", "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE", "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE", "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64", "runtime_state": "UINT32",
    "robot_status_bits": "UINT32", "safety_status_bits": "UINT32",
    "standard_analog_input0": "DOUBLE", "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE", "standard_analog_output1": "DOUBLE",
    "payload": "DOUBLE", "payload_cog": "VECTOR3D", "ft_raw_wrench": "VECTOR6D",
    "output_bit_registers0_to_31": "UINT32", "output_bit_registers32_to_63": "UINT32",
}
#: Controller inputs a client may set.
INPUT_TYPES: dict[str, str] = {
    "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8", "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8", "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8", "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8", "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE", "standard_analog_output_1": "DOUBLE",
    "external_force_torque": "VECTOR6D",
}
for _i in range(48):
    OUTPUT_TYPES[f"output_int_register_{_i}"] = "INT32"
    OUTPUT_TYPES[f"output_double_register_{_i}"] = "DOUBLE"
    OUTPUT_TYPES[f"output_bit_register_{64 + _i}"] = "BOOL"
    INPUT_TYPES[f"input_int_register_{_i}"] = "INT32"
    INPUT_TYPES[f"input_double_register_{_i}"] = "DOUBLE"
    INPUT_TYPES[f"input_bit_register_{64 + _i}"] = "BOOL"

# Output values the script and controller publish.
READY, DONE = 1, 2  #: output_int_register_0: ready for a command, done with it
RUNTIME_STOPPED, RUNTIME_PLAYING = 1, 2  #: runtime_state
ROBOT_MODE_RUNNING = 7
#: robot_mode: the dashboard's names and the RTDE numbers (UR's RTDE guide)
ROBOT_MODES = {
    "NO_CONTROLLER": -1, "DISCONNECTED": 0, "CONFIRM_SAFETY": 1, "BOOTING": 2, "POWER_OFF": 3,
    "POWER_ON": 4, "IDLE": 5, "BACKDRIVE": 6, "RUNNING": ROBOT_MODE_RUNNING,
}
_POWERED = ("POWER_ON", "IDLE", "BACKDRIVE", "RUNNING")
SAFETY_MODE_NORMAL, SAFETY_MODE_PROTECTIVE = 1, 3
SAFETY_BIT_NORMAL, SAFETY_BIT_PROTECTIVE = 1 << 0, 1 << 2
ROBOT_STATUS_POWER_ON, ROBOT_STATUS_PROGRAM_RUNNING = 1 << 0, 1 << 1

#: The command ids this emulator executes (ur_rtde's ``RobotCommand::Type``), and those the
#: script treats as real-time (processed, then *ready* at once, no *done*).
COMMANDS = {
    1: "moveJ", 3: "moveL", 6: "forceMode", 7: "forceModeStop", 8: "zeroFtSensor",
    16: "servoStop", 24: "servoL", 33: "stopL", 34: "stopJ", 35: "setWatchdog", 45: "movePath",
    255: "stopScript",
}
REALTIME = {24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71}
NO_CMD = 0
STOP_SCRIPT = 255

#: The line every ur_rtde control script prints first: how an upload is recognised.
SCRIPT_MARKER = "RTDE Control Script Loaded"
PATH_INJECTION = "# inject move path\n"


@runtime_checkable
class ArmBackend(Protocol):
    """The arm behind the controller; all calls come from the physics-owning thread.

    Poses are UR vectors ``[x, y, z, rx, ry, rz]`` (m, axis-angle rad) in the base frame."""

    def joint_positions(self) -> list[float]: ...

    def joint_velocities(self) -> list[float]: ...

    def tcp_pose(self) -> list[float]: ...

    def tcp_speed(self) -> list[float]:
        """``[vx, vy, vz, wx, wy, wz]`` (m/s, rad/s)."""
        ...

    def tcp_force(self) -> list[float]:
        """Wrench at the tool from the wrist sensor (N, N*m)."""
        ...

    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None: ...

    def move_linear(self, poses: Sequence[Sequence[float]], speed: float,
                    acceleration: float) -> None:
        """Straight lines through ``poses``, blended at the intermediate ones."""
        ...

    def servo(self, pose: Sequence[float], lookahead: float, gain: float) -> None:
        """servoj on the pose's joints, with the command's lookahead time (s) and gain."""
        ...

    def force_mode(self, selection: Sequence[int], wrench: Sequence[float],
                   limits: Sequence[float]) -> None:
        """Base-frame force mode (UR type 2)."""
        ...

    def stop(self) -> None:
        """Bring the arm to standstill and hold (ends force mode too)."""
        ...

    def motion_state(self) -> str:
        """``"moving"``, ``"done"``, ``"fault"`` or ``"idle"`` for the last command."""
        ...

    def protective_stop(self) -> str | None:
        """Why the arm tripped its force limit just now; None when it did not."""
        ...

    def speed_fraction(self, fraction: float) -> None:
        """The speed slider (0-1): every trajectory's timing runs at this fraction of its
        own, so 0 halts a move where it is and a later 1 resumes it."""
        ...

    def zero_ft(self) -> None: ...


@dataclass
class ControllerSettings:
    """What the emulated controller is; every value from the emulator's configuration."""

    version: tuple[int, int, int, int] = (3, 15, 7, 106331)  #: a CB3 UR5
    frequency: float = 125.0  #: Hz: the controller cycle (CB3)
    script_start_delay: float = 0.15  #: s from an upload to the program running
    unlock_delay: float = 5.0  #: s after a protective stop before the dashboard unlocks it
    serial: str = "2018300001"
    model: str = "UR5"
    #: the robot at start: RUNNING (powered, brakes released, as the emulated cell starts), or
    #: e.g. POWER_OFF (a controller just booted: ``power on``, then ``brake release``)
    robot_mode: str = "RUNNING"

    def __post_init__(self) -> None:
        if self.robot_mode not in ROBOT_MODES:
            raise ValueError(f"robot_mode {self.robot_mode!r}: one of {sorted(ROBOT_MODES)}")

    def has_safetystatus(self) -> bool:
        """Whether the dashboard knows ``safetystatus`` (software 3.11 on a CB3, 5.4 on an
        e-Series; older ones answer only ``safetymode``)."""
        major, minor = self.version[:2]
        return (major, minor) >= ((3, 11) if major < 5 else (5, 4))


@dataclass
class _Op:
    """One async operation of the script (a move or a stop thread)."""

    kind: str  # "move" | "stop"
    end: float = math.inf  # stop threads: controller time at which they finish


@dataclass
class _Program:
    """One run of the control script (what a re-upload starts afresh)."""

    reg_offset: int
    path: list[tuple[str, list[float], float, float, float]]  # (movel|movej, target, a, v, r)
    start_at: float
    running: bool = False
    executing_cmd: bool = False
    wr_count: int = 0
    op_id: int = 0
    move: _Op | None = None
    stopper: _Op | None = None
    mode: str = "idle"  # idle | servo | force
    stop_type: int = 0  # 0 stopj, 1 stopl: the script's global
    watchdog: float | None = None  # Hz
    watchdog_reg: str = "input_int_register_0"


@dataclass
class ControllerLog:
    """What happened, for tests and the report: commands, stops, errors."""

    commands: list[tuple[float, str]] = field(default_factory=list)
    stops: list[tuple[str, float]] = field(default_factory=list)  # (stopl|stopj, deceleration)
    #: time.monotonic() of each stop's arrival in the controller's cycle (for latency benches)
    stop_times: list[float] = field(default_factory=list)
    #: time.monotonic() of each speed slider set to 0 while the arm moved: the arm begins to
    #: stop in that cycle (counted with stop_times, kept apart from the script's stops)
    pauses: list[float] = field(default_factory=list)
    #: time.monotonic() of each stop's arrival at the controller (stop_times' entries, in the
    #: same order): when the RTDE message that carried it was received by the controller's
    #: network stack (the kernel's receive time), before the emulator's cycle took it
    stop_arrivals: list[float] = field(default_factory=list)
    #: arrivals of speed slider 0 while nothing moved: a stop command that found the arm at
    #: rest (its move had ended meanwhile); not a stop, but it did reach the controller
    rest_stop_arrivals: list[float] = field(default_factory=list)
    uploads: int = 0
    watchdog_trips: int = 0
    watchdog_trips_at: list[float] = field(default_factory=list)  #: the controller's time, s
    protective_stops: list[str] = field(default_factory=list)


class URController:
    """The controller and its control script, one :meth:`cycle` per controller period.

    Thread-safe surface (servers' threads): :meth:`write_inputs`, :meth:`outputs`,
    :meth:`upload`, :meth:`dashboard`, :meth:`raise_protective_stop`. :meth:`cycle` runs on the
    thread that owns the backend (the physics)."""

    def __init__(self, backend: ArmBackend, settings: ControllerSettings | None = None) -> None:
        self.backend = backend
        self.settings = settings or ControllerSettings()
        self.dt = 1.0 / self.settings.frequency
        self.t = 0.0  # controller time (s), advanced by cycle()
        self.log = ControllerLog()
        self.errors: list[str] = []
        self._lock = threading.Lock()
        self._inputs: dict[str, Any] = {}
        self._input_stamp: dict[str, float] = {}
        self._input_arrival: dict[str, float] = {}  #: each input's message's arrival
        self._cycle_arrivals: dict[str, float] = {}  #: the cycle's copy of it
        self._outputs: dict[str, Any] = {}
        self._pending_upload: str | None = None
        self._pending_stop = False
        self._pending_protective: str | None = None
        self._program: _Program | None = None
        self._registers: dict[str, Any] = {}  # output registers the script wrote
        self._protective_since: float | None = None
        self._protective_reason = ""
        self._robot_mode = self.settings.robot_mode  #: changed by the dashboard only
        self._slider = 1.0  #: the speed slider (see _speed_slider)
        self._publish()

    def _log_stop(self, stop: tuple[str, float]) -> None:
        now = time.monotonic()
        self.log.stops.append(stop)
        self.log.stop_times.append(now)
        prog = self._program
        name = f"input_int_register_{prog.reg_offset}" if prog is not None else ""
        self.log.stop_arrivals.append(self._cycle_arrivals.get(name, now))

    # --- thread-safe surface --------------------------------------------------------------

    def write_inputs(self, values: dict[str, Any], arrived: float | None = None) -> None:
        """``arrived``: when the message carrying ``values`` reached the controller
        (``time.monotonic()``; now if not given)."""
        arrived = time.monotonic() if arrived is None else arrived
        with self._lock:
            self._inputs.update(values)
            for name in values:
                self._input_stamp[name] = self.t
                self._input_arrival[name] = arrived

    def outputs(self) -> dict[str, Any]:
        with self._lock:
            return self._outputs

    def upload(self, script: str) -> None:
        """A program arrived on the script port (recognised on the next cycle)."""
        with self._lock:
            self._pending_upload = script

    def stop_program(self) -> None:
        with self._lock:
            self._pending_stop = True

    def raise_protective_stop(self, reason: str) -> None:
        """A fault from outside (schedule or signal): as if the safety system tripped."""
        with self._lock:
            self._pending_protective = reason

    def dashboard(self, command: str) -> str:
        """One dashboard command -> its reply line (UR's dashboard server replies).

        What it changes takes effect at once (the RTDE outputs show it from the next cycle):
        ``power on`` (POWER_OFF -> IDLE), ``brake release`` (IDLE -> RUNNING), ``power off``
        (the program, if one runs, ends in the next cycle), ``unlock protective stop`` (refused
        within ``unlock_delay`` of the stop, in the controller's time). ``stop`` ends the
        program in the next cycle."""
        c = command.strip().lower()
        s = self.settings
        with self._lock:
            out = self._outputs
            protective = self._protective_since is not None
            mode = self._robot_mode
            if c == "stop":
                self._pending_stop = True
                return "Stopped"
            if c == "unlock protective stop":
                if not protective:
                    return "Protective stop releasing"
                if self.t - (self._protective_since or 0.0) < s.unlock_delay:
                    return ("Cannot unlock protective stop until 5s after occurrence. Always "
                            "inspect cause of protective stop before unlocking")
                self._protective_since = None
                log.info("UR emulator: protective stop unlocked")
                return "Protective stop releasing"
            if c == "power on":
                if mode in ("POWER_OFF", "NO_CONTROLLER", "DISCONNECTED"):
                    self._robot_mode = "IDLE"
                return "Powering on"
            if c == "power off":
                self._robot_mode = "POWER_OFF"
                self._pending_stop = True
                return "Powering off"
            if c == "brake release":
                if mode in ("IDLE", "POWER_ON"):
                    self._robot_mode = "RUNNING"
                return "Brake releasing"
        if c == "polyscopeversion":
            major, minor, bugfix, build = s.version
            return f"URSoftware {major}.{minor}.{bugfix}.{build} (Jun 08 2021)"
        if c == "robotmode":
            return f"Robotmode: {mode}"
        if c == "safetymode" or (c == "safetystatus" and s.has_safetystatus()):
            label = "Safetystatus" if c == "safetystatus" else "Safetymode"
            return f"{label}: {'PROTECTIVE_STOP' if protective else 'NORMAL'}"
        if c == "close safety popup":
            return "closing safety popup"
        if c == "close popup":
            return "closing popup"
        if c == "get serial number":
            return s.serial
        if c == "get robot model":
            return s.model
        if c == "running":
            return f"Program running: {str(out['runtime_state'] == RUNTIME_PLAYING).lower()}"
        if c == "programstate":
            return "PLAYING rtde_control" if out["runtime_state"] == RUNTIME_PLAYING else (
                "STOPPED <unnamed>")
        if c == "quit":
            return "Disconnected"
        return f"could not understand: '{command.strip()}'"

    # --- the controller cycle ------------------------------------------------------------

    def cycle(self) -> None:
        """One controller period: uploads, safety, the script's main loop once, the async
        threads, then the outputs as one consistent package."""
        with self._lock:
            upload, self._pending_upload = self._pending_upload, None
            stop, self._pending_stop = self._pending_stop, False
            tripped, self._pending_protective = self._pending_protective, None
            inputs = dict(self._inputs)
            stamps = dict(self._input_stamp)
            self._cycle_arrivals = dict(self._input_arrival)
        self.t += self.dt
        self._speed_slider(inputs)
        if tripped is None:
            tripped = self.backend.protective_stop()
        if tripped is not None and self._protective_since is None:
            self._protective(tripped)
        if stop and self._program is not None:
            self._end_program("stopped from the dashboard")
        if upload is not None:
            self._accept(upload)
        prog = self._program
        if prog is not None and not prog.running and self.t >= prog.start_at:
            if self._protective_since is not None:
                self._fail("cannot start the program during a protective stop")
            elif self._robot_mode != "RUNNING":
                self._fail(f"cannot start the program: robot mode {self._robot_mode}")
            else:
                self._start(prog)
        prog = self._program
        if prog is not None and prog.running:
            self._watchdog(prog, stamps)
        prog = self._program
        if prog is not None and prog.running:
            self._main_loop(prog, inputs)
        prog = self._program
        if prog is not None and prog.running:
            self._threads(prog)
        self._publish()

    def _speed_slider(self, inputs: dict[str, Any]) -> None:
        """The speed slider, set by any RTDE client that sends ``speed_slider_fraction`` with
        bit 0 of ``speed_slider_mask``: a controller setting that outlives programs, read in
        the cycle like every input, with no command handshake."""
        if not int(inputs.get("speed_slider_mask", 0)) & 1:
            return
        fraction = min(max(float(inputs.get("speed_slider_fraction", 1.0)), 0.0), 1.0)
        if fraction == self._slider:
            return
        if fraction == 0.0:
            now = time.monotonic()
            arrived = self._cycle_arrivals.get("speed_slider_fraction", now)
            if self.backend.motion_state() == "moving":
                self.log.pauses.append(now)
                self.log.stop_times.append(now)
                self.log.stop_arrivals.append(arrived)
            else:
                self.log.rest_stop_arrivals.append(arrived)
        self._slider = fraction
        self.backend.speed_fraction(fraction)

    def _protective(self, reason: str) -> None:
        self.backend.stop()
        with self._lock:
            self._protective_since = self.t
        self._protective_reason = reason
        self.log.protective_stops.append(reason)
        log.warning("UR emulator: protective stop (%s)", reason)
        if self._program is not None:
            self._end_program(f"protective stop: {reason}")

    def _accept(self, script: str) -> None:
        """Recognise ur_rtde's control script; anything else is refused."""
        if self._program is not None:
            self._end_program("a new program was uploaded")
        if SCRIPT_MARKER not in script:
            self._fail(f"refused an upload that is not ur_rtde's control script "
                       f"({len(script)} bytes, first line {script.splitlines()[:1]!r})")
            return
        # ScriptClient inserts the offset right after each marker line (so it opens the
        # next line: "global reg_offset_int = # int register offset\n0    global ...").
        m_int = re.search(r"global reg_offset_int = # int register offset\n(\d+)", script)
        m_float = re.search(r"global reg_offset_float = # float register offset\n(\d+)", script)
        if m_int is None or m_float is None or m_int.group(1) != m_float.group(1):
            self._fail("the control script's register offsets are missing or differ")
            return
        self.log.uploads += 1
        self._program = _Program(
            reg_offset=int(m_int.group(1)),
            path=parse_injected_path(script),
            start_at=self.t + self.settings.script_start_delay,
        )

    def _start(self, prog: _Program) -> None:
        prog.running = True
        prog.watchdog_reg = f"input_int_register_{prog.reg_offset}"
        self._registers = {}
        self._async(prog, -1)  # reset_async_progress()
        self._reg(prog, 0, READY)  # signal_ready()

    def _end_program(self, why: str) -> None:
        prog = self._program
        self._program = None
        if prog is None:
            return
        if prog.running and (prog.move or prog.stopper or prog.mode != "idle"):
            self.backend.stop()  # a stopped program's motion stops with it
        log.info("UR emulator: program ended (%s)", why)

    def _fail(self, message: str) -> None:
        """What fails loudly: logged, recorded, the program stopped."""
        self.errors.append(message)
        log.error("UR emulator: %s", message)
        self._end_program(message)

    def _watchdog(self, prog: _Program, stamps: dict[str, float]) -> None:
        if prog.watchdog is None:
            return
        last = stamps.get(prog.watchdog_reg, -math.inf)
        if self.t - last > 1.0 / prog.watchdog:
            self.log.watchdog_trips += 1
            self.log.watchdog_trips_at.append(round(self.t, 3))
            self._end_program(f"RTDE watchdog: no input for {1.0 / prog.watchdog:.3f} s")

    # --- the script ----------------------------------------------------------------------

    def _in(self, inputs: dict[str, Any], prog: _Program, kind: str, index: int) -> Any:
        reg = {"integer": "int", "float": "double"}[kind]  # the script's words -> RTDE names
        name = f"input_{reg}_register_{index + prog.reg_offset}"
        return inputs.get(name, 0)

    def _reg(self, prog: _Program, index: int, value: int) -> None:
        self._registers[f"output_int_register_{index + prog.reg_offset}"] = int(value)

    def _async(self, prog: _Program, value: int) -> None:
        """``write_async_progress_register``: change count, operation id (a new one on 0),
        running bit and progress, packed as the script packs them."""
        prog.wr_count = 0 if prog.wr_count + 1 > 127 else prog.wr_count + 1
        if value == 0:
            prog.op_id = 0 if prog.op_id + 1 > 127 else prog.op_id + 1
        word = prog.wr_count * 65536 + prog.op_id * 16777216
        if value >= 0:
            word += min(value, 32767) + 32768
        self._reg(prog, 2, word)

    def _main_loop(self, prog: _Program, inputs: dict[str, Any]) -> None:
        cmd = int(self._in(inputs, prog, "integer", 0))
        if cmd in REALTIME:
            self._process(prog, cmd, inputs)
            if self._program is prog:
                self._reg(prog, 0, READY)
        elif cmd == NO_CMD:
            prog.executing_cmd = False
            self._reg(prog, 0, READY)
        elif not prog.executing_cmd:
            prog.executing_cmd = True
            if self._process(prog, cmd, inputs) and self._program is prog:
                self._reg(prog, 0, DONE)

    def _floats(self, inputs: dict[str, Any], prog: _Program, first: int, n: int) -> list[float]:
        return [float(self._in(inputs, prog, "float", first + i)) for i in range(n)]

    def _process(self, prog: _Program, cmd: int, inputs: dict[str, Any]) -> bool:
        """``process_cmd``: False when the program ended."""
        name = COMMANDS.get(cmd)
        if name is None:
            self._fail(f"unsupported command id {cmd} (the emulator executes "
                       f"{sorted(COMMANDS)})")
            return False
        if cmd not in (24,):  # servoL streams every tick: not worth a log line each
            self.log.commands.append((self.t, name))
        b = self.backend
        if cmd in (1, 3):  # moveJ, moveL
            target = self._floats(inputs, prog, 0, 6)
            speed, acc = self._floats(inputs, prog, 6, 2)
            asynchronous = int(self._in(inputs, prog, "integer", 1)) == 1
            self._stop_async_move(prog)
            self._leave_modes(prog)
            if cmd == 1:
                b.move_joints(target, speed, acc)
            else:
                b.move_linear([target], speed, acc)
            self._begin_move(prog, asynchronous)
        elif cmd == 45:  # movePath: the path injected into this very script
            asynchronous = int(self._in(inputs, prog, "integer", 1)) == 1
            self._stop_async_move(prog)
            self._leave_modes(prog)
            if not prog.path:
                self._fail("movePath: the uploaded script carries no injected path")
                return False
            self._run_path(prog)
            self._begin_move(prog, asynchronous, path=True)
        elif cmd == 6:  # forceMode
            ints = [int(self._in(inputs, prog, "integer", i)) for i in range(1, 8)]
            frame = self._floats(inputs, prog, 0, 6)
            wrench = self._floats(inputs, prog, 6, 6)
            limits = self._floats(inputs, prog, 12, 6)
            if ints[0] != 2 or any(abs(v) > 1e-12 for v in frame):
                self._fail(f"forceMode type {ints[0]} with task frame {frame}: the emulator "
                           "models the base frame, type 2, only")
                return False
            b.force_mode(ints[1:], wrench, limits)
            prog.mode = "force"
        elif cmd == 7:  # forceModeStop: end_force_mode(); stopl(10)
            if prog.mode == "force":
                prog.mode = "idle"
            b.stop()
            self._log_stop(("stopl", 10.0))
        elif cmd == 8:
            b.zero_ft()
        elif cmd == 24:  # servoL: the script runs servoj on get_inverse_kin(pose)
            # registers 6-10: speed, acceleration (unused), time, lookahead_time, gain
            lookahead, gain = self._floats(inputs, prog, 9, 2)
            b.servo(self._floats(inputs, prog, 0, 6), lookahead, gain)
            prog.mode = "servo"
        elif cmd == 16:  # servoStop: kill the servo thread, stopl(a)
            a = float(self._in(inputs, prog, "float", 0))
            prog.mode = "idle"
            b.stop()
            self._log_stop(("stopl", a))
        elif cmd in (33, 34):
            self._stop_cmd(prog, inputs)
        elif cmd == 35:
            prog.watchdog = float(self._in(inputs, prog, "float", 0))
        elif cmd == STOP_SCRIPT:
            self._end_program("stop script command")
            return False
        return True

    def _leave_modes(self, prog: _Program) -> None:
        """A move while servoing or in force mode: the motion takes over (the threads'
        motions would conflict on a real controller; the driver always stops them first)."""
        prog.mode = "idle"

    def _begin_move(self, prog: _Program, asynchronous: bool, path: bool = False) -> None:
        if asynchronous:
            prog.move = _Op("move")
            self._async(prog, 0)  # signal_async_operation_started()
            if path:
                self._async(prog, 0)  # the injected signal_async_progress(0): a new op id
        else:
            # A sync move would block the script (and ur_rtde's call) until it ends; the
            # driver never sends one, and the emulator models the async form only.
            self._fail("synchronous moves are not modelled (the driver sends async ones)")

    def _run_path(self, prog: _Program) -> None:
        kinds = {k for k, *_ in prog.path}
        if kinds != {"movel"}:
            self._fail(f"movePath with {sorted(kinds)}: the emulator models movel paths only")
            return
        _, _, a, v, _ = prog.path[0]
        self.backend.move_linear([t for _, t, *_ in prog.path], v, a)

    def _stop_async_move(self, prog: _Program) -> None:
        if prog.move is not None:
            prog.move = None
            self._async(prog, -1)  # the killer signals "finished" for the killed thread

    def _stop_cmd(self, prog: _Program, inputs: dict[str, Any]) -> None:
        """``exec_stopl_stopj``: the same code for stopL and stopJ."""
        a = float(self._in(inputs, prog, "float", 0))
        asynchronous = int(self._in(inputs, prog, "integer", 1)) == 1
        stop_move = True
        if prog.stopper is not None:
            stop_move = False
            prog.stopper = None
            self._async(prog, -1)
        if stop_move:
            self._stop_async_move(prog)
        prog.mode = "idle"
        if asynchronous:
            prog.stop_type = 1  # the script sets stopl for every async stop
            speed = self._stop_speed(linear=True)
            self.backend.stop()
            self._log_stop(("stopl", a))
            prog.stopper = _Op("stop", end=self.t + max(self.dt, speed / max(a, 1e-9)))
            self._async(prog, 0)
        else:
            kind = "stopl" if prog.stop_type == 1 else "stopj"
            self.backend.stop()
            self._log_stop((kind, a))

    def _stop_speed(self, linear: bool) -> float:
        if linear:
            return float(np.linalg.norm(self.backend.tcp_speed()[:3]))
        return float(np.max(np.abs(self.backend.joint_velocities())))

    def _threads(self, prog: _Program) -> None:
        """The async threads' own ends (their "finished" writes)."""
        if prog.move is not None:
            state = self.backend.motion_state()
            if state in ("done", "fault", "idle"):
                if state == "fault":
                    log.warning("UR emulator: the move ended in a fault")
                prog.move = None
                self._async(prog, -1)
        if prog.stopper is not None and self.t >= prog.stopper.end:
            prog.stopper = None
            self._async(prog, -1)  # whatever operation is current by now

    def _publish(self) -> None:
        b = self.backend
        prog = self._program
        running = prog is not None and prog.running
        protective = self._protective_since is not None
        mode = self._robot_mode
        q = b.joint_positions()
        tcp = b.tcp_pose()
        out: dict[str, Any] = {
            "timestamp": self.t,
            "actual_q": q,
            "target_q": q,
            "actual_qd": b.joint_velocities(),
            "actual_TCP_pose": tcp,
            "target_TCP_pose": tcp,
            "actual_TCP_speed": b.tcp_speed(),
            "actual_TCP_force": b.tcp_force(),
            "robot_mode": ROBOT_MODES[mode],
            "safety_mode": SAFETY_MODE_PROTECTIVE if protective else SAFETY_MODE_NORMAL,
            "safety_status": SAFETY_MODE_PROTECTIVE if protective else SAFETY_MODE_NORMAL,
            "safety_status_bits": SAFETY_BIT_NORMAL | (SAFETY_BIT_PROTECTIVE if protective else 0),
            "robot_status_bits": (ROBOT_STATUS_POWER_ON if mode in _POWERED else 0)
            | (ROBOT_STATUS_PROGRAM_RUNNING if running else 0),
            "runtime_state": RUNTIME_PLAYING if running else RUNTIME_STOPPED,
            "speed_scaling": self._slider,
            "target_speed_fraction": self._slider,
        }
        out.update(self._registers)
        with self._lock:
            self._outputs = out

    # --- for tests and the report --------------------------------------------------------

    def status(self) -> dict[str, Any]:
        prog = self._program
        return {
            "t": self.t,
            "program_running": bool(prog and prog.running),
            "watchdog_hz": prog.watchdog if prog else None,
            "protective_stop": self._protective_since is not None,
            "robot_mode": self._robot_mode,
            "uploads": self.log.uploads,
            "stops": list(self.log.stops),
            "commands": [c for _, c in self.log.commands],
            "errors": list(self.errors),
            "watchdog_trips": self.log.watchdog_trips,
            "watchdog_trips_at": list(self.log.watchdog_trips_at),
            "speed_slider": self._slider,
            "pauses": len(self.log.pauses),
            # every slider-to-0 that arrived, a move running or not: the stopL, on the other
            # socket, may have ended the move first on a loaded machine
            "slider_zeros": len(self.log.pauses) + len(self.log.rest_stop_arrivals),
        }


_PATH_LINE = re.compile(
    r"^\s*(movel|movej)\(p?\[([^\]]*)\],a=([^,]+),v=([^,]+),r=([^)]+)\)\s*$"
)


def parse_injected_path(script: str) -> list[tuple[str, list[float], float, float, float]]:
    """The moves ur_rtde injected after ``# inject move path`` (``Path::toScriptCode``:
    ``signal_async_progress(i)`` then ``movel(p[...],a=..,v=..,r=..)`` per waypoint)."""
    at = script.find(PATH_INJECTION)
    if at < 0:
        return []
    moves = []
    for line in script[at + len(PATH_INJECTION):].splitlines():
        stripped = line.strip()
        if stripped.startswith("signal_async_progress("):
            continue
        m = _PATH_LINE.match(line)
        if m is None:
            break  # the function's `end`: the injection is over
        kind, values, a, v, r = m.groups()
        moves.append((kind, [float(x) for x in values.split(",")], float(a), float(v),
                      float(r)))
    return moves


# --- the wire ------------------------------------------------------------------------------


def _read_exact(conn: socket.socket, n: int) -> bytes | None:
    data = b""
    while len(data) < n:
        try:
            chunk = conn.recv(n - len(data))
        except OSError:
            return None
        if not chunk:
            return None
        data += chunk
    return data


#: Linux's SO_TIMESTAMPNS (socket(7); Python names it only on some builds): each read carries
#: the kernel's receive time of its data
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_STAMP_SPACE = socket.CMSG_SPACE(16)


def _read_stamped(conn: socket.socket, n: int) -> tuple[bytes, float] | None:
    """``n`` bytes and when the first of them reached this host's network stack, as
    ``time.monotonic()``: the kernel's receive time (SO_TIMESTAMPNS, on the realtime clock,
    carried over to the monotonic one), so a server thread that was scheduled late still
    knows when a message arrived; its own clock where the kernel gives no stamp."""
    try:
        first, ancillary, _, _ = conn.recvmsg(n, _STAMP_SPACE)
    except OSError:
        return None
    if not first:
        return None
    arrived = time.monotonic()
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= 16:
            sec, nsec = struct.unpack("qq", data[:16])
            offset = time.time_ns() - time.monotonic_ns()
            arrived = min(arrived, (sec * 1_000_000_000 + nsec - offset) / 1e9)
    rest = _read_exact(conn, n - len(first)) if len(first) < n else b""
    return None if rest is None else (first + rest, arrived)


def _pack(kind: str, value: Any) -> bytes:
    fmt = FORMATS[kind]
    if isinstance(value, list | tuple | np.ndarray):
        return struct.pack(fmt, *value)
    return struct.pack(fmt, value)


def _zero(kind: str) -> Any:
    fmt = FORMATS[kind]
    n = int(fmt[1]) if fmt[1].isdigit() else 1
    z: Any = False if kind == "BOOL" else 0.0 if "d" in fmt else 0
    return [z] * n if n > 1 else z


class _Listener:
    """A TCP listener that can be closed and reopened (a pulled and replugged cable)."""

    def __init__(self, host: str, port: int, serve: Callable[[socket.socket], None],
                 name: str) -> None:
        self.host, self.port, self.name = host, port, name
        self._serve = serve
        self._server: socket.socket | None = None
        self._clients: list[socket.socket] = []
        self._lock = threading.Lock()
        self._stopped = threading.Event()
        self.connections = 0

    def open(self) -> None:
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        server.bind((self.host, self.port))
        self.port = server.getsockname()[1]  # port 0 picked a free one: kept for a replug
        server.listen(8)
        server.settimeout(0.05)
        self._server = server
        threading.Thread(target=self._accept, args=(server,), daemon=True,
                         name=f"ur-emu-{self.name}").start()

    def _accept(self, server: socket.socket) -> None:
        while not self._stopped.is_set() and self._server is server:
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.settimeout(None)
            with self._lock:
                if self._server is not server:
                    # The cable was pulled while this connection was being accepted: it must
                    # not outlive the pull (close() dropped only the ones listed then).
                    conn.close()
                    return
                self._clients.append(conn)
                self.connections += 1
            threading.Thread(target=self._run, args=(conn,), daemon=True).start()

    def _run(self, conn: socket.socket) -> None:
        try:
            self._serve(conn)
        finally:
            with self._lock:
                if conn in self._clients:
                    self._clients.remove(conn)
            try:
                conn.close()
            except OSError:
                pass

    def drop_clients(self) -> None:
        with self._lock:
            clients, self._clients = self._clients, []
        for c in clients:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()

    def close(self) -> None:
        """Stop listening (new connections are refused) and drop the live ones."""
        with self._lock:  # no accept in flight may list a connection after this
            server, self._server = self._server, None
        if server is not None:
            try:  # stops listening at once (close alone waits for a blocked accept to return)
                server.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            server.close()
        self.drop_clients()

    def shutdown(self) -> None:
        self._stopped.set()
        self.close()


class RTDEServer:
    """The controller's RTDE interface (port 30004) over a :class:`URController`."""

    def __init__(self, controller: URController, host: str, port: int = RTDE_PORT) -> None:
        self.controller = controller
        self.listener = _Listener(host, port, self._serve, "rtde")
        self.requested: list[tuple[float, list[str]]] = []  #: (frequency, names) per recipe
        self.protocol_versions: list[int] = []  #: every protocol version a client asked for
        self._owners: dict[str, int] = {}  # input name -> connection id
        self._lock = threading.Lock()
        self._next_conn = 0

    @staticmethod
    def _send(conn: socket.socket, kind: int, payload: bytes, lock: threading.Lock) -> None:
        with lock:
            conn.sendall(struct.pack(">HB", 3 + len(payload), kind) + payload)

    def _serve(self, conn: socket.socket) -> None:
        with self._lock:
            self._next_conn += 1
            cid = self._next_conn
        wlock = threading.Lock()
        try:  # the inputs' arrival times (see _read_stamped)
            conn.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        except OSError:
            pass
        outputs: list[tuple[list[tuple[str, str]], float]] = []
        inputs: list[list[tuple[str, str]]] = []
        streaming = threading.Event()
        streamer: threading.Thread | None = None
        try:
            while True:
                stamped = _read_stamped(conn, 3)
                if stamped is None:
                    return
                header, arrived = stamped
                size, kind = struct.unpack(">HB", header)
                payload = _read_exact(conn, size - 3) if size > 3 else b""
                if payload is None:
                    return
                if kind == REQUEST_PROTOCOL_VERSION:
                    (v,) = struct.unpack(">H", payload[:2])
                    with self._lock:
                        self.protocol_versions.append(v)
                    self._send(conn, kind, struct.pack(">B", int(v == 2)), wlock)
                elif kind == GET_URCONTROL_VERSION:
                    self._send(conn, kind, struct.pack(">4I", *self.controller.settings.version),
                               wlock)
                elif kind == SETUP_OUTPUTS:
                    (frequency,) = struct.unpack(">d", payload[:8])
                    names = [n for n in payload[8:].decode().split(",") if n]
                    types = [OUTPUT_TYPES.get(n, "NOT_FOUND") for n in names]
                    with self._lock:
                        self.requested.append((frequency, names))
                    ok = "NOT_FOUND" not in types
                    if ok:
                        outputs.append((list(zip(names, types, strict=True)), frequency))
                    rid = len(outputs) if ok else 0
                    self._send(conn, kind, struct.pack(">B", rid) + ",".join(types).encode(),
                               wlock)
                elif kind == SETUP_INPUTS:
                    names = [n for n in payload.decode().split(",") if n]
                    types = []
                    with self._lock:
                        for n in names:
                            owner = self._owners.get(n)
                            if n not in INPUT_TYPES:
                                types.append("NOT_FOUND")
                            elif owner is not None and owner != cid:
                                types.append("IN_USE")
                            else:
                                types.append(INPUT_TYPES[n])
                        ok = all(t in FORMATS for t in types)
                        if ok:
                            for n in names:
                                self._owners[n] = cid
                    if ok:
                        inputs.append(list(zip(names, types, strict=True)))
                    rid = len(inputs) if ok else 0
                    self._send(conn, kind, struct.pack(">B", rid) + ",".join(types).encode(),
                               wlock)
                elif kind == START:
                    ok = bool(outputs)
                    self._send(conn, kind, struct.pack(">B", int(ok)), wlock)
                    if ok and streamer is None:
                        streaming.set()
                        streamer = threading.Thread(
                            target=self._stream, args=(conn, outputs, streaming, wlock),
                            daemon=True, name="ur-emu-rtde-out")
                        streamer.start()
                    elif ok:
                        streaming.set()
                elif kind == PAUSE:
                    streaming.clear()
                    self._send(conn, kind, struct.pack(">B", 1), wlock)
                elif kind == DATA_PACKAGE:
                    rid = payload[0]
                    if not 1 <= rid <= len(inputs):
                        log.error("UR emulator: data package for unknown input recipe %d", rid)
                        continue
                    values: dict[str, Any] = {}
                    offset = 1
                    for name, t in inputs[rid - 1]:
                        fmt = FORMATS[t]
                        n = struct.calcsize(fmt)
                        v = struct.unpack(fmt, payload[offset:offset + n])
                        values[name] = v[0] if len(v) == 1 else list(v)
                        offset += n
                    self.controller.write_inputs(values, arrived)
                else:
                    log.error("UR emulator: RTDE message type %r not handled", chr(kind))
        finally:
            streaming.clear()
            with self._lock:
                for n in [n for n, o in self._owners.items() if o == cid]:
                    del self._owners[n]

    def _stream(self, conn: socket.socket, outputs: list[tuple[list[tuple[str, str]], float]],
                streaming: threading.Event, wlock: threading.Lock) -> None:
        """Data packages at each recipe's frequency (the controller's rate at most)."""
        top = self.controller.settings.frequency
        period = 1.0 / min(max(f for _, f in outputs), top)
        t_next = time.monotonic()
        while streaming.is_set():
            state = self.controller.outputs()
            try:
                for rid, (recipe, _) in enumerate(outputs, start=1):
                    body = [struct.pack(">B", rid)]
                    for name, t in recipe:
                        body.append(_pack(t, state.get(name, _zero(t))))
                    self._send(conn, DATA_PACKAGE, b"".join(body), wlock)
            except OSError:
                return
            t_next += period
            delay = t_next - time.monotonic()
            if delay < -period:  # fell behind (a stall): resynchronise, no burst
                t_next = time.monotonic()
            else:
                time.sleep(max(0.0, delay))


class ScriptServer:
    """The secondary/real-time script port (30003): programs in, nothing back."""

    IDLE = 0.05  #: s of silence after which a buffered text counts as one upload

    def __init__(self, controller: URController, host: str, port: int = SCRIPT_PORT) -> None:
        self.controller = controller
        self.listener = _Listener(host, port, self._serve, "script")

    def _serve(self, conn: socket.socket) -> None:
        buffer = ""
        conn.settimeout(self.IDLE)
        while True:
            try:
                chunk = conn.recv(65536)
            except TimeoutError:
                if buffer:
                    self.controller.upload(buffer)
                    buffer = ""
                continue
            except OSError:
                return
            if not chunk:
                if buffer:
                    self.controller.upload(buffer)
                return
            buffer += chunk.decode("utf-8", "replace")
            # ur_rtde's script ends with the control loop's marker and the closing `end`.
            tail = buffer.rstrip()
            if "# NODE_CONTROL_LOOP_ENDS" in buffer and tail.endswith("end"):
                self.controller.upload(buffer)
                buffer = ""


class DashboardServer:
    """The dashboard server (29999): one reply line per command line.

    Faults and scripted replies, for tests: :attr:`replies` (a command, lower case, -> the reply
    line sent instead of the controller's, e.g. ``Not in remote control``), :attr:`silent`
    (greets, then reads every command and answers none), :attr:`no_greeting` (accepts and says
    nothing). :attr:`received` records every command line. Alone (port 0 picks a free one):
    :meth:`start` / :meth:`stop`."""

    GREETING = "Connected: Universal Robots Dashboard Server"

    def __init__(self, controller: URController, host: str, port: int = DASHBOARD_PORT) -> None:
        self.controller = controller
        self.listener = _Listener(host, port, self._serve, "dashboard")
        self.received: list[str] = []
        self.replies: dict[str, str] = {}
        self.silent = False
        self.no_greeting = False

    @property
    def host(self) -> str:
        return self.listener.host

    @property
    def port(self) -> int:
        return self.listener.port

    def start(self) -> DashboardServer:
        self.listener.open()
        return self

    def stop(self) -> None:
        self.listener.shutdown()

    def __enter__(self) -> DashboardServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _serve(self, conn: socket.socket) -> None:
        if self.no_greeting:
            _drain(conn)
            return
        try:
            conn.sendall((self.GREETING + "\n").encode())
            for raw in conn.makefile("rb"):
                command = raw.decode("utf-8", "replace").strip()
                self.received.append(command)
                if self.silent:
                    continue
                reply = self.replies.get(command.lower())
                if reply is None:
                    reply = self.controller.dashboard(command)
                conn.sendall((reply + "\n").encode())
                if command.lower() == "quit":
                    # Closed as a controller closes it: our side first, then what the client
                    # still sends is read, so it meets the end of the stream and not a reset
                    # (a socket closed with unread bytes answers with RST).
                    conn.shutdown(socket.SHUT_WR)
                    conn.settimeout(QUIT_LINGER_S)
                    _drain(conn)
                    return
        except OSError:  # the client or the cable went away
            return


#: s a dashboard connection that was told ``quit`` waits for its client to close
QUIT_LINGER_S = 2.0


def _drain(conn: socket.socket) -> None:
    """Read and drop until the peer or the server closes the connection."""
    while True:
        try:
            if not conn.recv(4096):
                return
        except OSError:
            return


@dataclass
class URPorts:
    rtde: int = RTDE_PORT
    script: int = SCRIPT_PORT
    dashboard: int = DASHBOARD_PORT


class URServers:
    """The three servers of one emulated controller; :meth:`pull_cable` / :meth:`plug_cable`
    cut and restore the Ethernet link (every socket dropped, new connections refused)."""

    def __init__(self, controller: URController, host: str, ports: URPorts | None = None) -> None:
        ports = ports or URPorts()
        self.host = host
        self.rtde = RTDEServer(controller, host, ports.rtde)
        self.script = ScriptServer(controller, host, ports.script)
        self.dashboard = DashboardServer(controller, host, ports.dashboard)
        self._listeners = [self.rtde.listener, self.script.listener, self.dashboard.listener]
        self.cable = True

    def start(self) -> URServers:
        for listener in self._listeners:
            listener.open()
        return self

    def pull_cable(self) -> None:
        self.cable = False
        for listener in self._listeners:
            listener.close()
        log.warning("UR emulator: cable pulled at %s", self.host)

    def plug_cable(self) -> None:
        if not self.cable:
            for listener in self._listeners:
                listener.open()
            self.cable = True
            log.warning("UR emulator: cable plugged back at %s", self.host)

    def stop(self) -> None:
        for listener in self._listeners:
            listener.shutdown()


# --- backends -------------------------------------------------------------------------------


class StillArm:
    """:class:`ArmBackend` without physics: an arm that stays where it is put (:meth:`place`),
    for the controller's wires alone (the RTDE outputs, the dashboard). A motion command is
    recorded in :attr:`commands` and ends at once, the arm unmoved; it never trips."""

    def __init__(self, q: Sequence[float] = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0),
                 tcp: Sequence[float] = (0.4, 0.1, 0.3, 0.0, 3.14159, 0.0)) -> None:
        self._lock = threading.Lock()
        self._q, self._tcp = [float(v) for v in q], [float(v) for v in tcp]
        self.commands: list[str] = []

    def place(self, q: Sequence[float] | None = None, tcp: Sequence[float] | None = None
              ) -> None:
        """Put the arm at joints ``q`` and/or TCP pose ``tcp`` (any thread)."""
        with self._lock:
            if q is not None:
                self._q = [float(v) for v in q]
            if tcp is not None:
                self._tcp = [float(v) for v in tcp]

    def joint_positions(self) -> list[float]:
        with self._lock:
            return list(self._q)

    def joint_velocities(self) -> list[float]:
        return [0.0] * 6

    def tcp_pose(self) -> list[float]:
        with self._lock:
            return list(self._tcp)

    def tcp_speed(self) -> list[float]:
        return [0.0] * 6

    def tcp_force(self) -> list[float]:
        return [0.0] * 6

    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None:
        self.commands.append("move_joints")

    def move_linear(self, poses: Sequence[Sequence[float]], speed: float,
                    acceleration: float) -> None:
        self.commands.append("move_linear")

    def servo(self, pose: Sequence[float], lookahead: float, gain: float) -> None:
        self.commands.append("servo")

    def force_mode(self, selection: Sequence[int], wrench: Sequence[float],
                   limits: Sequence[float]) -> None:
        self.commands.append("force_mode")

    def stop(self) -> None:
        self.commands.append("stop")

    def speed_fraction(self, fraction: float) -> None:
        self.commands.append("speed_fraction")

    def motion_state(self) -> str:
        return "idle"

    def protective_stop(self) -> str | None:
        return None

    def zero_ft(self) -> None:
        self.commands.append("zero_ft")




class TwinArmBackend:
    """:class:`ArmBackend` over the twin's :class:`sim.arm.SimArm` and its wrist sensor."""

    def __init__(self, arm: Any, ft: Any = None) -> None:
        self.arm = arm
        self.ft = ft
        self._tripped_seen = False

    def joint_positions(self) -> list[float]:
        return [float(v) for v in self.arm.joint_positions()]

    def joint_velocities(self) -> list[float]:
        return [float(v) for v in self.arm.joint_velocities()]

    def tcp_pose(self) -> list[float]:
        pose = self.arm.tool_pose()
        return [float(v) for v in (*pose.position, *pose.rotvec)]

    def tcp_speed(self) -> list[float]:
        from drivers.ur5.kinematics import jacobian

        jac, _ = jacobian(self.arm.joint_positions())
        return [float(v) for v in jac @ np.asarray(self.joint_velocities())]

    def tcp_force(self) -> list[float]:
        if self.ft is None:
            return [0.0] * 6
        return [float(v) for v in self.ft.wrench()]

    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None:
        self.arm.move_joints(list(q), speed, acceleration)

    def move_linear(self, poses: Sequence[Sequence[float]], speed: float,
                    acceleration: float) -> None:
        from drivers.pose import Pose

        self.arm.move_path([Pose.from_rotvec(p[:3], p[3:]) for p in poses], speed, acceleration)

    def servo(self, pose: Sequence[float], lookahead: float, gain: float) -> None:
        from drivers.pose import Pose

        self.arm.set_servo_tracking(lookahead, gain)
        self.arm.servo(Pose.from_rotvec(pose[:3], pose[3:]))

    def force_mode(self, selection: Sequence[int], wrench: Sequence[float],
                   limits: Sequence[float]) -> None:
        sel = [bool(v) for v in selection]
        # UR limits: speed on compliant axes, allowed deviation on the others (the twin holds
        # the others, so only the speeds matter).
        self.arm.force_mode(sel, list(wrench), [limits[i] if sel[i] else 0.0 for i in range(6)])

    def stop(self) -> None:
        self.arm.stop()

    def speed_fraction(self, fraction: float) -> None:
        self.arm.set_speed_fraction(fraction)

    def motion_state(self) -> str:
        from drivers.arm import MotionState

        state = self.arm.status().state
        return {MotionState.MOVING: "moving", MotionState.DONE: "done",
                MotionState.FAULT: "fault"}.get(state, "idle")

    def protective_stop(self) -> str | None:
        st = self.arm.status()
        tripped = bool(st.protective_stop)
        new = tripped and not self._tripped_seen
        self._tripped_seen = tripped
        return st.message if new else None

    def zero_ft(self) -> None:
        if self.ft is not None:
            self.ft.bias()
