"""Streamed paths with force-limited give: the hybrid force-position control the pivot needs.

A :class:`CompliantPath` follows a path ``s -> Pose`` (``s`` in [0, 1]) one control step at a
time through ``Arm.servo`` and adds an *admittance* offset in the tool frame: on the selected
axes the TCP moves in the direction of the force the part applies to it, at ``gain`` metres per
second per newton above ``deadband``, up to ``limit`` metres from the path. Below the dead band
it creeps back towards the path. This is what a UR's force mode does with a zero wrench on those
axes; streaming keeps the path shape (an arc, a turn about a rim) exact on the other axes.

The wrench is the sensor's: the force *on* the tool in the tool frame (pressing the fingers onto
a part reads as ``-z``). Position control alone, with rigid fingers and a part a few millimetres
off its nominal place, squeezes the part until the force-torque guard trips.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.arm import MotionState
from drivers.devices import Devices
from drivers.pose import Pose
from skills.axes import FORCE
from skills.motion import Guard, GuardedMotion

#: m (or rad), the shortest path length the progress divides by: a path of zero length (already
#: at its end) then completes in one step instead of dividing by zero; far below any real motion
MIN_LENGTH = 1e-9


@dataclass(frozen=True)
class Compliance:
    """Give on tool-frame translation axes: ``axes`` a 3-tuple of bools (x, y, z)."""

    axes: tuple[bool, bool, bool] = (False, False, True)
    deadband: float = 8.0  #: N of contact force that is taken without giving way
    gain: float = 0.002  #: m/s per N above the dead band
    limit: float = 0.006  #: m, the largest offset from the path
    recover: float = 0.002  #: m/s back towards the path when the force is below the dead band


class CompliantPath:
    """Build with a path and a duration; ``motion()`` gives the guarded, tickable motion."""

    def __init__(
        self,
        name: str,
        dev: Devices,
        guard: Guard,
        path: Callable[[], Callable[[float], Pose]],
        length: Callable[[Callable[[float], Pose]], float],
        speed: float | Callable[[float], float],
        acceleration: float,
        compliance: Compliance,
        stop_when: Callable[[], bool] | None = None,
    ) -> None:
        """``path()`` is called when the motion starts (so it can use the measured pose) and
        returns ``s -> Pose``; ``length(path)`` its length in the units of ``speed`` (m, or
        rad for a pure turn, then ``speed`` is rad/s). ``speed`` may be a function of that
        length, read at the start: a path whose size is known only then (the Tilt's radius)
        gets its speed from it. ``stop_when`` ends it early."""
        self.name, self.dev, self.compliance = name, dev, compliance
        self.offset = np.zeros(3)  #: m, tool frame, current give
        self.peak_force = 0.0  #: N, largest force on the compliant axes
        self.progress = 0.0  #: s in [0, 1]
        self.stopped_early = False
        self._path_factory, self._length = path, length
        self._speed_of = speed if callable(speed) else (lambda _length: float(speed))
        #: the cruise speed of the current run (units of the path's length per s)
        self.speed = 0.0
        self._acc, self._stop_when = acceleration, stop_when
        self._pose_at: Callable[[float], Pose] | None = None
        self._t = 0.0
        self._v = 0.0
        self._total = 1.0
        self._mask = np.array(compliance.axes, bool)
        self.guarded = GuardedMotion(
            name, self._start, self._advance, dev.arm, dev.ft, dev.clock, guard, self._failed
        )

    def _start(self) -> None:
        self._pose_at = self._path_factory()
        self._total = max(MIN_LENGTH, float(self._length(self._pose_at)))
        self.speed = float(self._speed_of(self._total))
        self._t = self.dev.clock.now()
        self._v = 0.0
        self.progress = 0.0
        self.offset = np.zeros(3)

    def _failed(self) -> str | None:
        st = self.dev.arm.status()
        if st.state is MotionState.FAULT:
            return f"arm fault: {st.message}"
        return None

    def _advance(self) -> bool:
        assert self._pose_at is not None
        arm, c = self.dev.arm, self.compliance
        now = self.dev.clock.now()
        dt = max(0.0, now - self._t)
        self._t = now
        if self._stop_when is not None and self._stop_when():
            self.stopped_early = True
            arm.stop()
            return True
        if self.progress >= 1.0:
            arm.stop()
            return True
        # Trapezoid in path length: accelerate, cruise, decelerate to reach s = 1 at rest.
        remaining = (1.0 - self.progress) * self._total
        v_brake = float(np.sqrt(2.0 * self._acc * remaining))  # exact: v^2 = 2 a d at constant a
        self._v = min(self.speed, self._v + self._acc * dt, max(v_brake, self._acc * dt))
        self.progress = min(1.0, self.progress + self._v * dt / self._total)
        force = np.asarray(self.dev.ft.wrench()[FORCE], float) * self._mask
        magnitude = float(np.linalg.norm(force))
        self.peak_force = max(self.peak_force, magnitude)
        if magnitude > c.deadband:
            self.offset += c.gain * (magnitude - c.deadband) * (force / magnitude) * dt
        else:
            norm = float(np.linalg.norm(self.offset))
            if norm > 0.0:
                self.offset *= max(0.0, norm - c.recover * dt) / norm
        norm = float(np.linalg.norm(self.offset))
        if norm > c.limit:
            self.offset *= c.limit / norm
        target = self._pose_at(self.progress)
        arm.servo(Pose(target.position + target.rotation @ self.offset, target.rotation))
        return False

    def motion(self) -> GuardedMotion:
        return self.guarded
