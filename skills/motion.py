"""Guarded motion: every arm or gripper motion of a skill runs under a force-torque limit and a
timeout, and is advanced one control step at a time.

A :class:`GuardedMotion` wraps one command (a callable that starts it) and a completion test.
``tick()`` never blocks: it checks the wrench and the clock, then polls. On a guard trip it stops
the arm at once and fails with the reason; the gripper keeps its state (dropping a part is rarely
the safer choice).

A tick can be long, so the motion also arms its force and torque limits on the sensor's own
:class:`drivers.limit_guard.LimitGuard` (where the sensor has one: the FT300's reader and the
twin's sensor do), which compares every sample as it arrives and stops the arm itself; the
tick then reports that trip. The check in the tick stays as the second layer.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.arm import Arm, MotionState
from drivers.clock import Clock
from drivers.devices import Devices
from drivers.ft_sensor import ForceTorqueSensor
from drivers.gripper import Gripper
from drivers.health import DeviceError
from drivers.limit_guard import LimitGuard
from skills.axes import FORCE, TORQUE
from skills.status import RUNNING, Failure, SkillInputError, Status, StepResult

#: The cell's abort limits where a configuration gives none (its ``safety`` section defaults to
#: these): |F| in N and |T| in N*m at the wrist, and the time one motion of a skill may take (s).
DEFAULT_MAX_FORCE = 80.0
#: N*m, the default torque limit at the wrist (see above)
DEFAULT_MAX_TORQUE = 8.0
#: s, the default time one motion of a skill may take (see above)
DEFAULT_MOTION_TIMEOUT = 10.0
#: N, the highest force limit a motion may be given: the FT300's measuring range (+-300 N; its
#: counts saturate at 327.67 N), above which a limit could never be seen crossed
MAX_FORCE_LIMIT = 300.0
#: N*m, the highest torque limit a motion may be given: the FT300's torque range (+-30 N*m; its
#: counts saturate at 32.767 N*m), for the same reason
MAX_TORQUE_LIMIT = 30.0
#: s the fingers must be still before a gripper motion counts as finished, where its caller gives
#: no settle of its own: the 2F-85 reports "not moving" as soon as its fingers stop, and 0.1 s
#: (a few of its status polls) lets a grip that is still building its force finish doing so
GRIPPER_SETTLE = 0.1


@dataclass(frozen=True)
class Guard:
    """Limits for one motion: force (N) and torque (N*m) magnitudes in the tool frame, time (s).

    A skill run by the tree gets its force and torque from the tree node (see
    :func:`skills.params.with_limits`); these defaults are for skills run on their own."""

    max_force: float = DEFAULT_MAX_FORCE
    max_torque: float = DEFAULT_MAX_TORQUE
    timeout: float = DEFAULT_MOTION_TIMEOUT

    # Devices.move / Devices.grip ask the guard for the motion: the bundle lives in drivers,
    # below the skills, and must not import them (drivers.devices.MotionMaker).
    def arm_motion(self, name: str, dev: Devices, command: Callable[[], None]) -> GuardedMotion:
        """:func:`arm_motion` on ``dev`` under this guard."""
        return arm_motion(name, dev.arm, dev.ft, dev.clock, self, command)

    def gripper_motion(
        self, name: str, dev: Devices, command: Callable[[], None], settle: float = GRIPPER_SETTLE
    ) -> GuardedMotion:
        """:func:`gripper_motion` on ``dev`` under this guard."""
        return gripper_motion(name, dev.gripper, dev.arm, dev.ft, dev.clock, self, command, settle)


class GuardedMotion:
    """Start ``command`` on ``start()``; succeed when ``finished()`` holds; fail on a guard."""

    def __init__(
        self,
        name: str,
        command: Callable[[], None],
        finished: Callable[[], bool],
        arm: Arm,
        ft: ForceTorqueSensor,
        clock: Clock,
        guard: Guard,
        failed: Callable[[], str | Failed | None] | None = None,
        failure: Failure = Failure.CHECK_FAILED,
    ) -> None:
        """``failed()`` gives a reason to stop (a text, code ``failure``) or a (code, text)."""
        self.name = name
        self.failure = failure
        self._command = command
        self._finished = finished
        self._failed = failed
        self.arm, self.ft, self.clock, self.guard = arm, ft, clock, guard
        self._t0: float | None = None
        self.peak_force = 0.0
        limits = getattr(ft, "limits", None)
        self._limits = limits if isinstance(limits, LimitGuard) else None
        self._token: int | None = None

    def start(self) -> None:
        self._t0 = self.clock.now()
        self.peak_force = 0.0
        if self._limits is not None:  # armed before the command: no sample goes unchecked
            self._token = self._limits.arm(self.name, self.guard.max_force, self.guard.max_torque)
        self._command()

    def _disarm(self) -> None:
        if self._limits is not None:
            self._limits.disarm(self._token)
            self._token = None

    def tick(self) -> StepResult:
        result = self._guarded_tick()
        if result.status is not Status.RUNNING:
            self._disarm()
        return result

    def _guarded_tick(self) -> StepResult:
        try:
            return self._tick()
        except (DeviceError, TimeoutError, SkillInputError) as exc:
            # A device that stopped answering (a lost link, a stale FT stream, no camera frame,
            # a frame with no valid depth): the step cannot be guarded or finished. Stop the arm
            # and say why; the tree above decides whether to retry.
            try:
                self.arm.stop()
            except DeviceError:
                pass
            code = Failure.BAD_INPUT if isinstance(exc, SkillInputError) else Failure.DEVICE_LOST
            return StepResult(Status.FAILURE, f"{self.name}: {exc}; arm stopped", code)

    def _tick(self) -> StepResult:
        if self._t0 is None:
            self.start()
        trip = self._limits.trip() if self._limits is not None else None
        if trip is not None and self._token is not None and trip.limits.token == self._token:
            self.arm.stop()  # stopped already by the trip; again in case its stop failed
            self.peak_force = max(self.peak_force, trip.force)
            return StepResult(Status.FAILURE, trip.describe(), Failure.FORCE_TORQUE)
        w = self.ft.wrench()
        force, torque = float(np.linalg.norm(w[FORCE])), float(np.linalg.norm(w[TORQUE]))
        self.peak_force = max(self.peak_force, force)
        if force > self.guard.max_force or torque > self.guard.max_torque:
            self.arm.stop()
            return StepResult(
                Status.FAILURE,
                f"{self.name}: force-torque guard: |F| = {force:.1f} N (limit "
                f"{self.guard.max_force:g}), |T| = {torque:.2f} N*m (limit "
                f"{self.guard.max_torque:g}); arm stopped",
                Failure.FORCE_TORQUE,
            )
        elapsed = self.clock.now() - (self._t0 or 0.0)
        if elapsed > self.guard.timeout:
            self.arm.stop()
            return StepResult(
                Status.FAILURE,
                f"{self.name}: timeout after {elapsed:.1f} s; arm stopped",
                Failure.TIMEOUT,
            )
        if self._failed is not None:
            reason = self._failed()
            if reason:
                self.arm.stop()
                code, text = reason if isinstance(reason, tuple) else (self.failure, reason)
                return StepResult(Status.FAILURE, f"{self.name}: {text}", code)
        if self._finished():
            return StepResult(Status.SUCCESS, f"{self.name}: done")
        return RUNNING

    def halt(self) -> None:
        """Stop what this motion started (idempotent)."""
        self._disarm()
        if self._t0 is not None:
            self.arm.stop()


#: A reason to stop with its code.
Failed = tuple[Failure, str]


def arm_failure(arm: Arm, contact: bool = False) -> Failed | None:
    """The arm's own reason to stop a motion: a fault, or a stop that no contact explains."""
    st = arm.status()
    if st.state is MotionState.FAULT:
        return Failure.ARM_FAULT, f"arm fault: {st.message}"
    if st.state is MotionState.STOPPED and not contact:
        return Failure.ARM_STOPPED, f"arm stopped: {st.message}"
    return None



