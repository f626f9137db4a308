"""The calling thread's scheduling priority, for the loops that must keep time.

A control loop sharing a small machine with other work (the cell's tick loop beside its device
readers; the emulator beside `cell run` on a 2-core test machine) waits for a core behind
whatever else is runnable. Linux keeps a nice value per thread, so the loop's own thread can be
raised without raising the threads it shares a process with. Raising needs root or
CAP_SYS_NICE; without them the thread runs as it is and the caller reports what it got.
"""

from __future__ import annotations

import os
import threading
from typing import Any

#: the process's nice value when this module was first imported: before any loop raised its
#: thread (cell/runner.py imports it at start-up)
STARTING_NICENESS = os.getpriority(os.PRIO_PROCESS, 0)


def set_thread_niceness(niceness: int) -> dict[str, Any]:
    """Set the calling thread's nice value (0: leave it); what it got, for a report:
    ``{"niceness", "applied"}`` and ``"why"`` when it could not."""
    if niceness == 0:
        return {"niceness": os.getpriority(os.PRIO_PROCESS, 0), "applied": False}
    tid = threading.get_native_id()
    try:
        os.setpriority(os.PRIO_PROCESS, tid, niceness)
    except (OSError, AttributeError) as exc:
        return {"niceness": os.getpriority(os.PRIO_PROCESS, tid), "applied": False,
                "why": f"not permitted ({exc.__class__.__name__})"}
    return {"niceness": os.getpriority(os.PRIO_PROCESS, tid), "applied": True}


def yield_thread() -> int:
    """Put the calling thread back to the process's starting nice value if it inherited a
    raised one: work started from a raised loop (planning, perception) must not compete with
    the loop for a core. Lowering a priority is always permitted. Returns its nice value."""
    tid = threading.get_native_id()
    try:
        if os.getpriority(os.PRIO_PROCESS, tid) < STARTING_NICENESS:
            os.setpriority(os.PRIO_PROCESS, tid, STARTING_NICENESS)
        return os.getpriority(os.PRIO_PROCESS, tid)
    except (OSError, AttributeError):
        return STARTING_NICENESS
