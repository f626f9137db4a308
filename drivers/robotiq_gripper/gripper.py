"""The :class:`drivers.gripper.Gripper` interface on a real Robotiq 2F-85.

Why a background thread: the tree ticks at the arm's control rate and every skill polls
``moving()``/``fault()`` each tick, but one status read is a serial round trip (and up to
``(retries + 1) * timeout`` when the gripper is silent). So one thread owns the transport: it
sends queued commands and reads the status at ``poll_hz``, and keeps the newest status with the
time it arrived. The Gripper methods only read that cache and return at once; a status older than
``stale_after`` makes :meth:`Robotiq2F85.fault` report it, so a cut cable fails the running
motion instead of freezing the tree.

Commands (:meth:`open`, :meth:`close`, :meth:`start_activation`) are queued and return at once.
Until a status read after the command echoes its position request (gPR), ``moving()`` stays True,
so a skill never mistakes the previous motion's "arrived" for the new one's.

Errors: a transport failure (after its bounded retries) is kept and surfaces through ``fault()``;
the thread then waits with growing back-off (up to 2 s) before trying again, so a dead gripper
costs a few requests a second, not a storm. A command that could not be sent is dropped, never
replayed later (a late go-to is worse than none), and reported by ``fault()``.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import replace

from drivers.gripper_spec import GripperSpec, default_gripper
from drivers.health import CheckResult, DeviceError
from drivers.robotiq_gripper.registers import (
    OBJ_MOVING,
    OBJ_STALLED_CLOSING,
    OBJ_STALLED_OPENING,
    STA_TEXT,
    STROKE,
    ActionRequest,
    Calibration,
    GripperStatus,
    count_force,
    count_speed,
    fault_text,
    force_count,
    speed_count,
)
from drivers.robotiq_gripper.transport import DEVICE, GripperTransport

OPEN_FORCE = 100.0  #: N, the force setting while opening (as the twin's OPEN_FORCE)
FORCE_CAL = 20.0  #: N, the gentlest grip, for the calibration close
ERROR_BACKOFF_CAP = 2.0  #: s, longest wait between polls while the gripper does not answer

_RESET = "reset"  # queue marker: write rACT = 0, then rACT = 1 once the reset shows


class Robotiq2F85:
    """Implements :class:`drivers.gripper.Gripper` on a 2F-85 behind a :class:`GripperTransport`.

    ``transport``: :class:`ModbusRtuTransport` or :class:`UrcapSocketTransport`;
    ``calibration``: the unit's open/closed position counts (see :meth:`calibrate`);
    ``finger_width``: pad width ``w`` (m; the twin's 0.020 by default, so planning agrees);
    ``poll_hz``: status reads a second; ``stale_after``: s after which the newest status counts
    as lost (a fault); ``clock``: monotonic seconds; ``spec``: the gripper's description (the
    shipped 2F-85 by default), whose linkage gives :meth:`tip_advance`. Call :meth:`start` (or
    use ``with``) before use and :meth:`disconnect` after; disconnecting leaves the fingers where
    they are.
    """

    stroke: float = STROKE

    def __init__(
        self,
        transport: GripperTransport,
        calibration: Calibration | None = None,
        finger_width: float = 0.020,
        poll_hz: float = 50.0,
        stale_after: float = 0.5,
        clock: Callable[[], float] = time.monotonic,
        spec: GripperSpec | None = None,
    ) -> None:
        self.spec = spec or default_gripper()
        if poll_hz <= 0 or stale_after <= 0:
            raise ValueError("poll_hz and stale_after must be > 0")
        self.transport = transport
        self.calibration = calibration or Calibration()
        self.finger_width = finger_width
        self.poll_hz, self.stale_after = poll_hz, stale_after
        self._clock = clock
        self._lock = threading.Lock()
        self._queue: deque[ActionRequest | str] = deque()
        self._status: GripperStatus | None = None
        self._status_time = -float("inf")
        self._link_error: str | None = None  # the newest transport failure (cleared by a read)
        self._command_error: str | None = None  # a command that could not be sent
        self._queued = 0  # go-to commands queued so far
        self._confirmed = 0  # ... of which a status has echoed the position request
        self._sent_pr: int | None = None  # position request of the newest sent go-to
        self._sent_seq = 0
        self._activating = False  # an activation is queued or under way (rACT = 1 not yet sent)
        self._reset_sent = False  # the reset is written; rACT = 1 follows once gACT reads 0
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self.polls = 0  #: successful status reads (diagnostics, tests)

    # --- life cycle ------------------------------------------------------------------------

    def start(self) -> Robotiq2F85:
        """Open the link and start the status thread. Raises DeviceError if the link fails."""
        if self._thread is not None:
            return self
        self.transport.connect()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="robotiq-2f85", daemon=True)
        self._thread.start()
        return self

    def disconnect(self) -> None:
        """Stop the thread and close the link; the gripper keeps its state (and its part).

        (Not ``close``: that name is the Gripper interface's finger command.)"""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self.transport.close()

    def __enter__(self) -> Robotiq2F85:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    # --- commands (return at once) -------------------------------------------------------

    def start_activation(self) -> None:
        """Queue the activation sequence (reset, then rACT = 1); poll :meth:`activated`.

        On the real gripper activation moves the fingers through their whole stroke and takes a
        few seconds, so no part may be between them.
        """
        with self._lock:
            self._queue.append(_RESET)
            self._activating = True
        self._wake.set()

    def activated(self) -> bool:
        """True once a fresh status shows gACT = 1 and gSTA = 3."""
        st = self._fresh_status()
        return st is not None and st.activated

    def open(self, width: float | None = None, speed: float = 0.1) -> None:
        """Start opening to ``width`` (m; full stroke if None) at ``speed`` (m/s)."""
        target = self.stroke if width is None else width
        self._go(self.calibration.count(target), speed, OPEN_FORCE)

    def close(self, force: float, speed: float = 0.05, width: float = 0.0) -> None:
        """Start closing towards ``width`` (m; 0 = fully) with at most ``force`` (N) at
        ``speed`` (m/s); the gripper stops on a part and holds it with ``force``."""
        self._go(self.calibration.count(width), speed, force)

    def _go(self, position: int, speed: float, force: float) -> None:
        req = ActionRequest(act=True, gto=True, position=position, speed=speed_count(speed),
                            force=force_count(force))
        with self._lock:
            # A newer go-to replaces one not yet sent: only the newest target matters.
            if self._queue and isinstance(self._queue[-1], ActionRequest):
                self._queue.pop()
            self._queue.append(req)
            self._queued += 1
            self._command_error = None
        self._wake.set()

    # --- the Gripper queries (cached, return at once) ------------------------------------

    def width(self) -> float:
        """Opening (m) from the newest status's gPO through the calibration."""
        with self._lock:
            st = self._status
        if st is None:
            raise DeviceError(DEVICE, self.transport.address, "no status received yet")
        return self.calibration.width(st.po)

    def tip_advance(self, width: float) -> float:
        """m the tips reach further along the approach at ``width`` than closed (the linkage of
        the gripper's description)."""
        return self.spec.tip_advance(width)

    def moving(self) -> bool:
        """True while the newest go-to is not yet echoed or the fingers still travel."""
        with self._lock:
            if self._command_error is not None:
                return False
            if self._confirmed < self._queued:
                return True
            st = self._status
        return st is not None and st.activated and st.gto == 1 and st.obj == OBJ_MOVING

    def object_detected(self) -> bool:
        """True when the fingers stalled on an object (gOBJ 1 or 2) in the newest motion."""
        with self._lock:
            if self._confirmed < self._queued:
                return False
            st = self._status
        return st is not None and st.obj in (OBJ_STALLED_OPENING, OBJ_STALLED_CLOSING)

    def fault(self) -> str | None:
        """Why the gripper cannot be trusted now, or None: a lost or stale status, a command
        that was not delivered, or the gripper's own fault code (gFLT) as text."""
        with self._lock:
            st, t, link, cmd = (self._status, self._status_time, self._link_error,
                                self._command_error)
        age = self._clock() - t
        if st is None or age > self.stale_after:
            what = ("no status received yet" if st is None
                    else f"status stale: newest is {age:.2f} s old (limit {self.stale_after} s)")
            return f"{what}; {link}" if link else what
        if cmd is not None:
            return cmd
        return fault_text(st.flt)

    # --- extras for start-up and diagnostics ------------------------------------------------

    def status(self) -> tuple[GripperStatus | None, float]:
        """The newest status and its age (s)."""
        with self._lock:
            return self._status, self._clock() - self._status_time

    def activate(self, timeout: float = 10.0) -> None:
        """Blocking activation for start-up checks only (never from a tick): reset, rACT = 1,
        wait for gSTA = 3. Raises DeviceError on a fault or after ``timeout`` s."""
        self.start()
        self.start_activation()
        self._wait(lambda st: st.activated and not self._activating, timeout, "activation")

    def calibrate(self, timeout: float = 10.0) -> Calibration:
        """Blocking, start-up only, with nothing between the fingers: open fully, close fully,
        and take the position counts where the fingers stopped as this unit's calibration."""
        self.start()
        self.open(self.stroke, speed=0.15)
        open_st = self._wait_motion(timeout, "calibration opening")
        self.close(FORCE_CAL, speed=0.15, width=0.0)
        closed_st = self._wait_motion(timeout, "calibration closing")
        if closed_st.obj == OBJ_STALLED_CLOSING:
            raise DeviceError(DEVICE, self.transport.address,
                              "calibration: the fingers stalled on something; empty the gripper")
        self.calibration = Calibration(open_st.po, closed_st.po, self.stroke)
        return self.calibration

    def _wait_motion(self, timeout: float, what: str) -> GripperStatus:
        def done(st: GripperStatus) -> bool:
            return not self.moving()
        return self._wait(done, timeout, what)

    def _wait_fresh(self, timeout: float) -> None:
        """Block until a fresh status arrives (faults included: check() reports them)."""
        end = time.monotonic() + timeout
        while self._fresh_status() is None:
            if time.monotonic() > end:
                raise DeviceError(DEVICE, self.transport.address,
                                  self.fault() or f"no status within {timeout} s")
            time.sleep(1.0 / self.poll_hz)

    def _wait(self, done: Callable[[GripperStatus], bool], timeout: float, what: str
              ) -> GripperStatus:
        end = time.monotonic() + timeout
        while True:
            fault = self.fault()
            st, _ = self.status()
            if st is not None and fault is None and done(st):
                return st
            if fault is not None and st is not None and st.flt and not self._activating:
                raise DeviceError(DEVICE, self.transport.address, f"{what}: {fault}")
            if time.monotonic() > end:
                reason = fault or (STA_TEXT.get(st.sta, "?") if st else "no status")
                raise DeviceError(DEVICE, self.transport.address,
                                  f"{what} not done within {timeout} s ({reason})")
            time.sleep(1.0 / self.poll_hz)

    def check(self, activate: bool = False, timeout: float = 10.0) -> CheckResult:
        """The start-up check row: activation state, fault, position, firmware.

        With ``activate`` the gripper is activated first (blocking, moves the fingers). Passes
        when a fresh status shows the gripper activated and without fault.
        """
        details: dict[str, str] = {"transport": self.transport.kind}
        try:
            if activate:
                self.activate(timeout)
            else:
                self.start()
                self._wait_fresh(min(timeout, 2.0))
        except DeviceError as exc:
            details["fault"] = self.fault() or "none"
            return CheckResult(DEVICE, self.transport.address, False, details, exc.cause)
        st, age = self.status()
        assert st is not None
        fault = self.fault()
        details.update({
            "activation": STA_TEXT.get(st.sta, str(st.sta)) + ("" if st.act else " (rACT 0)"),
            "fault": fault or "none",
            "position": f"{st.po}/255 = {self.calibration.width(st.po) * 1000:.1f} mm open",
            "request echo": str(st.pr),
            "object": str(st.obj),
            "current": f"{st.cu * 10} mA" if st.cu is not None else "not readable here",
            "speed/force settings": f"{count_speed(255) * 1000:.0f} mm/s, "
                                    f"{count_force(255):.0f} N at 255",
            "calibration": f"open {self.calibration.open_count}, "
                           f"closed {self.calibration.closed_count}",
            "status age": f"{age * 1000:.0f} ms",
            "firmware": "not readable through the documented register map",
        })
        if st.kflt:
            details["controller fault (kFLT)"] = f"0x{st.kflt:X}"
        error = None
        if fault is not None:
            error = fault
        elif not st.activated:
            error = "not activated (run with activation, or activate it from the pendant)"
        return CheckResult(DEVICE, self.transport.address, error is None, details, error)

    # --- the status thread ---------------------------------------------------------------

    def _fresh_status(self) -> GripperStatus | None:
        with self._lock:
            st, t = self._status, self._status_time
        return st if self._clock() - t <= self.stale_after else None

    def _run(self) -> None:
        period = 1.0 / self.poll_hz
        failures = 0
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                self._send_queued()
                st = self.transport.read_status()
            except DeviceError as exc:
                failures += 1
                with self._lock:
                    self._link_error = str(exc)
                self._stop.wait(min(period * 2 ** failures, ERROR_BACKOFF_CAP))
                continue
            failures = 0
            self._take(st)
            self._wake.wait(max(0.0, period - (time.monotonic() - t0)))
            self._wake.clear()

    def _send_queued(self) -> None:
        """Send what the tick queued, in order; a failed command is dropped and reported.

        A go-to waits in the queue while an activation runs or before the first status (so it
        never lands mid-activation, which the gripper would delay with fault 0x05). On a gripper
        in reset (gACT = 0) it is sent with rACT = 0: the gripper then refuses it with fault
        0x07 instead of silently starting an activation, which would sweep the fingers through
        the whole stroke.
        """
        while True:
            with self._lock:
                if not self._queue:
                    return
                item = self._queue[0]
                st = self._status
                if item != _RESET and (self._activating or st is None):
                    return
                self._queue.popleft()
                seq = self._queued
            try:
                if item == _RESET:
                    self.transport.write_request(ActionRequest(act=False))
                    with self._lock:
                        self._reset_sent = True
                else:
                    assert isinstance(item, ActionRequest)
                    if st is not None and st.act == 0:
                        item = replace(item, act=False)
                    self.transport.write_request(item)
                    with self._lock:
                        self._sent_pr, self._sent_seq = item.position, seq
            except DeviceError as exc:
                with self._lock:
                    self._command_error = f"command not delivered: {exc}"
                    self._confirmed = self._queued
                    if item == _RESET:
                        self._activating = False
                raise

    def _take(self, st: GripperStatus) -> None:
        """Keep a fresh status; finish the activation sequence; confirm the sent go-to."""
        activate_now = False
        with self._lock:
            self._status, self._status_time = st, self._clock()
            self._link_error = None
            self.polls += 1
            if self._reset_sent and st.act == 0:
                activate_now = True
            if (self._sent_pr is not None and st.gto == 1 and st.pr == self._sent_pr
                    and self._confirmed < self._sent_seq):
                self._confirmed = self._sent_seq
        if activate_now:
            try:
                self.transport.write_request(ActionRequest(act=True))
            except DeviceError as exc:
                with self._lock:
                    self._link_error = str(exc)
                return
            with self._lock:
                self._activating = self._reset_sent = False
                self._sent_pr = None


