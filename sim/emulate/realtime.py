"""The emulators' clock: one thread steps the twin at its control period in wall-clock time.

Why one thread: PyBullet's client is not thread-safe, and the emulated controller's cycle moves
the twin's arm; device servers only exchange values with it (locks around small dicts). The loop
sleeps to absolute deadlines, so a late step does not shift the ones after it, and records how
much of each period was left (the *margin*): a margin below zero is a step that overran.
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
                if margin < -10 * self.period:  # a long stall: resynchronise, no catch-up burst
                    t_next = time.monotonic()
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
        }
