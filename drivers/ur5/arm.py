"""The :class:`drivers.arm.Arm` interface on a real UR5 over ``ur_rtde``.

Same semantics as the twin's :class:`sim.arm.SimArm`: every command starts a motion and returns;
the control loop polls :meth:`UR5Arm.status` once per tick. Nothing called per tick sleeps or
waits on the network beyond one ``ur_rtde`` call (asynchronous moves and stops, ``servoL``, and
reads of the state ur_rtde's receive threads already hold).

How each command maps onto the controller, and why:

* :meth:`move_to` / :meth:`move_path`: ``moveL`` with ``asynchronous=True``; a path is one
  ``moveL`` over a list of poses with blend radii, so the TCP does not stop at intermediate
  waypoints (as in the twin). UR rejects overlapping blends, so each radius is at most
  :data:`BLEND_FRACTION` of its shorter neighbouring segment. ur_rtde sends a path by stopping
  its control script and uploading it again with the path inside, then waits, without a
  timeout, for the program to run: that call runs on a worker thread, bounded by
  ``script_start_timeout``; the tick only polls it.
* :meth:`move_joints`: ``moveJ`` asynchronous.
* ur_rtde sends a command and waits for the control script's handshake (two to three
  controller cycles: 16-24 ms on a CB3, longer than a tick). A move's command is therefore
  sent on a worker, as a path's upload is: the move is MOVING at once and :meth:`status` polls
  the worker, then the operation. A stop meanwhile is sent by the worker right after the
  command; any other command meanwhile waits for it (at most the handshake), so ur_rtde's
  control interface is never entered twice at once.
* Completion comes from the async status word (``getAsyncOperationProgressEx``): the script
  numbers every async operation it starts and flags the running one. Our move is the first
  operation numbered after the one current when it was sent (after a path's re-upload: any
  operation of the fresh script); it ended when that operation is no longer running or another
  replaced it. Nothing waits for a "-1": the script cancels a running operation and starts the
  next within one controller cycle, so none is published between two moves. A finished move is
  DONE only if the arm is within the goal tolerance.
* A move right after an asynchronous stop is held back (the state says MOVING) until the stop's
  operation has ended: the script's stop thread, when it ends, marks whatever operation is current
  as finished, which would end the new move's tracking at once.
* :meth:`servo`: one ``servoL`` per call (the caller calls it once per tick), ``time`` = one
  control period, with ``lookahead``/``gain`` from :class:`UR5Settings`.
* :meth:`force_mode`: ``forceMode`` with the base frame as task frame (type 2: not transformed);
  selected axes get the caller's speed limits, the others the allowed deviation from
  :class:`UR5Settings` (what UR's ``limits`` mean for non-compliant axes).
* :meth:`stop`: ``stopL`` (asynchronous) for moves and joint moves alike -- the script runs
  every asynchronous stop as ``stopl``, so the deceleration is ``stop_deceleration`` in m/s^2 --
  ``servoStop`` or ``forceModeStop``, whichever matches the running mode; a second call sends
  nothing.
* :meth:`status`: the live safety status bits and robot mode come first (protective stop ->
  FAULT with ``protective_stop=True``; emergency or safeguard stop, violation, fault, robot not
  RUNNING, control script not running, lost link -> FAULT with the reason), then the motion.
  A fault is latched until the next command, as in the twin.
* Lost link: bounded reconnect attempts with :func:`drivers.health.backoff_delays` between them,
  scheduled on the clock and run off the tick (``ur_rtde``'s reconnect blocks on TCP connects),
  so a dead controller costs a handful of attempts, never a storm. A reconnect uploads a fresh
  control script, so the watchdog (which lives for one script run) is armed again after it, as
  after :meth:`recover`.
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

from drivers.arm import ArmStatus, MotionState
from drivers.clock import Clock, WallClock
from drivers.health import CheckResult, DeviceError, backoff_delays
from drivers.pose import Pose
from drivers.ur5.dashboard import DashboardClient
from drivers.ur5.rtde_adapter import RTDE_PORT, RTDEAdapter, URRTDEAdapter

F = TypeVar("F", bound=Callable[..., Any])

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


#: s: servoj's lookahead time for each ``servoL`` (UR's range 0.03-0.2). servoj follows the stream
#: as ``q'' = gain (q_goal - q - lookahead q')`` (UR's description; :mod:`sim.arm`): it trails a
#: steady stream by the lookahead. At UR's example values (0.1 s, 300) the twin's pivot lost the
#: hole in 2 of 10 bushing trials; at 0.05 s and 1000, 10 of 10 (damping 0.79, 5 Hz).
SERVO_LOOKAHEAD = 0.05
#: 1/s^2: servoj's proportional gain (UR's range 100-2000); see :data:`SERVO_LOOKAHEAD`.
SERVO_GAIN = 1000.0


@dataclass(frozen=True)
class UR5Settings:
    """Tuning of the UR5 driver; the defaults suit a CB3 UR5 at 125 Hz."""

    frequency: float = 125.0  #: Hz: RTDE and control rate (500 on an e-Series)
    servo_lookahead: float = SERVO_LOOKAHEAD  #: s, UR range [0.03, 0.2]: smooths the stream
    servo_gain: float = SERVO_GAIN  #: UR range [100, 2000]: servoL position gain
    path_blend: float = 0.01  #: m: blend radius at intermediate path waypoints (upper bound)
    #: m/s^2: every stop of a move, a joint move or servoing (the control script runs each
    #: asynchronous stop as ``stopl``, so there is no joint deceleration to set)
    stop_deceleration: float = 10.0
    #: s: the longest wait for an uploaded control script to run (a path's upload, recover())
    script_start_timeout: float = 5.0
    #: s: the controller's data packages (their ``timestamp``) may stop advancing this long
    #: before the link counts as lost. A pulled cable rarely closes the socket (no FIN from a
    #: dead peer), so ur_rtde may go on reporting "connected" over a silent link.
    data_timeout: float = 0.5
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
        if self.script_start_timeout <= 0:
            raise ValueError("script_start_timeout must be > 0 s")
        if self.data_timeout <= 0:
            raise ValueError("data_timeout must be > 0 s")


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


@dataclass
class _CommandJob:
    """A move's command on its worker thread: a path's ``moveL`` (ur_rtde re-uploads its
    script for it) or a single ``moveL`` / ``moveJ``, whose handshake with the control script
    takes two to three controller cycles (16-24 ms on a CB3) that the tick must not wait."""

    started: float
    finished: threading.Event = field(default_factory=threading.Event)
    ok: bool = False
    error: str | None = None
    cancelled: bool = False
    what: str = "moveL path"
    #: a path's upload starts a fresh script, whose operations number from 0
    fresh_script: bool = True


#: s close() waits for the control side to see a drop the receive side has seen
LINK_SETTLE = 0.25
#: a watchdog kick once this share of the watchdog's period has passed since the last kick or
#: command: the tick loop polls every period, so a poll up to (1 - share) of the watchdog's
#: period late still keeps it fed
KICK_SHARE = 0.25
#: controller cycles that must have run (by the controller's own timestamp) since a command was
#: written before a kick may write the command register: the timestamp last seen may be a cycle
#: old, and the script reads a command at the cycle after it arrives
KICK_QUIET_CYCLES = 3
#: the speed slider the cell's moves run at: their speeds and accelerations as programmed
RUN_SPEED_FRACTION = 1.0


def _serialized(method: F) -> F:
    """One caller at a time in the driver: the force-torque guard stops the arm from the
    sensor's reader thread while the tick may be sending the next command, and neither this
    driver's state nor ur_rtde's interfaces may be entered twice at once."""

    @functools.wraps(method)
    def locked(self: UR5Arm, *args: Any, **kwargs: Any) -> Any:
        with self._cmd:
            return method(self, *args, **kwargs)

    return cast(F, locked)


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
        self._cmd = threading.RLock()  #: see _serialized
        self._io_lock = threading.Lock()  #: the speed slider's connection (see stop)
        #: the slider is at 0 after a stop; set back before the next command. Set at start-up
        #: too: a run that ended between the two leaves the controller's slider at 0.
        self._paused = True
        self._rtde = adapter
        self._clock = clock or WallClock()
        self.settings = settings or UR5Settings()
        self.dashboard = dashboard
        self._spawn = spawn
        self._mode = "hold"  # hold | path | joints | servo | force
        self._state = MotionState.IDLE
        self._message = ""
        self._protective = False
        # Async move completion (see _poll_progress): the operation id current before our
        # command, ours once seen, a command held back behind a running async stop.
        self._op_before = 0
        self._op_ours: int | None = None
        self._stop_sent = False
        self._deferred: tuple[str, Callable[[], bool]] | None = None
        # A path's upload on its worker thread (see move_path).
        self._job: _CommandJob | None = None
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
        #: the watchdog is armed by start_watchdog(), once the start-up is over: the checks
        #: and the gripper's calibration poll the arm less often than a 10 Hz watchdog needs
        self._watchdog_on = False
        self._last_command = -float("inf")  #: clock time of the newest command written
        #: the controller's timestamp last read (its data packages), and when it last moved
        self._stamp: float | None = None
        self._stamp_seen = 0.0
        #: the controller's timestamp last seen when the newest command was written
        self._command_stamp: float | None = None
        self._last_kick = -float("inf")  #: clock time of the newest watchdog kick

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
            if ok and self._watchdog_on:  # a fresh script: arm its watchdog again
                ok = bool(self._rtde.set_watchdog(self.settings.watchdog_hz))
                cause = "the controller refused the watchdog after the reconnect"
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

    def _data_stale(self) -> bool:
        """True when the controller's timestamp has not moved for ``data_timeout`` s."""
        stamp, now = float(self._rtde.timestamp()), self._clock.now()
        if stamp != self._stamp:
            self._stamp, self._stamp_seen = stamp, now
            return False
        return now - self._stamp_seen > self.settings.data_timeout

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
            if self._data_stale():
                self._lose_link(
                    f"RTDE data stale: no new package for {self.settings.data_timeout:g} s"
                )
                self._maybe_reconnect()
                if self._link_lost:
                    return self._link_message(), False
            bits = self._rtde.safety_status_bits()
            mode = self._rtde.robot_mode()
            # While a path's upload runs on its worker, the script is being replaced (not
            # running, no watchdog) and the control interface is the worker's.
            uploading = self._job is not None
            running = uploading or self._rtde.is_program_running()
            # A kick writes the command register (with 0): sent within a controller cycle of
            # a command, it overwrote the command before the script read it (a force mode that
            # never began, on the UR emulator). A command written since refreshes the watchdog
            # itself, so the kick waits until the controller has run KICK_QUIET_CYCLES since
            # (its own timestamp: a controller that runs late -- the emulator on a loaded
            # machine -- read a force mode late, and a kick two wall-clock cycles after it
            # overwrote it: the push never began), and two of the cell's cycles.
            # A kick is sent as often as the watchdog needs, not on every poll: a command the
            # tick sends right after a kick waits longer for the control script (measured
            # against the UR emulator: commands' median 2.9 -> 6.0 ms with a kick every poll).
            now = self._clock.now()
            period = 1.0 / self.settings.frequency
            quiet = now - self._last_command >= 2.0 * period and (
                self._command_stamp is None
                or self._stamp is None
                or self._stamp - self._command_stamp >= KICK_QUIET_CYCLES * period
            )
            due = (now - max(self._last_command, self._last_kick)
                   >= KICK_SHARE / (self.settings.watchdog_hz or 1.0))
            if self._watchdog_on and not uploading and quiet and due:
                self._rtde.kick_watchdog()
                self._last_kick = now
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

    @_serialized
    def status(self) -> ArmStatus:
        """State of the last commanded motion; a live safety condition or a lost link is a
        FAULT whatever the motion was (and stays latched until the next command)."""
        problem = self._health()
        if problem is not None:
            message, protective = problem
            self._fault(message, protective)
            return ArmStatus(MotionState.FAULT, message, protective, link_lost=self._link_lost)
        if self._job is not None:
            self._poll_job()
        elif self._state is MotionState.MOVING and self._mode in ("path", "joints"):
            self._poll_progress()
        return ArmStatus(self._state, self._message, self._protective)

    def _poll_progress(self) -> None:
        try:
            running, op = self._rtde.async_status()
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(self._link_message())
            return
        if self._stop_sent and not running:
            self._stop_sent = False  # the async stop's operation has ended
        if self._deferred is not None:
            if running:
                return  # the stop still runs: ours waits
            what, call = self._deferred
            self._deferred = None
            self._start_async(what, call)
            return
        if self._op_ours is None:
            if op == self._op_before:
                return  # ours has not started yet
            self._op_ours = op
        if op == self._op_ours and running:
            return
        self._mode = "hold"
        self._check_goal()

    def _poll_job(self) -> None:
        """The path's upload on its worker: wait (MOVING), bounded by script_start_timeout."""
        job = self._job
        assert job is not None
        if not job.finished.is_set():
            if self._clock.now() - job.started <= self.settings.script_start_timeout:
                return
            self._job = None
            if job.fresh_script:
                self._fault(f"moveL path: the control script did not start within "
                            f"{self.settings.script_start_timeout:g} s")
                self._lose_link("the control script did not start after a path's upload")
            else:
                self._fault(f"{job.what}: the control script did not take it within "
                            f"{self.settings.script_start_timeout:g} s")
                self._lose_link(f"the control script did not take a {job.what}")
            self._spawn(self._rtde.drop_control)
            return
        self._job = None
        if job.error is not None:
            self._lose_link(job.error)
            self._fault(f"{job.what} failed: {self._link_message()}")
        elif not job.ok:
            self._fault(f"{job.what} rejected by the controller")
        elif job.cancelled:
            self._mode = "hold"
            self._stop_sent = True
            if self._state is MotionState.MOVING:
                self._latch(MotionState.STOPPED)
        else:
            if job.fresh_script:
                self._op_before, self._op_ours = 0, None  # a fresh script numbers from 0
            self._poll_progress()

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

    @_serialized
    def tool_pose(self) -> Pose:
        """Measured TCP pose in the base frame (``getActualTCPPose``), m and rad.

        Raises :class:`DeviceError` while the link is down rather than return a stale pose."""
        if self._link_lost:
            raise DeviceError(DEVICE, self.address, self._link_message())
        return vector_to_pose(self._rtde.tcp_pose())

    @_serialized
    def joint_positions(self) -> NDArray[np.float64]:
        """Measured joint angles (rad), base to wrist 3 (``getActualQ``)."""
        if self._link_lost:
            raise DeviceError(DEVICE, self.address, self._link_message())
        return np.asarray(self._rtde.joint_positions(), float).reshape(6)

    # --- commands ------------------------------------------------------------------------

    def _begin(self, what: str) -> bool:
        """Before any command: refuse (FAULT) if the arm cannot move; else leave the mode
        that is running if the new command needs another one."""
        if self._job is not None and not self._job.fresh_script:
            self._settle_job()
        if self._job is not None:
            self._fault(f"{what} refused: a path's upload is still under way (stop first)")
            return False
        problem = self._health()
        if problem is not None:
            message, protective = problem
            self._fault(f"{what} refused: {message}", protective)
            return False
        self._deferred = None
        try:
            self._resume_speed()
            if self._paused:
                self._fault(f"{what} refused: the controller did not take the speed slider "
                            "back from 0")
                return False
            if self._mode == "servo" and what != "servo":
                self._rtde.servo_stop(self.settings.stop_deceleration)
            elif self._mode == "force" and what != "force_mode":
                self._rtde.force_mode_stop()
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(f"{what} refused: {self._link_message()}")
            return False
        return True

    def _mark_command(self) -> None:
        """A command is being written: the time, on the cell's clock and on the controller's
        (the timestamp last seen), that the watchdog's kick waits out (see :meth:`_health`)."""
        self._last_command = self._clock.now()
        self._command_stamp = self._stamp

    def _send(self, what: str, call: Callable[[], bool]) -> bool:
        """Run one controller call; a refusal or an exception is a FAULT naming the call."""
        self._mark_command()
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
            running, op = self._rtde.async_status()
        except Exception as e:
            self._lose_link(f"{type(e).__name__}: {e}")
            self._fault(f"{what} failed: {self._link_message()}")
            return
        if self._stop_sent and running:
            self._deferred = (what, call)  # sent when the stop's operation has ended
            self._latch(MotionState.MOVING)
            return
        self._stop_sent = False
        self._deferred = None
        self._op_before, self._op_ours = op, None
        # The handshake off the tick (see _CommandJob); status() polls the job, then the move.
        self._mark_command()
        job = _CommandJob(self._clock.now(), what=what, fresh_script=False)
        self._job = job
        self._latch(MotionState.MOVING)
        deceleration = self.settings.stop_deceleration

        def send() -> None:
            try:
                job.ok = bool(call())
                if job.cancelled and job.ok:
                    self._rtde.stop_l(deceleration)  # stopped while it was being sent
            except Exception as e:  # whatever ur_rtde raises: the command failed
                job.error = f"{type(e).__name__}: {e}"
            job.finished.set()

        self._spawn(send)

    def _settle_job(self) -> None:
        """A command arrived while a move's command is under way on its worker (a handshake:
        a few controller cycles; a path's upload: longer): wait for it, bounded, so the two
        never enter ur_rtde's control interface at once."""
        job = self._job
        if job is None:
            return
        job.finished.wait(self.settings.script_start_timeout)
        self._poll_job()

    @_serialized
    def move_to(self, pose: Pose, speed: float, acceleration: float) -> None:
        """Start a straight-line move to ``pose`` (``moveL`` asynchronous; m/s, m/s^2)."""
        _check_limits(speed, acceleration)
        if not self._begin("moveL"):
            return
        target = pose_to_vector(pose)
        self._mode, self._goal, self._goal_q = "path", pose, None
        self._start_async("moveL", lambda: self._rtde.move_l(target, speed, acceleration))

    @_serialized
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
        self._deferred = None
        job = _CommandJob(self._clock.now())
        self._job = job
        self._latch(MotionState.MOVING)
        watchdog = self.settings.watchdog_hz if self._watchdog_on else None

        def upload() -> None:
            try:
                job.ok = bool(self._rtde.move_l_path(rows))
                if job.ok and watchdog:
                    self._rtde.set_watchdog(watchdog)  # the fresh script has none
                if job.cancelled:
                    self._rtde.stop_l(self.settings.stop_deceleration)
            except Exception as e:  # whatever ur_rtde raises: the upload failed
                job.error = f"{type(e).__name__}: {e}"
            job.finished.set()

        self._spawn(upload)  # off the tick: ur_rtde blocks until the new script runs

    @_serialized
    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None:
        """Start a joint-space move to ``q`` (``moveJ`` asynchronous; rad/s, rad/s^2)."""
        _check_limits(speed, acceleration)
        goal = np.asarray(q, float).reshape(6)
        if not self._begin("moveJ"):
            return
        target = [float(v) for v in goal]
        self._mode, self._goal, self._goal_q = "joints", None, goal
        self._start_async("moveJ", lambda: self._rtde.move_j(target, speed, acceleration))

    def servo_lag(self) -> float:
        """servoj's lookahead time: the controller trails a steady stream by it."""
        return self.settings.servo_lookahead

    @_serialized
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

    @_serialized
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
        self._mark_command()
        if self._job is not None:
            self._job.cancelled = True  # the worker stops the arm once its upload returns
        elif self._deferred is not None:
            self._deferred = None  # never sent: nothing to stop
        elif self._mode in ("path", "joints"):
            self._rtde.stop_l(s.stop_deceleration)
            self._stop_sent = True
        elif self._mode == "servo":
            self._rtde.servo_stop(s.stop_deceleration)
        elif self._mode == "force":
            self._rtde.force_mode_stop()
        self._mode = "hold"

    def stop(self) -> None:
        """Decelerate to standstill and drop the motion; a running motion ends STOPPED, a
        finished or faulted one keeps its state. Idempotent: a second call sends nothing.

        A move (path or joints) is first paused by the speed slider, before the driver's
        lock: the force-torque guard calls this from the sensor's thread, possibly while the
        tick is inside a command, and ``stopL`` itself waits for the control script to finish
        the handshake of any command in flight (up to three controller cycles on a CB3, 24
        ms). The slider acts in the controller's next cycle; ``stopL`` then ends the move, and
        the next command sets the slider back (:data:`RUN_SPEED_FRACTION`).

        Never raises: it is what guards call on their way out. Without a link nothing can be
        sent; the status stays FAULT with the reason."""
        self._pause()
        with self._cmd:
            self._stop_locked()

    def _pause(self) -> None:
        """The speed slider to 0 if a move runs (see :meth:`stop`). Reads the mode without the
        lock: a move that ends meanwhile costs a pause the next command undoes, and one that
        starts meanwhile is stopped by ``stopL`` all the same."""
        if self._mode not in ("path", "joints") or self._link_lost:
            return
        with self._io_lock:
            try:
                paused = bool(self._rtde.set_speed_slider(0.0))
            except Exception:  # noqa: BLE001 -- stopL follows; the status says what failed
                paused = False
            self._paused = self._paused or paused

    def _resume_speed(self) -> None:
        """Set the slider back before a command (the paused move was ended by its stop: a
        command is refused while a path's upload, which stops on its own, is under way)."""
        with self._io_lock:
            if self._paused and self._rtde.set_speed_slider(RUN_SPEED_FRACTION):
                self._paused = False

    def _stop_locked(self) -> None:
        mode = self._mode
        if self._job is not None:
            self._job.cancelled = True
            self._job = None if self._job.finished.is_set() else self._job
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

    @_serialized
    def recover(self) -> None:
        """After a protective stop whose cause was inspected: close the popup, unlock the stop
        on the dashboard and restart the control script. Blocking; not for a tick."""
        if self.dashboard is None:
            raise DeviceError(DEVICE, self.address, "recover() needs the dashboard client")
        self._settle_job()
        self.dashboard.close_safety_popup()
        self.dashboard.unlock_protective_stop()
        if not self._rtde.reupload_script():
            raise DeviceError(DEVICE, self.address, "the control script did not restart")
        # reuploadScript() returns once the text is sent; the controller starts the program
        # later, and ur_rtde refuses every command until it runs.
        t_end = time.monotonic() + self.settings.script_start_timeout
        while not self._rtde.is_program_running():
            if time.monotonic() > t_end:
                raise DeviceError(
                    DEVICE, self.address,
                    f"the control script did not run within {self.settings.script_start_timeout:g}"
                    " s of its upload",
                )
            time.sleep(0.005)
        self._arm_watchdog()  # it lived for the old script's run only
        self._stop_sent, self._deferred = False, None
        self._latch(MotionState.IDLE)

    @_serialized
    def start_watchdog(self) -> None:
        """Arm ur_rtde's watchdog at ``settings.watchdog_hz`` (if set): from now on the
        controller stops the control script, and the arm, when :meth:`status` is not polled
        that often (the tick loop polls it every tick). Call it when the ticks start, not
        before: the start-up does not poll that often. Raises :class:`DeviceError` when the
        controller refuses it."""
        if self.settings.watchdog_hz and not self._watchdog_on:
            # Called from the tick loop after its first tick, whose move may be on its worker.
            self._settle_job()
            self._watchdog_on = True
            self._arm_watchdog()

    def _arm_watchdog(self) -> None:
        if not self._watchdog_on:
            return
        if self.settings.watchdog_hz and not self._rtde.set_watchdog(self.settings.watchdog_hz):
            raise DeviceError(DEVICE, self.address, "the controller refused the watchdog")

    @_serialized
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

    @_serialized
    def close(self) -> None:
        """Stop, then drop the links (shutdown path); no further reconnect attempt starts. A
        control link ur_rtde has seen drop is abandoned, not disconnected: see
        :func:`drivers.ur5.rtde_adapter.links_abandoned` for why and what the process owes."""
        self.stop()
        try:
            with self._lock:
                self._attempts = self.settings.reconnect_attempts
            # Only a control link ur_rtde has seen drop is abandoned: one still up (the data went
            # stale, an upload timed out) is disconnected, which stops the control script and so
            # the arm; nothing else would once this process ends. The two sides are separate
            # sockets: when the receive side has seen the drop, the control side is given a
            # moment to see it too (against the UR emulator it lagged in 1 pull of 6, and the
            # disconnect then took the exit from 34 ms to 2.3 s).
            if self._link_lost and not self._rtde.receive_connected():
                deadline = time.monotonic() + LINK_SETTLE
                while self._rtde.control_connected() and time.monotonic() < deadline:
                    time.sleep(0.005)
            if self._link_lost and not self._rtde.control_connected():
                self._rtde.abandon()
            else:
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
