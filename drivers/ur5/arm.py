"""The :class:`drivers.arm.Arm` interface on a real UR5 over ``ur_rtde``.

Same semantics as the twin's :class:`sim.arm.SimArm`: every command starts a motion and returns;
the control loop polls :meth:`UR5Arm.status` once per tick. Nothing called per tick sleeps or
waits on the network beyond one ``ur_rtde`` call (asynchronous moves and stops, ``servoL``, and
reads of the state ur_rtde's receive threads already hold).

How each command maps onto the controller, and why:

* :meth:`move_to` / :meth:`move_path`: ``moveL`` with ``asynchronous=True``; a path is one
  ``moveL`` over a list of poses with blend radii, so the TCP does not stop at intermediate
  waypoints (as in the twin). UR rejects overlapping blends, so each radius is at most
  :data:`BLEND_FRACTION` of its shorter neighbouring segment.
* :meth:`move_joints`: ``moveJ`` asynchronous.
* Completion comes from ``getAsyncOperationProgress``: >= 0 while the move runs, negative when
  none does, toggling between -1 and -2 so a move too short to be seen running still shows as a
  new negative value. A finished move is DONE only if the arm is within the goal tolerance.
* :meth:`servo`: one ``servoL`` per call (the caller calls it once per tick), ``time`` = one
  control period, with ``lookahead``/``gain`` from :class:`UR5Settings`.
* :meth:`force_mode`: ``forceMode`` with the base frame as task frame (type 2: not transformed);
  selected axes get the caller's speed limits, the others the allowed deviation from
  :class:`UR5Settings` (what UR's ``limits`` mean for non-compliant axes).
* :meth:`stop`: ``stopL``/``stopJ`` (asynchronous), ``servoStop`` or ``forceModeStop``, whichever
  matches the running mode; a second call sends nothing.
* :meth:`status`: the live safety status bits and robot mode come first (protective stop ->
  FAULT with ``protective_stop=True``; emergency or safeguard stop, violation, fault, robot not
  RUNNING, control script not running, lost link -> FAULT with the reason), then the motion.
  A fault is latched until the next command, as in the twin.
* Lost link: bounded reconnect attempts with :func:`drivers.health.backoff_delays` between them,
  scheduled on the clock and run off the tick (``ur_rtde``'s reconnect blocks on TCP connects),
  so a dead controller costs a handful of attempts, never a storm.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from drivers.arm import ArmStatus, MotionState
from drivers.clock import Clock, WallClock
from drivers.health import CheckResult, DeviceError, backoff_delays
from drivers.pose import Pose
from drivers.ur5.dashboard import DashboardClient
from drivers.ur5.rtde_adapter import RTDE_PORT, RTDEAdapter, URRTDEAdapter

log = logging.getLogger(__name__)

DEVICE = "UR5"

#: ``getSafetyStatusBits`` bit -> meaning (UR RTDE guide, ``safety_status_bits``).
SAFETY_BITS = {
    0: "normal mode",
    1: "reduced mode",
    2: "protective stop",
    3: "recovery mode",
    4: "safeguard stop",
    5: "system emergency stop",
    6: "robot emergency stop",
    7: "emergency stop",
    8: "safety violation",
    9: "safety fault",
    10: "stopped due to safety",
}
PROTECTIVE_STOP_BIT = 2
#: Bits that stop the arm, in the order a message names them (the most specific first).
STOP_BITS = (5, 6, 7, 4, 8, 9, 3, 10)

#: ``getRobotMode`` value -> name.
ROBOT_MODES = {
    -1: "NO_CONTROLLER",
    0: "DISCONNECTED",
    1: "CONFIRM_SAFETY",
    2: "BOOTING",
    3: "POWER_OFF",
    4: "POWER_ON",
    5: "IDLE",
    6: "BACKDRIVE",
    7: "RUNNING",
    8: "UPDATING_FIRMWARE",
}
ROBOT_MODE_RUNNING = 7

BLEND_FRACTION = 0.45  #: blend radius at most this fraction of the shorter neighbouring segment
DONE_POSITION = 0.002  #: m: a finished Cartesian move must end this close to its goal ...
DONE_ANGLE = np.radians(1.0)  #: rad: ... and this close in rotation
DONE_JOINT = 0.005  #: rad: a finished joint move, per joint


@dataclass(frozen=True)
class UR5Settings:
    """Tuning of the UR5 driver; the defaults suit a CB3 UR5 at 125 Hz."""

    frequency: float = 125.0  #: Hz: RTDE and control rate (500 on an e-Series)
    servo_lookahead: float = 0.1  #: s, UR range [0.03, 0.2]: smooths the servoL targets
    servo_gain: float = 300.0  #: UR range [100, 2000]: servoL position gain
    path_blend: float = 0.01  #: m: blend radius at intermediate path waypoints (upper bound)
    stop_deceleration: float = 10.0  #: m/s^2: stopL, servoStop
    stop_joint_deceleration: float = 4.0  #: rad/s^2: stopJ
    #: Force mode, non-compliant axes: allowed deviation from the programmed pose (m, m, m,
    #: rad, rad, rad).
    force_deviation: tuple[float, ...] = (0.01, 0.01, 0.01, 0.05, 0.05, 0.05)
    reconnect_attempts: int = 5  #: attempts after a lost link before giving up
    reconnect_first_delay: float = 0.5  #: s before the second attempt (then doubling, <= cap)
    reconnect_max_delay: float = 4.0  #: s
    #: Hz: arm ur_rtde's watchdog (the controller stops the script if status() is not polled
    #: this often); None: off. Only enable it when the control loop polls status() every tick
    #: even while the arm is idle.
    watchdog_hz: float | None = None

    def __post_init__(self) -> None:
        if self.frequency <= 0:
            raise ValueError(f"frequency must be > 0 Hz, got {self.frequency}")
        if not 0.03 <= self.servo_lookahead <= 0.2:
            raise ValueError(
                f"servo_lookahead must be in [0.03, 0.2] s, got {self.servo_lookahead}"
            )
        if not 100.0 <= self.servo_gain <= 2000.0:
            raise ValueError(f"servo_gain must be in [100, 2000], got {self.servo_gain}")
        if len(self.force_deviation) != 6:
            raise ValueError("force_deviation needs 6 values")
        if self.reconnect_attempts < 1:
            raise ValueError("reconnect_attempts must be >= 1")


def pose_to_vector(pose: Pose) -> list[float]:
    """``Pose`` -> the controller's ``[x, y, z, rx, ry, rz]`` (m, axis-angle rad)."""
    return [float(v) for v in np.concatenate([pose.position, pose.rotvec])]


