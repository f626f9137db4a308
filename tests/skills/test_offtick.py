"""Off-tick work runs beside the tick loop, never above it."""

from __future__ import annotations

import os
import threading

import pytest

from drivers.priority import STARTING_NICENESS, set_thread_niceness
from skills.offtick import OffTick


def test_background_work_leaves_the_raised_priority_it_inherited() -> None:
    """Started from a loop raised above the process (as `cell run`'s tick loop is), the worker
    thread goes back to the process's starting nice value; inline work stays on the caller."""
    seen: dict[str, int] = {}

    def loop() -> None:
        got = set_thread_niceness(STARTING_NICENESS - 3)
        if not got["applied"]:
            seen["skip"] = 1
            return
        seen["loop"] = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        job = OffTick("w", lambda: os.getpriority(os.PRIO_PROCESS, threading.get_native_id()),
                      background=True)
        job.start()
        while not job.done():
            pass
        seen["worker"] = job.result
        inline = OffTick("i", lambda: os.getpriority(os.PRIO_PROCESS,
                                                     threading.get_native_id()),
                         background=False)
        inline.start()
        seen["inline"] = inline.result

    t = threading.Thread(target=loop)
    t.start()
    t.join()
    if "skip" in seen:
        pytest.skip("this process may not raise a thread's priority")
    assert seen["loop"] == STARTING_NICENESS - 3
    assert seen["worker"] == STARTING_NICENESS
    assert seen["inline"] == STARTING_NICENESS - 3
