"""Safety and recovery composed in the tree: force-torque guard, timeout, retry, cycles, stop.

These wrap leaves instead of living inside them, so an integrator sees and changes them in the
tree's YAML. The guard and the timeout check *before* the child ticks: a wrench over the limit
stops the arm in the same tick it is read, before the child commands another step.

Every one of them runs on every tick of the cell (125 Hz), so each keeps its per-tick path lean:
a blackboard key is resolved once (:class:`_BoardKey`), ``tick()`` formats no debug message
unless py_trees logs at debug level, and the walk for the most specific feedback
(:func:`_deepest_feedback`) is a plain recursion, not py_trees' nested generators.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import py_trees
from py_trees import common
from py_trees.behaviour import Behaviour
from py_trees.decorators import Decorator

from drivers.clock import Clock
from drivers.events import EventKind, StopKind
from drivers.health import DeviceError
from skills.status import Failure
from trees.context import CellContext
from trees.node_type import MOTION, Param, declare

Status = common.Status
WRENCH_KEY = "/ft/wrench"
_INFO = py_trees.logging.Level.INFO


class _BoardKey:
    """One blackboard key of one client, resolved once.

    Why: a client's ``get()``/``set()`` splits the name, checks the client's access sets and
    looks up the remapping on every call, a few microseconds each, and the sampler writes and
    every running guard reads the wrench on every tick. The key is registered with the client as
    before (access, remapping, the blackboard's metadata); while py_trees' activity stream is on,
    every read and write still goes through the client so that the stream records it.
    """

    __slots__ = ("client", "key", "_stored_as")

    def __init__(self, client: py_trees.blackboard.Client, key: str, access: common.Access) -> None:
        client.register_key(key=key, access=access)
        self.client, self.key = client, key
        name = py_trees.blackboard.Blackboard.absolute_name(client.namespace, key)
        self._stored_as: str = client.remappings[name]

    def get(self) -> Any:
        """The value; ``KeyError`` when it was never set (as the client)."""
        board = py_trees.blackboard.Blackboard
        if board.activity_stream is None:
            return board.storage[self._stored_as]
        return self.client.get(self.key)

    def exists(self) -> bool:
        board = py_trees.blackboard.Blackboard
        if board.activity_stream is None:
            return self._stored_as in board.storage
        return bool(self.client.exists(self.key))

    def set(self, value: Any) -> None:
        board = py_trees.blackboard.Blackboard
        if board.activity_stream is None:
            board.storage[self._stored_as] = value
        else:
            self.client.set(self.key, value)


class _LeanDecorator(Decorator):
    """py_trees' :class:`Decorator` with the same ``tick()`` steps, leaner.

    py_trees formats a debug message on every tick whether or not it is logged, and checks the
    new status against ``list(Status)``, which iterates the enum: together about as much as the
    rest of a pass-through's tick. Here the message is formatted only at debug level and the
    check is a type test (the same test: ``Status`` members are its only instances)."""

    def paused(self) -> bool:
        """True to skip the child this tick and stay RUNNING (only asked while RUNNING)."""
        return False

    def tick(self) -> Iterator[Behaviour]:
        running = self.status is Status.RUNNING
        if running and self.paused():
            yield self
            return
        if py_trees.logging.level < _INFO:
            self.logger.debug(f"{self.__class__.__name__}.tick()")
        if not running:
            self.initialise()
        yield from self.decorated.tick()
        new_status = _checked(self, self.update())
        if new_status is not Status.RUNNING:
            self.stop(new_status)
        self.status = new_status
        yield self


def _checked(node: Behaviour, status: Any) -> Status:
    """``status`` if it is a :class:`Status`, else INVALID with the error py_trees logs."""
    if type(status) is Status:
        return status
    node.logger.error(
        f"A behaviour returned an invalid status, setting to INVALID [{status}][{node.name}]"
    )
    return Status.INVALID


class _CheckFirst(_LeanDecorator):
    """A decorator that may end its child before ticking it (guard, timeout)."""

    def check(self) -> str | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def on_trip(self, reason: str) -> None:
        """Called once when :meth:`check` trips, after the child was stopped."""

    def hold(self) -> str | None:
        """Why the child must not start yet (it is not ticked, this stays RUNNING), or None."""
        return None

    def tick(self) -> Iterator[Behaviour]:
        if self.status is not Status.RUNNING:
            self.initialise()
        waiting = self.hold()
        if waiting is not None:
            self.status = Status.RUNNING
            self.feedback_message = waiting
            yield self
            return
        reason = self.check()
        if reason is not None:
            self.feedback_message = reason
            self.stop(Status.FAILURE)  # stops a running child: its terminate() halts the motion
            self.on_trip(reason)
            yield self
            return
        yield from self.decorated.tick()
        new_status = self.update()
        if new_status is not Status.RUNNING:
            self.stop(new_status)
        self.status = new_status
        yield self

    def update(self) -> Status:
        child = self.decorated
        self.feedback_message = child.feedback_message
        return child.status


@declare(
    "ft_guard",
    "fails the child within one tick of a wrench over the limits; stops the arm",
    "Decorator",
    {k: MOTION[k] for k in ("max_force_n", "max_torque_nm")},
)
class FTGuard(_CheckFirst):
    """Fail the child within one tick of the wrench passing ``max_force`` (N) or
    ``max_torque`` (N*m): the child is halted, the arm stopped, and the reason recorded.

    The gripper is left as it is: a part held in a hole grasp is safer held than dropped.
    """

    def __init__(
        self, name: str, child: Behaviour, ctx: CellContext, max_force: float, max_torque: float
    ) -> None:
        super().__init__(name=name, child=child)
        self.ctx, self.max_force, self.max_torque = ctx, max_force, max_torque
        self._over_since: float | None = None
        self.trip_code = Failure.FORCE_TORQUE  #: why the last trip (set by check())
        self.bb = self.attach_blackboard_client(name=name)
        self._wrench = _BoardKey(self.bb, WRENCH_KEY, common.Access.READ)

    @classmethod
    def from_spec(
        cls, name: str, child: Behaviour, ctx: CellContext, params: dict[str, Any],
        defaults: dict[str, float],
    ) -> FTGuard:
        """From a tree file's node; a limit it does not give is the safety section's."""
        force = params.get("max_force_n", defaults["max_force_n"])
        return cls(name, child, ctx, force, params.get("max_torque_nm", defaults["max_torque_nm"]))

    def _over_limits(self, raw: Any) -> tuple[float, float] | None:
        """(|F|, |T|) when the wrench is over either limit, else None. Squared magnitudes
        against squared limits, on plain floats (the same double arithmetic as numpy's scalars,
        without their per-operation cost): this runs every tick on every active guard."""
        w = np.asarray(raw, float).tolist()
        f2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
        t2 = w[3] * w[3] + w[4] * w[4] + w[5] * w[5]
        if f2 > self.max_force * self.max_force or t2 > self.max_torque * self.max_torque:
            return f2**0.5, t2**0.5
        return None

    def hold(self) -> str | None:
        """A motion does not start while the stream is lost (it waits for the link; the
        sampler stops the cell if the link stays lost past its grace), nor, for up to
        ``ctx.limits.ft_settle`` (``safety.ft_settle_s``), while the wrench reads over the
        limits: a recovery right after a spike (put back, a retry) would otherwise be failed by
        the same spike. One already running is failed by :meth:`check` instead."""
        if self.decorated.status is Status.RUNNING:
            self._over_since = None
            return None
        try:
            raw = self._wrench.get()
        except KeyError:
            return None
        if raw is None:
            return f"{self.decorated.name}: waiting for the force-torque link"
        over = self._over_limits(raw)
        if over is None:
            self._over_since = None
            return None
        now = self.ctx.devices.clock.now()
        if self._over_since is None:
            self._over_since = now
        if now - self._over_since < self.ctx.limits.ft_settle:
            return f"{self.decorated.name}: waiting for the wrench to settle (|F| {over[0]:.1f} N)"
        self._over_since = None
        return None  # still over the limits: check() fails the motion before it starts

    def check(self) -> str | None:
        try:
            raw = self._wrench.get()
        except KeyError:
            return None
        if raw is None:  # the sampler lost the stream: nothing moves unwatched
            self.trip_code = Failure.FT_LINK_LOST
            return f"{self.decorated.name}: force-torque link lost: no wrench; arm stopped"
        over = self._over_limits(raw)
        if over is not None:
            force, torque = over
            self.trip_code = Failure.FORCE_TORQUE
            return (
                f"{self.decorated.name}: force-torque abort: |F| {force:.1f} N (limit "
                f"{self.max_force:g}), |T| {torque:.2f} N*m (limit {self.max_torque:g}); "
                "arm stopped"
            )
        return None

    def on_trip(self, reason: str) -> None:
        self.ctx.devices.arm.stop()  # also when the child was not running a motion
        self.ctx.events.abort(reason, self.trip_code, leaf_name(self))


@declare(
    "timeout",
    "fails the child after a time (s, the cell's clock)",
    "Decorator",
    {"seconds": Param(float, required=True, low=0.01, high=86400)},
    btcpp_id="CellTimeout",
)
class Timeout(_CheckFirst):
    """Fail the child when it runs longer than ``seconds`` of the injected clock."""

    def __init__(self, name: str, child: Behaviour, ctx: CellContext, seconds: float) -> None:
        super().__init__(name=name, child=child)
        self.ctx, self.seconds = ctx, seconds
        self._t0 = 0.0

    @classmethod
    def from_spec(
        cls, name: str, child: Behaviour, ctx: CellContext, params: dict[str, Any],
        defaults: dict[str, float],
    ) -> Timeout:
        return cls(name, child, ctx, params["seconds"])

    @property
    def clock(self) -> Clock:
        """The injected clock (read when used: the devices arrive after the tree is built)."""
        return self.ctx.devices.clock

    def initialise(self) -> None:
        self._t0 = self.clock.now()

    def check(self) -> str | None:
        elapsed = self.ctx.devices.clock.now() - self._t0  # self.clock, without the property
        if elapsed > self.seconds:
            return f"{self.decorated.name}: timeout after {elapsed:.1f} s (limit {self.seconds:g})"
        return None

    def on_trip(self, reason: str) -> None:
        self.ctx.devices.arm.stop()
        self.ctx.events.abort(reason, Failure.TIMEOUT, leaf_name(self))


@declare(
    "retry",
    "runs the child again after a failure",
    "Decorator",
    {
        "attempts": Param(int, required=True, low=1, high=100, doc="runs in all"),
        "pause_s": Param(
            float, low=0.0, high=60.0, doc="wait before each new attempt (s); default 0"
        ),
    },
)
class Retry(_LeanDecorator):
    """Run the child again after a failure, up to ``attempts`` runs in all.

    A retry starts the child afresh on the next tick (its ``initialise()`` runs again), so a
    re-perceive inside it sees the bin as it is now. It gives up early when the cell was told to
    stop.
    """

    @classmethod
    def from_spec(
        cls, name: str, child: Behaviour, ctx: CellContext, params: dict[str, Any],
        defaults: dict[str, float],
    ) -> Retry:
        return cls(name, child, ctx, params["attempts"], params.get("pause_s", 0.0))

    def __init__(
        self, name: str, child: Behaviour, ctx: CellContext, attempts: int, pause_s: float = 0.0
    ) -> None:
        """``pause_s``: seconds (the cell's clock) to wait before each new attempt. Why: a
        retry on the next tick meets the same transient that failed the last one -- a force
        spike of a few samples re-trips the guard before the motion starts; a gripper's fault
        code lasts a second or two."""
        super().__init__(name=name, child=child)
        self.ctx, self.attempts, self.pause_s = ctx, attempts, pause_s
        self.failures = 0
        self.last_reason = ""
        self.first_reason = ""
        self._resume_at: float | None = None
        self.bb = self.attach_blackboard_client(name=name)
        self._bin_empty = _BoardKey(self.bb, "/cell/bin_empty", common.Access.READ)

    def initialise(self) -> None:
        self.failures = 0
        self._resume_at = None

    def paused(self) -> bool:
        """Pausing before the next attempt: the child is not ticked, nothing moves."""
        if self._resume_at is None:
            return False
        if self.ctx.devices.clock.now() < self._resume_at:
            return True
        self._resume_at = None
        return False

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.FAILURE:
            self.failures += 1
            self.last_reason = _deepest_feedback(self.decorated)
            if self.failures == 1:
                self.first_reason = self.last_reason
            bin_empty = self._bin_empty.exists() and self._bin_empty.get()
            if self.failures >= self.attempts or self.ctx.events.stopped or bin_empty:
                self.feedback_message = (
                    f"gave up after {self.failures} of {self.attempts} attempts: {self.last_reason}"
                )
                return Status.FAILURE
            self.feedback_message = (
                f"attempt {self.failures} of {self.attempts} failed ({self.last_reason}); retrying"
            )
            if self.pause_s > 0:
                self._resume_at = self.ctx.devices.clock.now() + self.pause_s
            return Status.RUNNING  # the child restarts (initialise()) on its next tick
        if status != Status.RUNNING:
            self.feedback_message = f"attempt {self.failures + 1} of {self.attempts}: {status.name}"
        return status


@declare(
    "stop_on_failure",
    "a failure below needs a person: stops the cell with this reason",
    "Decorator",
    {"reason": Param(str, required=True)},
)
class StopOnFailure(_LeanDecorator):
    """A failure here needs a person (a part stuck in the slot, a part dropped outside the bin):
    tell the cell to stop, with the reason."""

    def __init__(self, name: str, child: Behaviour, ctx: CellContext, reason: str) -> None:
        super().__init__(name=name, child=child)
        self.ctx, self.reason = ctx, reason

    @classmethod
    def from_spec(
        cls, name: str, child: Behaviour, ctx: CellContext, params: dict[str, Any],
        defaults: dict[str, float],
    ) -> StopOnFailure:
        return cls(name, child, ctx, params["reason"])

    def update(self) -> Status:
        status = self.decorated.status
        self.feedback_message = self.decorated.feedback_message
        if status is Status.FAILURE:
            why = f"{self.reason}: {_deepest_feedback(self.decorated)}"
            # A retry's last attempt may fail on its precondition ("the hand is empty"): the
            # person needs what went wrong first.
            for node in _failure_path(self.decorated):
                if (
                    isinstance(node, Retry)
                    and node.status == Status.FAILURE
                    and node.failures > 1
                    and node.first_reason
                    and node.first_reason not in why
                ):
                    why = f"{why} (first attempt: {node.first_reason})"
                    break
            self.feedback_message = why
            self.ctx.events.stop(why, StopKind.PERSON_NEEDED, self.reason)
        return status


class _CellDecorator(_LeanDecorator):
    """A decorator built from its child and the cell's context alone (no parameters)."""

    def __init__(self, name: str, child: Behaviour, ctx: CellContext) -> None:
        super().__init__(name=name, child=child)
        self.ctx = ctx

    @classmethod
    def from_spec(
        cls, name: str, child: Behaviour, ctx: CellContext, params: dict[str, Any],
        defaults: dict[str, float],
    ) -> _CellDecorator:
        return cls(name, child, ctx)


@declare(
    "optional",
    "a step the cycle can do without: its failure is not the cycle's (succeeds either way)",
    "Decorator",
)
class OptionalStep(_CellDecorator):
    """A step that only saves time (a look at the bin while the machine runs): when it fails
    the cycle goes on and does the work later, where it always did. Its failure still shows in
    the log and the phases, and a stop the cell was told to make still stops it."""

    def update(self) -> Status:
        status = self.decorated.status
        self.feedback_message = self.decorated.feedback_message
        if status is Status.FAILURE:
            if self.ctx.events.stopped:
                return Status.FAILURE
            self.feedback_message = f"{self.name} skipped: {_deepest_feedback(self.decorated)}"
            return Status.SUCCESS
        return status


@declare("cycles", "repeats the child until workflow.cycles or the bin is empty", "Decorator")
class Cycles(_CellDecorator):
    """Run the workflow's cycle again and again: SUCCESS when the count is reached or the bin is
    empty; FAILURE when the cell was told to stop or too many cycles in a row failed."""

    def __init__(self, name: str, child: Behaviour, ctx: CellContext) -> None:
        super().__init__(name, child, ctx)
        self.done = 0
        self.failed_in_a_row = 0
        self.bb = self.attach_blackboard_client(name=name)
        self._cycles_done = _BoardKey(self.bb, "/cell/cycles_done", common.Access.WRITE)
        self._bin_empty = _BoardKey(self.bb, "/cell/bin_empty", common.Access.READ)
        self._cycles_done.set(0)

    def initialise(self) -> None:
        self.done = self.ctx.limits.cycles_done  # a resumed cell goes on counting
        self._cycles_done.set(self.done)

    def update(self) -> Status:
        status = self.decorated.status
        limits = self.ctx.limits
        if status is Status.RUNNING:
            self.feedback_message = (
                f"cycle {self.done + 1} of {limits.cycles}: {_deepest_feedback(self.decorated)}"
            )
            return Status.RUNNING
        if status == Status.SUCCESS:
            self.done += 1
            self.failed_in_a_row = 0
            self._cycles_done.set(self.done)
            self.ctx.events.event(EventKind.CYCLE_DONE, cycle=self.done)
        else:
            self.failed_in_a_row += 1
            reason = _deepest_feedback(self.decorated)
            self.ctx.events.event(EventKind.CYCLE_FAILED, reason=reason)
            if self.ctx.events.stopped:
                self.feedback_message = f"cell stopped: {self.ctx.events.stopped}"
                return Status.FAILURE
        if self._bin_empty.exists() and self._bin_empty.get():
            self.feedback_message = f"bin empty after {self.done} cycles"
            return Status.SUCCESS
        if self.done >= limits.cycles:
            self.feedback_message = f"{self.done} cycles done"
            return Status.SUCCESS
        if self.failed_in_a_row >= limits.max_failed_cycles:
            why = f"{self.failed_in_a_row} cycles in a row failed; last: {reason}"
            self.ctx.events.stop(why, StopKind.FAILED_CYCLES)
            self.feedback_message = f"cell stopped: {why}"
            return Status.FAILURE
        return Status.RUNNING  # the child restarts afresh on its next tick


class FTSampler(Behaviour):
    """Reads the force-torque sensor once per tick for every guard (the only writer of
    ``/ft/wrench``); never ends.

    A lost stream (a dead or stale sensor) writes ``None``: every guard then fails its motion at
    once (the arm stops), so nothing moves unwatched. A link that comes back within
    ``ctx.limits.ft_link_grace`` seconds is a transient -- the retries above carry on; one lost
    longer stops the cell (the parallel above fails, halting every running leaf).

    It watches the arm's link as well: a controller that stopped answering (a pulled cable, a
    crashed control box) stops the cell at once. The retries above would only stack up one
    failed cycle after another against a dead link; the controller's watchdog has stopped the
    arm already, and the state file says why so that `cell run --resume` picks up after it."""

    def __init__(self, name: str, ctx: CellContext) -> None:
        super().__init__(name=name)
        self.ctx = ctx
        self.bb = self.attach_blackboard_client(name=name)
        self._wrench = _BoardKey(self.bb, WRENCH_KEY, common.Access.WRITE)
        self.feedback_message = f"sampling the wrench into {WRENCH_KEY}"
        self._lost_since: float | None = None

    def tick(self) -> Iterator[Behaviour]:
        """:meth:`Behaviour.tick`'s steps without its per-tick costs (see :class:`_LeanDecorator`):
        the sampler runs on every tick of the cell."""
        if py_trees.logging.level < _INFO:
            self.logger.debug(f"{self.__class__.__name__}.tick()")
        if self.status is not Status.RUNNING:
            self.initialise()
        new_status = _checked(self, self.update())
        if new_status is not Status.RUNNING:
            self.stop(new_status)
        self.status = new_status
        yield self

    def update(self) -> Status:
        try:
            wrench = self.ctx.devices.ft.wrench()
        except DeviceError as exc:
            now = self.ctx.devices.clock.now()
            why = f"force-torque sensor lost: {exc}"
            if self._lost_since is None:
                self._lost_since = now
                self.ctx.devices.arm.stop()
                self.ctx.events.abort(f"{why}; arm stopped", Failure.FT_LINK_LOST)
            self._wrench.set(None)
            lost = now - self._lost_since
            if lost >= self.ctx.limits.ft_link_grace:
                if self.ctx.limits.ft_link_grace > 0:
                    why = f"{why} (lost for {lost:.2f} s)"
                self.feedback_message = why
                self.ctx.events.stop(why, StopKind.FT_LINK_LOST)
                return Status.FAILURE
            self.feedback_message = f"{why}; waiting {lost:.2f} s so far"
            return Status.RUNNING
        if self._lost_since is not None:
            self._lost_since = None
            self.feedback_message = f"sampling the wrench into {WRENCH_KEY} (link back)"
        self._wrench.set(wrench)
        arm = self.ctx.devices.arm.status()
        if arm.link_lost:
            why = f"arm link lost: {arm.message}"
            self.ctx.devices.arm.stop()
            # Nothing reaches the arm now: what stops it is the controller's watchdog, where one
            # is armed (devices.arm.watchdog_hz), or the end of the move it was given.
            self.ctx.events.abort(f"{why}; no command reaches the arm", Failure.DEVICE_LOST)
            self.ctx.events.stop(why, StopKind.ARM_LINK_LOST)
            self.feedback_message = why
            return Status.FAILURE
        return Status.RUNNING


def leaf_name(node: Behaviour) -> str:
    """The name of the leaf under a chain of decorators (the node an abort belongs to)."""
    while isinstance(node, Decorator):
        node = node.decorated
    return node.name


def _failure_path(node: Behaviour) -> Iterator[Behaviour]:
    """``node`` and, depth-first, every node below it reached through failed children only
    (see :func:`_first_feedback`: what failed in an earlier run of a subtree is not here)."""
    yield node
    for child in node.children:
        if child.status is Status.FAILURE:
            yield from _failure_path(child)


def _deepest_feedback(node: Behaviour) -> str:
    """The most specific reason under ``node``: for a failure, the first node that failed in
    depth-first order (the leaf, or the guard that stopped it); while running, the tip."""
    wanted = Status.FAILURE if node.status is Status.FAILURE else Status.RUNNING
    return _first_feedback(node, wanted) or node.feedback_message


def _first_feedback(node: Behaviour, wanted: Status) -> str | None:
    """The feedback of the first node in ``node.iterate()`` order (children first, depth-first,
    then the node) whose status is ``wanted`` and whose feedback is not empty, or None --
    looking only below children that are ``wanted`` themselves.

    Why only there: a node keeps the status of its last run, so a subtree that ended otherwise
    may still hold old failures (an optional look that failed and was passed over, a fallback
    that did not apply in an earlier attempt); they are not why this node failed. The same
    order as ``iterate()``, as a plain recursion: ``iterate()`` resumes one generator per level
    for every node it yields, and :class:`Cycles` asks this on every tick while the cycle runs."""
    for child in node.children:
        if child.children:
            if child.status is not wanted:
                continue
            found = _first_feedback(child, wanted)
            if found is not None:
                return found
        elif child.status is wanted and child.feedback_message:  # a leaf, without a call
            return child.feedback_message
    if node.status is wanted and node.feedback_message:
        return node.feedback_message
    return None


__all__ = [
    "Cycles",
    "FTGuard",
    "FTSampler",
    "Retry",
    "StopOnFailure",
    "Timeout",
    "WRENCH_KEY",
    "py_trees",
]