def vector_to_pose(v: Sequence[float]) -> Pose:
    """The controller's ``[x, y, z, rx, ry, rz]`` -> ``Pose``."""
    if len(v) != 6:
        raise ValueError(f"a UR pose has 6 values, got {len(v)}")
    return Pose.from_rotvec(v[:3], v[3:])


def describe_safety_bits(bits: int) -> str:
    """Names of the set bits, for check() and messages."""
    names = [name for bit, name in SAFETY_BITS.items() if bits & (1 << bit)]
    return ", ".join(names) if names else "none"


def _spawn_thread(fn: Callable[[], None]) -> None:
    threading.Thread(target=fn, name="ur5-reconnect", daemon=True).start()


class UR5Arm:
    """Implements :class:`drivers.arm.Arm` over an :class:`RTDEAdapter`.

    ``adapter`` must be connected (see :meth:`connect` for the usual construction). ``clock``
    schedules reconnect attempts. ``dashboard`` (optional) supplies version and serial to
    :meth:`check` and is used by :meth:`recover`. ``spawn`` runs a blocking reconnect attempt
    off the tick (a daemon thread by default; tests run it inline).
    """

    def __init__(
        self,
        adapter: RTDEAdapter,
        clock: Clock | None = None,
        settings: UR5Settings | None = None,
        dashboard: DashboardClient | None = None,
        spawn: Callable[[Callable[[], None]], None] = _spawn_thread,
    ) -> None:
        self._rtde = adapter
        self._clock = clock or WallClock()
        self.settings = settings or UR5Settings()
        self.dashboard = dashboard
        self._spawn = spawn
        self._mode = "hold"  # hold | path | joints | servo | force
        self._state = MotionState.IDLE
        self._message = ""
        self._protective = False
        # Async move completion (see _poll_progress).
        self._await_previous = False
        self._neg_before = 0
        self._seen_running = False
        self._goal: Pose | None = None
        self._goal_q: NDArray[np.float64] | None = None
        self.last_servo_target: Pose | None = None
        # Link and reconnect.
        self._lock = threading.Lock()
        self._link_lost = False
        self._link_cause = ""
        self._last_attempt = ""
        self._attempts = 0
        self._next_attempt = 0.0
        self._in_flight = False
        self._delays = backoff_delays(
            self.settings.reconnect_attempts,
            self.settings.reconnect_first_delay,
            2.0,
            self.settings.reconnect_max_delay,
        )
        if self.settings.watchdog_hz:
            self._rtde.set_watchdog(self.settings.watchdog_hz)

    @classmethod
    def connect(
        cls,
        host: str,
        clock: Clock | None = None,
        settings: UR5Settings | None = None,
        dashboard_timeout: float | None = 2.0,
        connect_attempts: int = 3,
    ) -> UR5Arm:
        """Connect to the controller at ``host`` (RTDE 30004; dashboard 29999 unless
        ``dashboard_timeout`` is None). Blocking, with bounded retries: start-up only."""
        settings = settings or UR5Settings()
        adapter = URRTDEAdapter(host, settings.frequency)
        delays = backoff_delays(connect_attempts, 0.5, 2.0, 4.0)
        for attempt in range(connect_attempts):
            try:
                adapter.connect()
                break
            except Exception as e:  # ur_rtde raises RuntimeError; anything else is as fatal
                if attempt == connect_attempts - 1:
                    raise DeviceError(
                        DEVICE, f"{host}:{RTDE_PORT}",
                        f"cannot connect after {connect_attempts} attempt(s): {e}",
                    ) from e
                time.sleep(delays[attempt])
        dashboard = None
        if dashboard_timeout is not None:
            dashboard = DashboardClient(host, timeout=dashboard_timeout)
        return cls(adapter, clock, settings, dashboard)

    @property
    def address(self) -> str:
        return f"{self._rtde.host}:{RTDE_PORT}"

    # --- state ---------------------------------------------------------------------------

    def _latch(self, state: MotionState, message: str = "", protective: bool = False) -> None:
        self._state, self._message, self._protective = state, message, protective

    def _fault(self, message: str, protective: bool = False) -> None:
        if self._state is not MotionState.FAULT or self._message != message:
            log.error("%s at %s: %s", DEVICE, self.address, message)
        self._mode = "hold"
        self._latch(MotionState.FAULT, message, protective)

    def _lose_link(self, cause: str) -> None:
        with self._lock:
            if self._link_lost:
                return
            self._link_lost = True
            self._link_cause = cause
            self._last_attempt = ""
            self._attempts = 0
            self._next_attempt = self._clock.now()

    def _link_message(self) -> str:
        n = self.settings.reconnect_attempts
        base = f"lost connection to the controller at {self.address}: {self._link_cause}"
        if self._last_attempt:
            base += f" (last attempt: {self._last_attempt})"
        if self._in_flight:
            return f"{base}; reconnect attempt {self._attempts + 1}/{n} under way"
        if self._attempts >= n:
            return f"{base}; gave up after {n} reconnect attempts"
        return f"{base}; reconnect attempt {self._attempts + 1}/{n} at t={self._next_attempt:.1f} s"

    def _maybe_reconnect(self) -> None:
        """Start the next bounded attempt when its back-off has passed (never two at once)."""
        with self._lock:
            if (
                not self._link_lost
                or self._in_flight
                or self._attempts >= self.settings.reconnect_attempts
                or self._clock.now() < self._next_attempt
            ):
                return
            self._in_flight = True
        self._spawn(self._attempt_reconnect)

    def _attempt_reconnect(self) -> None:
        try:
            ok, cause = bool(self._rtde.reconnect()), "reconnect refused"
        except Exception as e:  # whatever ur_rtde raises, the attempt failed
            ok, cause = False, f"{type(e).__name__}: {e}"
        with self._lock:
            self._in_flight = False
            self._attempts += 1
            if ok:
                log.warning("%s at %s: reconnected", DEVICE, self.address)
                self._link_lost = False
                self._attempts = 0
                self._last_attempt = ""
                if self._state is MotionState.FAULT:
                    self._message += "; reconnected, the motion was dropped"
                return
            self._last_attempt = cause
            if self._attempts < self.settings.reconnect_attempts:
                self._next_attempt = self._clock.now() + self._delays[self._attempts - 1]

    def reconnect(self) -> None:
        """Grant a fresh budget of reconnect attempts after :meth:`status` gave up (an
        operator's decision, never automatic: that would make the retries unbounded)."""
        with self._lock:
            if self._link_lost and not self._in_flight:
                self._attempts = 0
                self._next_attempt = self._clock.now()

    def _health(self) -> tuple[str, bool] | None:
        """What stops the arm right now, ``(reason, protective_stop)``; None when healthy."""
        if self._link_lost:
            self._maybe_reconnect()  # may succeed inline; then check the arm as usual
            if self._link_lost:
                return self._link_message(), False
        try:
            if not self._rtde.is_connected():
                self._lose_link("RTDE link down")
                self._maybe_reconnect()
                if self._link_lost:
                    return self._link_message(), False
            bits = self._rtde.safety_status_bits()
            mode = self._rtde.robot_mode()
            running = self._rtde.is_program_running()
            if self.settings.watchdog_hz:
                self._rtde.kick_watchdog()
        except Exception as e:  # ur_rtde raises RuntimeError on a dead socket
            self._lose_link(f"{type(e).__name__}: {e}")
            self._maybe_reconnect()
            return self._link_message(), False
        if bits & (1 << PROTECTIVE_STOP_BIT):
            return "protective stop (inspect the cause, then unlock it on the dashboard)", True
        for bit in STOP_BITS:
            if bits & (1 << bit):
                return f"{SAFETY_BITS[bit]} (safety status bits 0x{bits:x})", False
        if mode != ROBOT_MODE_RUNNING:
            name = ROBOT_MODES.get(mode, str(mode))
            return f"robot mode {name}, not RUNNING (power on and release the brakes)", False
        if not running:
            return "the ur_rtde control script is not running on the controller", False
        return None

    def status(self) -> ArmStatus:
        """State of the last commanded motion; a live safety condition or a lost link is a
        FAULT whatever the motion was (and stays latched until the next command)."""
        problem = self._health()
        if problem is not None:
            message, protective = problem
            self._fault(message, protective)
            return ArmStatus(MotionState.FAULT, message, protective)
        if self._state is MotionState.MOVING and self._mode in ("path", "joints"):
            self._poll_progress()
        return ArmStatus(self._state, self._message, self._protective)

    def _poll_progress(self) -> None:
        try:
            p = self._rtde.async_progress()
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(self._link_message())
            return
        if self._await_previous:  # an earlier async move was still running at our command
            if p < 0:
                self._await_previous = False
                self._neg_before = p
            return
        if p >= 0:
            self._seen_running = True
            return
        if not (self._seen_running or p != self._neg_before):
            return  # ours has not started yet
        self._mode = "hold"
        self._check_goal()

    def _check_goal(self) -> None:
        """The move ended: DONE at the goal, FAULT if the controller ended it elsewhere."""
        try:
            if self._goal is not None:
                d, angle = vector_to_pose(self._rtde.tcp_pose()).distance(self._goal)
                if d > DONE_POSITION or angle > DONE_ANGLE:
                    self._fault(
                        f"move ended {d * 1e3:.1f} mm, {np.degrees(angle):.1f} deg from its goal"
                    )
                    return
            elif self._goal_q is not None:
                q = np.asarray(self._rtde.joint_positions(), float)
                err = float(np.max(np.abs(q - self._goal_q)))
                if err > DONE_JOINT:
                    self._fault(f"joint move ended {np.degrees(err):.2f} deg from its goal")
                    return
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(self._link_message())
            return
        self._latch(MotionState.DONE)

    # --- reading -------------------------------------------------------------------------

    def tool_pose(self) -> Pose:
        """Measured TCP pose in the base frame (``getActualTCPPose``), m and rad.

        Raises :class:`DeviceError` while the link is down rather than return a stale pose."""
        if self._link_lost:
            raise DeviceError(DEVICE, self.address, self._link_message())
        return vector_to_pose(self._rtde.tcp_pose())

    def joint_positions(self) -> NDArray[np.float64]:
        """Measured joint angles (rad), base to wrist 3 (``getActualQ``)."""
        if self._link_lost:
            raise DeviceError(DEVICE, self.address, self._link_message())
        return np.asarray(self._rtde.joint_positions(), float).reshape(6)

    # --- commands ------------------------------------------------------------------------

    def _begin(self, what: str) -> bool:
        """Before any command: refuse (FAULT) if the arm cannot move; else leave the mode
        that is running if the new command needs another one."""
        problem = self._health()
        if problem is not None:
            message, protective = problem
            self._fault(f"{what} refused: {message}", protective)
            return False
        try:
            if self._mode == "servo" and what != "servo":
                self._rtde.servo_stop(self.settings.stop_deceleration)
            elif self._mode == "force" and what != "force_mode":
                self._rtde.force_mode_stop()
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(f"{what} refused: {self._link_message()}")
            return False
        return True

    def _send(self, what: str, call: Callable[[], bool]) -> bool:
        """Run one controller call; a refusal or an exception is a FAULT naming the call."""
        try:
            ok = call()
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(f"{what} failed: {self._link_message()}")
            return False
        if not ok:
            self._fault(f"{what} rejected by the controller")
            return False
        return True

    def _start_async(self, what: str, call: Callable[[], bool]) -> None:
        try:
            before = self._rtde.async_progress()
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(f"{what} failed: {self._link_message()}")
            return
        self._await_previous = before >= 0
        self._neg_before = before
        self._seen_running = False
        if self._send(what, call):
            self._latch(MotionState.MOVING)

    def move_to(self, pose: Pose, speed: float, acceleration: float) -> None:
        """Start a straight-line move to ``pose`` (``moveL`` asynchronous; m/s, m/s^2)."""
        _check_limits(speed, acceleration)
        if not self._begin("moveL"):
            return
        target = pose_to_vector(pose)
        self._mode, self._goal, self._goal_q = "path", pose, None
        self._start_async("moveL", lambda: self._rtde.move_l(target, speed, acceleration))

    def move_path(self, waypoints: Sequence[Pose], speed: float, acceleration: float) -> None:
        """Start a straight-line path through ``waypoints`` (one ``moveL`` over the list,
        blended at the intermediate waypoints)."""
        _check_limits(speed, acceleration)
        if not waypoints:
            raise ValueError("a path needs at least one waypoint")
        if len(waypoints) == 1:
            self.move_to(waypoints[0], speed, acceleration)
            return
        if not self._begin("moveL path"):
            return
        try:
            start = vector_to_pose(self._rtde.tcp_pose())
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(f"moveL path failed: {self._link_message()}")
            return
        radii = blend_radii([start, *waypoints], self.settings.path_blend)
        rows = [
            [*pose_to_vector(p), float(speed), float(acceleration), r]
            for p, r in zip(waypoints, radii, strict=True)
        ]
        self._mode, self._goal, self._goal_q = "path", waypoints[-1], None
        self._start_async("moveL path", lambda: self._rtde.move_l_path(rows))

    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None:
        """Start a joint-space move to ``q`` (``moveJ`` asynchronous; rad/s, rad/s^2)."""
        _check_limits(speed, acceleration)
        goal = np.asarray(q, float).reshape(6)
        if not self._begin("moveJ"):
            return
        target = [float(v) for v in goal]
        self._mode, self._goal, self._goal_q = "joints", None, goal
        self._start_async("moveJ", lambda: self._rtde.move_j(target, speed, acceleration))

    def servo(self, target: Pose) -> None:
        """Stream the TCP target for the next control step: one ``servoL`` per call with
        ``time`` = one control period (the caller calls once per tick)."""
        if not self._begin("servo"):
            return
        s = self.settings
        vector = pose_to_vector(target)
        if self._send(
            "servoL",
            lambda: self._rtde.servo_l(vector, 1.0 / s.frequency, s.servo_lookahead, s.servo_gain),
        ):
            self._mode = "servo"
            self.last_servo_target = target
            self._latch(MotionState.MOVING)

    def force_mode(
        self,
        selection: Sequence[bool],
        wrench: Sequence[float],
        speed_limits: Sequence[float],
    ) -> None:
        """Hybrid force-position control in the base frame until :meth:`stop` (``forceMode``,
        task frame = base, type 2)."""
        args = force_mode_arguments(selection, wrench, speed_limits, self.settings.force_deviation)
        if not self._begin("force_mode"):
            return
        if self._mode in ("path", "joints") and self._state is MotionState.MOVING:
            self._stop_motion()
        if self._send("forceMode", lambda: self._rtde.force_mode(*args)):
            self._mode = "force"
            self._latch(MotionState.MOVING)

    def _stop_motion(self) -> None:
        """Send the stop that matches the running mode (no-op when holding)."""
        s = self.settings
        if self._mode == "path":
            self._rtde.stop_l(s.stop_deceleration)
        elif self._mode == "joints":
            self._rtde.stop_j(s.stop_joint_deceleration)
        elif self._mode == "servo":
            self._rtde.servo_stop(s.stop_deceleration)
        elif self._mode == "force":
            self._rtde.force_mode_stop()
        self._mode = "hold"

    def stop(self) -> None:
        """Decelerate to standstill and drop the motion; a running motion ends STOPPED, a
        finished or faulted one keeps its state. Idempotent: a second call sends nothing.

        Never raises: it is what guards call on their way out. Without a link nothing can be
        sent; the status stays FAULT with the reason."""
        mode = self._mode
        if mode == "hold" or self._link_lost:
            self._mode = "hold"
            if self._state is MotionState.MOVING and not self._link_lost:
                self._latch(MotionState.STOPPED)
            return
        try:
            self._stop_motion()
        except Exception as e:
            self._mode = "hold"
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(f"stop failed: {self._link_message()}")
            return
        if self._state is MotionState.MOVING:
            self._latch(MotionState.STOPPED)

    # --- start-up and recovery -----------------------------------------------------------

    def recover(self) -> None:
        """After a protective stop whose cause was inspected: close the popup, unlock the stop
        on the dashboard and restart the control script. Blocking; not for a tick."""
        if self.dashboard is None:
            raise DeviceError(DEVICE, self.address, "recover() needs the dashboard client")
        self.dashboard.close_safety_popup()
        self.dashboard.unlock_protective_stop()
        if not self._rtde.reupload_script():
            raise DeviceError(DEVICE, self.address, "the control script did not restart")
        self._latch(MotionState.IDLE)

    def check(self) -> CheckResult:
        """Start-up check: link, robot mode, safety status, control script; controller version
        and serial from the dashboard when there is one. Never moves the arm."""
        details: dict[str, str] = {"rtde_frequency_hz": f"{self.settings.frequency:g}"}
        problems: list[str] = []
        try:
            connected = self._rtde.is_connected()
            details["rtde_connected"] = str(connected)
            if connected:
                mode = self._rtde.robot_mode()
                bits = self._rtde.safety_status_bits()
                details["robot_mode"] = ROBOT_MODES.get(mode, str(mode))
                details["safety_status"] = describe_safety_bits(bits)
                details["control_script"] = (
                    "running" if self._rtde.is_program_running() else "not running"
                )
                details["joints_rad"] = " ".join(f"{v:.4f}" for v in self._rtde.joint_positions())
                details["tcp_pose"] = " ".join(f"{v:.4f}" for v in self._rtde.tcp_pose())
            else:
                problems.append("RTDE not connected")
        except Exception as e:
            problems.append(f"RTDE: {type(e).__name__}: {e}")
        if self.dashboard is not None:
            for key, read in (
                ("controller_version", self.dashboard.polyscope_version),
                ("serial_number", self.dashboard.serial_number),
                ("robot_model", self.dashboard.robot_model),
                ("dashboard_robot_mode", self.dashboard.robot_mode),
                ("dashboard_safety_status", self.dashboard.safety_status),
            ):
                try:
                    details[key] = read()
                except DeviceError as e:
                    details[key] = "unavailable"
                    # Older CB3 software lacks these two commands: reported, not a failure.
                    if key not in ("serial_number", "robot_model"):
                        problems.append(str(e))  # names the dashboard's address
        problem = None if problems else self._health()
        if problem is not None:
            problems.append(problem[0])
        return CheckResult(
            DEVICE, self.address, not problems, details, "; ".join(problems) or None
        )

    def close(self) -> None:
        """Stop, then drop the links (shutdown path)."""
        self.stop()
        try:
            self._rtde.disconnect()
        finally:
            if self.dashboard is not None:
                self.dashboard.close()


