"""The emulators' real-time loop: a late step slips the twin's clock, it never bursts."""

from __future__ import annotations

import threading
import time

import pytest

from sim.emulate.realtime import RealTimeLoop

PERIOD = 0.01


def test_a_step_that_overran_is_not_caught_up_in_a_burst() -> None:
    starts: list[float] = []

    def step() -> None:
        starts.append(time.monotonic())
        if len(starts) == 5:
            time.sleep(6 * PERIOD)  # one step costs six periods
        if len(starts) >= 15:
            loop.stop()

    loop = RealTimeLoop(PERIOD, step)
    thread = threading.Thread(target=loop.run)
    thread.start()
    thread.join(timeout=5.0)
    gaps = [b - a for a, b in zip(starts[5:-1], starts[6:], strict=True)]
    # Catching up would run the next five steps back to back (gaps near zero): the world would
    # move faster than the wall clock with no command from the cell between them. Counted over
    # the steps after the overrun, not gap by gap: on a loaded machine one step started late
    # shortens the gap after it (a 4.6 ms gap was seen), but a burst shortens their sum by the
    # five periods it catches up.
    assert sum(gaps) > (len(gaps) - 1) * PERIOD, [round(g * 1e3, 1) for g in gaps]
    assert sum(g < 0.5 * PERIOD for g in gaps) <= 1, [round(g * 1e3, 1) for g in gaps]
    stats = loop.margin_stats()
    assert stats["overruns"] >= 1
    assert stats["slipped_s"] >= 4 * PERIOD  # the twin's time fell behind by about the overrun
    # The step's own cost, apart from the margin: the six-period step is the longest.
    assert stats["step_max_ms"] >= 5.5 * PERIOD * 1e3 > stats["step_median_ms"]
    worst = stats["worst_overruns"][0]  # the latest step first, at its place in the twin's time
    assert worst["step_ms"] >= 5.5 * PERIOD * 1e3 and worst["late_ms"] >= 4.5 * PERIOD * 1e3
    assert worst["twin_s"] == pytest.approx(5 * PERIOD)


def test_the_stepping_thread_runs_at_its_own_niceness_and_the_report_says_so() -> None:
    import os

    seen: list[int] = []

    def step() -> None:
        seen.append(os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))
        loop.stop()

    before = os.getpriority(os.PRIO_PROCESS, 0)
    # Lowering one's own priority is always permitted, so this runs everywhere.
    loop = RealTimeLoop(PERIOD, step, niceness=min(before + 3, 19))
    thread = threading.Thread(target=loop.run)
    thread.start()
    thread.join(timeout=5.0)
    assert seen == [min(before + 3, 19)]
    assert loop.margin_stats()["priority"] == {"niceness": min(before + 3, 19), "applied": True}
    assert os.getpriority(os.PRIO_PROCESS, 0) == before  # per thread: the caller is unchanged
