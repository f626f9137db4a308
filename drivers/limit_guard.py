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

import itertools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Trip:
    """One trip: which armed motion, what the sample read, when it arrived and when the stop
    command returned (both on the guard's clock, s)."""

    name: str
    force: float  #: |F| of the sample, N
    torque: float  #: |T| of the sample, N*m
    max_force: float
    max_torque: float
    sample_time: float
    stopped_time: float
    stop_error: str = ""  #: why the stop command failed, if it did (the tick's guard stops again)

    def describe(self) -> str:
        return (
            f"{self.name}: force-torque guard (at the sensor's rate): |F| = {self.force:.1f} N "
            f"(limit {self.max_force:g}), |T| = {self.torque:.2f} N*m (limit "
            f"{self.max_torque:g}); arm stopped"
        )


class LimitGuard:
    """Armed by motions, fed by the sensor, stopping the arm (see the module's doc).

    ``stop`` is the arm's stop (connected by whoever assembles the devices: the sensor is
    opened before the arm); ``clock`` stamps the trips (``time.monotonic`` on hardware, the
    simulation's clock in the twin). Thread-safe: :meth:`feed` runs on the sensor's thread,
    the rest on the tick's."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._armed: dict[int, tuple[str, float, float]] = {}
        self._tokens = itertools.count(1)
        self._trip: Trip | None = None
        self._stop: Callable[[], None] | None = None
        self.trips = 0  #: trips since start-up (diagnostics)

    def connect_stop(self, stop: Callable[[], None]) -> None:
        """What a trip calls: the arm's stop (it must be safe to call from another thread)."""
        self._stop = stop

    @property
    def connected(self) -> bool:
        return self._stop is not None

    def arm(self, name: str, max_force: float, max_torque: float) -> int:
        """Arm ``name``'s limits (N, N*m) in place of any armed before; returns the token that
        disarms them. Clears an earlier trip: a motion that starts has seen it."""
        with self._lock:
            token = next(self._tokens)
            self._armed.clear()
            self._armed[token] = (name, float(max_force), float(max_torque))
            self._trip = None
            return token

    def disarm(self, token: int | None) -> None:
        """Disarm the limits ``token`` armed, if still in force (idempotent; None: nothing)."""
        if token is None:
            return
        with self._lock:
            self._armed.pop(token, None)

    def trip(self) -> Trip | None:
        """The last trip since the newest :meth:`arm`, or None."""
        with self._lock:
            return self._trip

    def feed(self, wrench: NDArray[np.float64], stamp: float | None = None) -> Trip | None:
        """Compare one bias-removed sample ``[Fx..Tz]`` with every armed limit; on the first
        over any, disarm all, stop the arm and keep the trip. Called on the sensor's thread
        for every sample; quick when nothing is armed."""
        if not self._armed:
            return None
        w = np.asarray(wrench, float)
        force, torque = float(np.linalg.norm(w[:3])), float(np.linalg.norm(w[3:6]))
        sampled = self._clock() if stamp is None else stamp
        with self._lock:
            over = next(
                ((n, f, t) for n, f, t in self._armed.values() if force > f or torque > t),
                None,
            )
            if over is None:
                return None
            self._armed.clear()
            name, max_force, max_torque = over
            first = Trip(name, force, torque, max_force, max_torque, sampled, sampled)
            self._trip = first  # kept before the stop: a motion armed meanwhile clears it
            self.trips += 1
        error = "no arm connected"
        if self._stop is not None:
            try:
                self._stop()
                error = ""
            except Exception as exc:  # noqa: BLE001 -- the sensor's thread must live on
                error = f"{type(exc).__name__}: {exc}"
        trip = Trip(name, force, torque, max_force, max_torque, sampled, self._clock(), error)
        with self._lock:
            if self._trip is first:
                self._trip = trip
        return trip

__all__ = ["LimitGuard", "Trip"]
