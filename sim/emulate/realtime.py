"""The emulators' clock: one thread steps the twin at its control period in wall-clock time.

Why one thread: PyBullet's client is not thread-safe, and the emulated controller's cycle moves
the twin's arm; device servers only exchange values with it (locks around small dicts). The loop
sleeps to absolute deadlines, so an early or on-time step does not shift the ones after it, and
records how much of each period was left (the *margin*): a margin below zero is a step that
overran.

A step that overran is not caught up: the next one starts at once and the deadlines move on from
there, so the twin's time *slips* behind the wall clock by the overrun (counted in
``slipped_s``). Catching up would run the twin's physics several periods back to back with no
command from the cell in between, a world moving faster than the wall clock, which no real cell
meets; a slip shows the driver a slower robot (the controller's timestamps follow the steps),
as a speed slider turned down would. In contact-rich phases (a finger caught in the hole, a
part pivoting on the floor) one step of the full cell costs 10-12 ms on a 2-core machine, so
some slip is expected there.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np


class RealTimeLoop:
    """Call ``step`` every ``period`` s until :meth:`stop`; :meth:`run` blocks."""

    def __init__(self, period: float, step: Callable[[], None]) -> None:
        self.period = period
        self._step = step
        self._stop = threading.Event()
        self.steps = 0
        self.overruns = 0
        self.slipped = 0.0  #: s the twin's time has fallen behind the wall clock
        self._margins: list[float] = []  # s left in each period (ring of the last 100 000)

    def stop(self) -> None:
        self._stop.set()

    def run(self) -> None:
        t_next = time.monotonic()
        while not self._stop.is_set():
            self._step()
            self.steps += 1
            t_next += self.period
            margin = t_next - time.monotonic()
            if len(self._margins) >= 100_000:
                self._margins = self._margins[50_000:]
            self._margins.append(margin)
            if margin < 0:
                self.overruns += 1
                self.slipped -= margin
                t_next -= margin  # the deadline moves to now: no catch-up burst
                continue
            self._stop.wait(margin)

    def margin_stats(self) -> dict[str, float]:
        """Margin per step (ms): median, 1st percentile, minimum; overruns counted."""
        if not self._margins:
            return {"steps": 0}
        m = np.asarray(self._margins) * 1e3
        return {
            "steps": self.steps,
            "period_ms": self.period * 1e3,
            "margin_median_ms": float(np.median(m)),
            "margin_p1_ms": float(np.percentile(m, 1)),
            "margin_min_ms": float(m.min()),
            "overruns": self.overruns,
            "slipped_s": round(self.slipped, 3),
        }
