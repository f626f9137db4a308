"""Contact by force: the wrist's reading in the base frame and the force-mode push that ends on
a measured contact. Packing, slot feeding and the pivot's Grasp (feeling for S) share them; they
sit apart from those skills so that each imports them without importing the others."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.devices import Devices
from drivers.pose import Pose
from skills.axes import DIM, FORCE, WRENCH_DIM
from skills.motion import Failed, Guard, GuardedMotion, arm_failure

__all__ = [
    "CONTACT_RATIO", "FORCE_SETTLE", "STILL_SPEED", "ForcePush", "nothing_pressed", "world_force",
]

# The contact test of a push whose caller gives none of its own: the values the packing pushes
# were measured with (their contact_settle_s and still_speed_m_s defaults).
#: s the TCP must stand still, pressing, before the contact counts: many arm state samples, so
#: one still sample between two steps of a stick-slip is not taken for a contact
FORCE_SETTLE = 0.15
#: m/s below which the TCP counts as standing still: a push still closing a gap moves at its
#: commanded speed (about 0.01 m/s), one pressed against a neighbour only creeps
STILL_SPEED = 0.002
#: share of the commanded force that must press back before the contact counts: short of 1
#: because the force mode settles a little under its target against a stiff neighbour
CONTACT_RATIO = 0.7


def world_force(dev: Devices) -> NDArray[np.float64]:
    """The force (N) the environment applies to the tool, in the base frame."""
    return dev.arm.tool_pose().rotation @ np.asarray(dev.ft.wrench()[FORCE], float)


def nothing_pressed(
    dev: Devices, reference: Callable[[], ArrayLike | None] | None
) -> NDArray[np.float64]:
    """The force on the tool (N, base frame) a contact is measured from: ``reference()``
    where it is given and gives one, else the reading now."""
    given = None if reference is None else reference()
    return world_force(dev) if given is None else np.asarray(given, float)


class ForcePush:
    """A push by hybrid force-position control: the arm's force mode presses ``force`` (N) along
    ``direction`` (a base-frame axis, e.g. ``(1, 0, 0)``) at most ``speed`` (m/s) and holds
    position on every other axis but the ``free`` ones, where it presses nothing and gives way to
    what pushes it; it ends on the *measured* contact -- the TCP has stood still
    (slower than ``still_speed``) for ``settle`` s while the force against it is at least
    ``contact_ratio`` of ``force`` -- or, having gone ``reach`` m with nothing felt, without one.

    This is how the paper packs (Sec. IV-C: -z, +x, +y until contact): the force, not a
    position, decides where the part ends, so a part a millimetre off its nominal place still
    ends pressed against its neighbour with the configured force instead of at a guessed
    target. The commanded force is added to the one read at the start (the held part's weight
    and the sensor's offset), so only the environment's reaction counts.

    A ``free`` axis is for a push into a round neighbour met off its centre line: held there, the
    pushed part shoves the neighbour sideways along the contact's slope; free, the pushed part
    itself gives way along that axis. ``lean`` (N, base frame, on free axes only) presses the
    part along a free axis as it goes: a part pushed along a row leans on the wall beside it, so
    it meets its neighbour on their centre line and pushes it along the row, not off the wall.
    """

    def __init__(
        self,
        name: str,
        dev: Devices,
        guard: Guard,
        direction: ArrayLike,
        force: float,
        speed: float,
        reach: Callable[[], float] | float,
        settle: float = FORCE_SETTLE,
        still_speed: float = STILL_SPEED,
        contact_ratio: float = CONTACT_RATIO,
        free: tuple[int, ...] = (),
        lean: ArrayLike = (0.0, 0.0, 0.0),
        reference: Callable[[], ArrayLike | None] | None = None,
        free_speed: float | None = None,
    ) -> None:
        """``free``: base axes (0 x, 1 y, 2 z) besides the push's that give way (at ``free_speed``);
        ``lean``: the force (N) pressed along them. ``reference``: the force on the tool (N,
        base frame) that counts as nothing pressed, read when the push begins (default, or when
        it gives None: the reading then). A push that begins in a contact it must let go of
        needs one read before it: measured from its own start, the free axes would keep
        pressing what they pressed then. ``free_speed``: the free axes' speed limit (m/s;
        default ``speed``): what they may drift at under an offset the reference misses."""
        d = np.asarray(direction, float)
        axis = int(np.argmax(np.abs(d)))
        if np.count_nonzero(d) != 1:
            raise ValueError(f"a force push runs along one base axis, got {direction}")
        self.dev, self.axis, self.sign = dev, axis, float(np.sign(d[axis]))
        if axis in free or any(a not in range(DIM) for a in free):
            raise ValueError(f"free axes must be other base axes than the push's, got {free}")
        self.free = tuple(free)
        self.lean = np.asarray(lean, float)
        if self.lean.shape != (DIM,) or any(
            self.lean[a] != 0.0 for a in range(DIM) if a not in self.free
        ):
            raise ValueError(f"a push leans only along its free axes, got {lean} with {free}")
        self.force, self.speed, self.settle = force, speed, settle
        self.still_speed, self.contact_ratio = still_speed, contact_ratio
        self._reach = reach if callable(reach) else (lambda r=float(reach): r)
        self._reference = reference
        self.free_speed = speed if free_speed is None else free_speed
        self.contact = False
        self.contact_pose: Pose | None = None
        self.resisting = 0.0  #: N, the newest force against the push (above the reference)
        self.travelled = 0.0  #: m along the push since it began
        self._ref = np.zeros(3)
        self._start_pos = np.zeros(3)
        self._last: tuple[float, float] | None = None  #: (time, position along the push)
        self._still_since: float | None = None
        self._limit = 0.0
        self.motion = GuardedMotion(
            name, self._start, self._finished, dev.arm, dev.ft, dev.clock, guard, self._failed
        )

    def _start(self) -> None:
        arm = self.dev.arm
        self._ref = nothing_pressed(self.dev, self._reference)
        self._start_pos = arm.tool_pose().position.copy()
        self._limit = float(self._reach())
        self.contact, self.contact_pose, self.travelled = False, None, 0.0
        self._last, self._still_since = None, None
        selection = [False] * WRENCH_DIM
        selection[self.axis] = True
        wrench = [0.0] * WRENCH_DIM
        # The wrench the tool applies is minus the force on it: reference plus the push.
        wrench[self.axis] = float(-self._ref[self.axis]) + self.sign * self.force
        limits = [0.0] * WRENCH_DIM
        limits[self.axis] = self.speed
        for axis in self.free:
            # Nothing pressed beyond what was read at the start but the lean: a contact, or the
            # lean until one, moves it.
            selection[axis] = True
            wrench[axis] = float(-self._ref[axis] + self.lean[axis])
            limits[axis] = self.free_speed
        arm.force_mode(selection, wrench, limits)

    def _finished(self) -> bool:
        arm, now = self.dev.arm, self.dev.clock.now()
        here = float(arm.tool_pose().position[self.axis])
        self.travelled = self.sign * (here - float(self._start_pos[self.axis]))
        self.resisting = -self.sign * float(world_force(self.dev)[self.axis] - self._ref[self.axis])
        speed = None
        if self._last is not None and now > self._last[0]:
            speed = abs(here - self._last[1]) / (now - self._last[0])
        self._last = (now, here)
        if self.travelled > self._limit:
            arm.stop()
            return True
        pressing = self.resisting >= self.contact_ratio * self.force
        if speed is not None and speed < self.still_speed and pressing:
            if self._still_since is None:
                self._still_since = now
            if now - self._still_since >= self.settle:
                arm.stop()
                self.contact, self.contact_pose = True, arm.tool_pose()
                return True
        else:
            self._still_since = None
        return False

    def _failed(self) -> Failed | None:
        return arm_failure(self.dev.arm)
