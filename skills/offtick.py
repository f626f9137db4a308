"""A computation kept off the tick where time runs on while it computes.

Why: on hardware the tick loop must come round every control period -- the guards, the
watchdog and the streamed motions wait on it -- and some planning takes longer than one (the
pick planner's clearance sweeps: 250-450 ms a part). Where the clock is real time
(``Clock.realtime``: the wall clock of the hardware backend) the work runs on a worker thread
and the step stays RUNNING meanwhile. In the twin simulated time stands still during a tick, so
the work runs inline and the twin's outcomes do not depend on how fast the host is.

The work must be a pure computation: it reads what it was given and touches no device.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Generic, TypeVar

from drivers.clock import Clock
from drivers.priority import yield_thread

T = TypeVar("T")


def runs_in_real_time(clock: Clock) -> bool:
    """Whether time passes while a tick computes (the hardware's clock), not simulated time."""
    return bool(getattr(clock, "realtime", False))


class OffTick(Generic[T]):
    """``work()`` started by :meth:`start`, on a worker thread named ``name`` when
    ``background`` is True, else at once; :meth:`done` polls it from the tick and raises what
    the work raised. (skills/frames.py's camera frames run the same way.)"""

    def __init__(self, name: str, work: Callable[[], T], background: bool) -> None:
        self.name, self._work, self.background = name, work, background
        self._done = threading.Event()
        self._result: T | None = None
        self._error: BaseException | None = None

    def start(self) -> None:
        if self.background:
            threading.Thread(target=self._run_yielding, name=self.name, daemon=True).start()
        else:
            self._run()

    def _run_yielding(self) -> None:
        # Started from the tick loop's thread, it inherited the loop's raised priority: the
        # work would take a core from the loop it is meant to keep on time.
        yield_thread()
        self._run()

    def _run(self) -> None:
        try:
            self._result = self._work()
        except BaseException as exc:  # noqa: BLE001 -- handed to the tick thread, raised there
            self._error = exc
        finally:
            self._done.set()

    def done(self) -> bool:
        if not self._done.is_set():
            return False
        if self._error is not None:
            raise self._error
        return True

    @property
    def result(self) -> T:
        assert self._done.is_set() and self._error is None
        return self._result  # type: ignore[return-value]


__all__ = ["OffTick", "runs_in_real_time"]