def _check_limits(speed: float, acceleration: float) -> None:
    if speed <= 0 or acceleration <= 0:
        raise ValueError(f"speed and acceleration must be > 0, got {speed}, {acceleration}")


def blend_radii(poses: Sequence[Pose], blend: float) -> list[float]:
    """Blend radius (m) for each pose after the first (the start): ``blend`` capped at
    :data:`BLEND_FRACTION` of the shorter neighbouring segment so blends never overlap (the
    controller rejects overlapping ones), 0 at the last waypoint so the path ends on it."""
    lengths = [
        float(np.linalg.norm(b.position - a.position))
        for a, b in zip(poses[:-1], poses[1:], strict=True)
    ]
    radii = [
        min(blend, BLEND_FRACTION * min(lengths[i], lengths[i + 1]))
        for i in range(len(lengths) - 1)
    ]
    return [*radii, 0.0]


def force_mode_arguments(
    selection: Sequence[bool],
    wrench: Sequence[float],
    speed_limits: Sequence[float],
    deviation: Sequence[float],
) -> tuple[list[float], list[int], list[float], int, list[float]]:
    """``forceMode`` arguments ``(task_frame, selection, wrench, type, limits)`` for the Arm's
    base-frame force mode: task frame = base (identity pose), type 2 (frame not transformed);
    compliant axes limited to ``speed_limits``, the others to ``deviation``."""
    sel = [bool(v) for v in selection]
    w = [float(v) for v in wrench]
    lim = [abs(float(v)) for v in speed_limits]
    if not (len(sel) == len(w) == len(lim) == 6):
        raise ValueError("selection, wrench and speed_limits need 6 values each")
    limits = [lim[i] if sel[i] else float(deviation[i]) for i in range(6)]
    return [0.0] * 6, [int(v) for v in sel], w, 2, limits
