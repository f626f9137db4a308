"""The force-torque limit of the running motion, checked against every sensor sample.

Why in the driver layer: the tree's guards compare the wrist wrench with their limits once a
tick, and a tick can take far longer than a sensor period (planning, a first frame); for that
long nothing would compare the force with anything. A :class:`LimitGuard` sits on the sensor's
own thread (the FT300's reader, the twin's step) and stops the arm on the first sample over a
limit, whatever the tick is doing. The motions arm it with their limits when they start and
disarm it when they end; the tree's guards stay as the second layer, and report the trip.

The newest motion's limits are the ones in force: :meth:`LimitGuard.arm` replaces what was
armed, so limits a motion's owner forgot to disarm last only until the next motion starts (and a
stop on an arm that holds still does nothing). A trip disarms, and is kept until the next
:meth:`LimitGuard.arm` so the motion that tripped can say why.
"""

from __future__ import annotations

import dataclasses
import itertools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Limits:
    """What one motion armed: its token, name and limits (N, N*m)."""

    token: int
    name: str
    max_force: float
    max_torque: float


@dataclass(frozen=True)
class Trip:
    """One trip: the limits that were armed, what the sample read and when it arrived (the
    guard's clock, s), and why the stop command failed, if it did (the tick's guard stops
    again)."""

    limits: Limits
    force: float  #: |F| of the sample, N
    torque: float  #: |T| of the sample, N*m
    sample_time: float
    stop_error: str = ""

    def describe(self) -> str:
        lim = self.limits
        return (
            f"{lim.name}: force-torque guard (at the sensor's rate): |F| = {self.force:.1f} N "
            f"(limit {lim.max_force:g}), |T| = {self.torque:.2f} N*m (limit "
            f"{lim.max_torque:g}); arm stopped"
        )


class LimitGuard:
    """Armed by motions, fed by the sensor, stopping the arm (see the module's doc).

    The arm's stop is connected by whoever assembles the devices (the sensor is opened before
    the arm); ``clock`` stamps samples that come without a time (``time.monotonic`` on
    hardware, the simulation's clock in the twin). Thread-safe: :meth:`feed` runs on the
    sensor's thread, the rest on the tick's."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._armed: Limits | None = None
        self._tokens = itertools.count(1)
        self._trip: Trip | None = None
        self._stop: Callable[[], None] | None = None

    def connect_stop(self, stop: Callable[[], None]) -> None:
        """What a trip calls: the arm's stop (it must be safe to call from another thread)."""
        self._stop = stop

    @property
    def armed(self) -> Limits | None:
        """The limits in force, or None."""
        return self._armed

    def arm(self, name: str, max_force: float, max_torque: float) -> int:
        """Arm ``name``'s limits (N, N*m) in place of any armed before; returns the token that
        disarms them. Clears an earlier trip: a motion that starts has seen it."""
        with self._lock:
            token = next(self._tokens)
            self._armed = Limits(token, name, float(max_force), float(max_torque))
            self._trip = None
            return token

    def disarm(self, token: int | None) -> None:
        """Disarm the limits ``token`` armed, if still in force (idempotent; None: nothing)."""
        with self._lock:
            if self._armed is not None and self._armed.token == token:
                self._armed = None

    def trip(self) -> Trip | None:
        """The last trip since the newest :meth:`arm`, or None."""
        with self._lock:
            return self._trip

    def feed(self, wrench: NDArray[np.float64], stamp: float | None = None) -> Trip | None:
        """Compare one bias-removed sample ``[Fx..Tz]`` with the armed limits; over either,
        disarm, keep the trip and stop the arm. Called on the sensor's thread for every
        sample; quick when nothing is armed."""
        if self._armed is None:
            return None
        w = np.asarray(wrench, float)
        force, torque = float(np.linalg.norm(w[:3])), float(np.linalg.norm(w[3:6]))
        with self._lock:
            lim = self._armed
            if lim is None or (force <= lim.max_force and torque <= lim.max_torque):
                return None
            self._armed = None
            trip = Trip(lim, force, torque, self._clock() if stamp is None else stamp)
            self._trip = trip  # kept before the stop: a motion armed meanwhile clears it
        error = "no arm connected"
        if self._stop is not None:
            try:
                self._stop()
                error = ""
            except Exception as exc:  # noqa: BLE001 -- the sensor's thread must live on
                error = f"{type(exc).__name__}: {exc}"
        if error:
            trip = dataclasses.replace(trip, stop_error=error)
            with self._lock:
                if self._trip is not None and self._trip.limits is lim:
                    self._trip = trip
        return trip


__all__ = ["LimitGuard", "Limits", "Trip"]
