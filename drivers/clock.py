"""Time for the control loop: simulation time in the twin, monotonic wall time on hardware."""

from __future__ import annotations

import time
from typing import Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    def now(self) -> float:
        """Seconds since an arbitrary origin; never goes backwards."""
        ...


class WallClock:
    """Monotonic wall time, for hardware."""

    #: time passes while a tick computes: long work goes off the tick (skills/offtick.py)
    realtime = True

    def now(self) -> float:
        return time.monotonic()