def arm_motion(
    name: str,
    arm: Arm,
    ft: ForceTorqueSensor,
    clock: Clock,
    guard: Guard,
    command: Callable[[], None],
) -> GuardedMotion:
    """A guarded arm motion that finishes when the arm reports DONE and fails on FAULT/STOPPED."""

    def failed() -> Failed | None:
        return arm_failure(arm)

    return GuardedMotion(
        name, command, lambda: arm.status().state is MotionState.DONE, arm, ft, clock, guard, failed
    )


class Settled:
    """Completion test of a gripper motion: the fingers have been still for ``seconds``.

    A class, not a closure over a dict: when the fingers stopped is this motion's own state,
    cleared by :meth:`reset` each time the motion (re)starts, so a second start waits again."""

    def __init__(self, gripper: Gripper, clock: Clock, seconds: float) -> None:
        self.gripper, self.clock, self.seconds = gripper, clock, seconds
        self.since: float | None = None  #: s (clock time) the fingers were first seen still

    def reset(self) -> None:
        self.since = None

    def __call__(self) -> bool:
        if self.gripper.moving():
            self.since = None
            return False
        if self.since is None:
            self.since = self.clock.now()
        return self.clock.now() - self.since >= self.seconds


def gripper_motion(
    name: str,
    gripper: Gripper,
    arm: Arm,
    ft: ForceTorqueSensor,
    clock: Clock,
    guard: Guard,
    command: Callable[[], None],
    settle: float = GRIPPER_SETTLE,
) -> GuardedMotion:
    """A guarded gripper motion that finishes once the fingers stop moving (after ``settle`` s)."""
    settled = Settled(gripper, clock, settle)

    def failed() -> Failed | None:
        fault = gripper.fault()
        return (Failure.GRIPPER_FAULT, f"gripper fault: {fault}") if fault else None

    def command_and_reset() -> None:
        settled.reset()
        command()

    return GuardedMotion(name, command_and_reset, settled, arm, ft, clock, guard, failed)


