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

The stepping thread asks the kernel for a higher priority than the cell's processes (a UR
controller runs its cycle in real time, on its own computer): on a 2-core machine shared with
`cell run` and the camera's renderer, a step otherwise waits for a core behind them. Where the
process may not raise it (no root, no CAP_SYS_NICE), it runs as it is and the report says so.
"""

from __future__ import annotations

import heapq
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from drivers.priority import set_thread_niceness

#: How many of the latest-ending steps the report lists.
WORST_KEPT = 5


class RealTimeLoop:
    """Call ``step`` every ``period`` s until :meth:`stop`; :meth:`run` blocks.

    ``niceness``: the stepping thread's nice value (lower runs first; 0 leaves it as is).
    """

    def __init__(self, period: float, step: Callable[[], None], niceness: int = 0) -> None:
        self.period = period
        self._step = step
        self._niceness = niceness
        self.priority: dict[str, Any] = {}
        self._stop = threading.Event()
        self.steps = 0
        self.overruns = 0
        self.slipped = 0.0  #: s the twin's time has fallen behind the wall clock
        self._margins: list[float] = []  # s left in each period (ring of the last 100 000)
        self._costs: list[float] = []  # s each step itself took (same ring)
        self._worst: list[tuple[float, int, float]] = []  # min-heap: (-lateness, step, cost)

    def stop(self) -> None:
        self._stop.set()

    def run(self) -> None:
        self.priority = set_thread_niceness(self._niceness)
        t_next = time.monotonic()
        while not self._stop.is_set():
            t_start = time.monotonic()
            self._step()
            self.steps += 1
            t_next += self.period
            t_end = time.monotonic()
            margin = t_next - t_end
            if len(self._margins) >= 100_000:
                self._margins = self._margins[50_000:]
                self._costs = self._costs[50_000:]
            self._margins.append(margin)
            self._costs.append(t_end - t_start)
            if margin < 0:
                entry = (-margin, self.steps, t_end - t_start)
                if len(self._worst) < WORST_KEPT:
                    heapq.heappush(self._worst, entry)
                elif entry > self._worst[0]:
                    heapq.heapreplace(self._worst, entry)
                self.overruns += 1
                self.slipped -= margin
                t_next -= margin  # the deadline moves to now: no catch-up burst
                continue
            self._stop.wait(margin)

    def margin_stats(self) -> dict[str, Any]:
        """Margin per step (ms): median, 1st percentile, minimum; overruns counted; and the
        step's own cost (ms; median, p99, max), which tells a world that costs more than its
        period from a step kept waiting for a core."""
        if not self._margins:
            return {"steps": 0, "priority": self.priority}
        m = np.asarray(self._margins) * 1e3
        c = np.asarray(self._costs) * 1e3
        return {
            "steps": self.steps,
            "period_ms": self.period * 1e3,
            "margin_median_ms": float(np.median(m)),
            "margin_p1_ms": float(np.percentile(m, 1)),
            "margin_min_ms": float(m.min()),
            "step_median_ms": float(np.median(c)),
            "step_p99_ms": float(np.percentile(c, 99)),
            "step_max_ms": float(c.max()),
            "overruns": self.overruns,
            "slipped_s": round(self.slipped, 3),
            "priority": self.priority,
            # Where they were: the twin's time of each (its clock advances a period a step).
            "worst_overruns": [
                {"twin_s": round(step * self.period, 3), "late_ms": round(1e3 * late, 1),
                 "step_ms": round(1e3 * cost, 1)}
                for late, step, cost in sorted(self._worst, reverse=True)
            ],
        }