class Sequence:
    """Run steps one after the other, one tick at a time; the first failure ends the sequence."""

    def __init__(self, name: str, steps: list[GuardedMotion]) -> None:
        self.name = name
        self.steps = steps
        self.index = 0

    def tick(self) -> StepResult:
        while self.index < len(self.steps):
            result = self.steps[self.index].tick()
            if result.status is Status.RUNNING:
                return StepResult(Status.RUNNING, f"{self.name}: {self.steps[self.index].name}")
            if result.status is Status.FAILURE:
                return result
            self.index += 1
            return StepResult(Status.RUNNING, result.message)
        return StepResult(Status.SUCCESS, f"{self.name}: done")

    def halt(self) -> None:
        if self.index < len(self.steps):
            self.steps[self.index].halt()

    @property
    def current(self) -> str:
        """Name of the step in progress (``done`` once every step succeeded)."""
        return self.steps[self.index].name if self.index < len(self.steps) else "done"

    def passed(self, name: str) -> bool:
        """Whether the step named ``name`` has succeeded (the sequence went past it).

        Skills ask by name, not by position: a step inserted before it (a test's, a variant's)
        moves it without changing what is asked."""
        return any(step.name == name for step in self.steps[: self.index])


class _Timer:
    """A hold's clock: started with the motion, done ``seconds`` after that."""

    def __init__(self, clock: Clock, seconds: float) -> None:
        self.clock, self.seconds = clock, seconds
        self.t0: float | None = None  #: s (clock time) the hold began

    def start(self) -> None:
        self.t0 = self.clock.now()

    def done(self) -> bool:
        assert self.t0 is not None, "a hold is done only once started"
        return self.clock.now() - self.t0 >= self.seconds


class Steady:
    """Completion test of a hold that lets a part come to rest: the wrist's force has stayed
    within ``band`` (N, peak to peak of its magnitude) for ``window`` s, or ``longest`` s have
    passed since the hold began.

    A part still moving against the fingers changes the load the wrist carries; one at rest, or
    one no finger touches any more, leaves it steady. So the hold lasts as long as the part
    needs, never a fixed time tuned to one part: a light part already standing clear of the
    fingers is not left waiting untouched."""

    def __init__(
        self, ft: ForceTorqueSensor, clock: Clock, band: float, window: float, longest: float
    ) -> None:
        self.ft, self.clock, self.band, self.window = ft, clock, band, window
        self._timer = _Timer(clock, longest)  #: the hold's upper bound
        self._samples: list[tuple[float, float]] = []  #: (clock time, |F|) spanning the window

    def start(self) -> None:
        self._timer.start()
        self._samples = []

    def done(self) -> bool:
        if self._timer.done():
            return True
        now = self.clock.now()
        self._samples.append((now, float(np.linalg.norm(self.ft.wrench()[FORCE]))))
        # Keep the newest reading at or before the window's start as well: the readings always
        # span the whole window, so a long tick never leaves one reading to call steady alone.
        while len(self._samples) > 1 and now - self._samples[1][0] >= self.window:
            self._samples.pop(0)
        if now - self._samples[0][0] < self.window:  # not a whole window read yet
            return False
        values = [f for _, f in self._samples]
        return max(values) - min(values) <= self.band


def wait_steady(
    name: str, dev: Devices, guard: Guard, band: float, window: float, longest: float
) -> GuardedMotion:
    """Hold still under the guard until the wrist reads steady (:class:`Steady`)."""
    steady = Steady(dev.ft, dev.clock, band, window, longest)
    return GuardedMotion(name, steady.start, steady.done, dev.arm, dev.ft, dev.clock, guard)


def wait(name: str, dev: Devices, guard: Guard, seconds: float) -> GuardedMotion:
    """Hold still for ``seconds`` under the guard (let a part settle)."""
    timer = _Timer(dev.clock, seconds)
    return GuardedMotion(name, timer.start, timer.done, dev.arm, dev.ft, dev.clock, guard)
