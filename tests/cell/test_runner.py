"""cell/runner.py: the tick loop, the cell's state (the tree's events sink) and the JSONL tick log.

A fake backend steps the fake devices (tests/skills/fakes.py) like the world would, so a halt at
the end of a run can be checked as "the arm was told to stop". No twin, no wall-clock waits
except the one pacing test.
"""

from __future__ import annotations

import copy
import json
import os
import signal
import time

import numpy as np
import py_trees
import pytest
from py_trees.behaviour import Behaviour
from py_trees.common import Access, Status

from cell.runner import CellState, TickLog, TickLoop
from tests.trees.helpers import fresh_ctx
from trees import behaviours as lv


@pytest.fixture
def ctx():
    return fresh_ctx()


class FakeBackend:
    """Steps the context's fake devices and clock by one control step."""

    name = "fake"

    def __init__(self, ctx) -> None:  # type: ignore[no-untyped-def]
        self.dev = ctx.devices
        self.steps = 0

    @property
    def clock(self):  # type: ignore[no-untyped-def]
        return self.dev.clock

    def step(self) -> None:
        self.steps += 1
        self.dev.arm.tick()
        self.dev.gripper.tick()
        self.dev.clock.t += self.dev.clock.dt

    def close(self) -> None:
        pass

    def judge(self, kind, data):  # type: ignore[no-untyped-def]
        return None


class Scripted(Behaviour):
    """Returns ``script[i]`` on its i-th tick (the last one repeats); ``on_update`` is called
    with the tick number first."""

    def __init__(self, name: str, *script: Status, on_update=None) -> None:  # type: ignore[no-untyped-def]
        super().__init__(name)
        self.script = list(script) or [Status.RUNNING]
        self.ticks = self.setups = self.halts = 0
        self.on_update = on_update

    def setup(self, **kwargs) -> None:  # type: ignore[no-untyped-def]
        self.setups += 1

    def update(self) -> Status:
        self.ticks += 1
        if self.on_update is not None:
            self.on_update(self.ticks)
        status = self.script[min(self.ticks - 1, len(self.script) - 1)]
        self.feedback_message = f"tick {self.ticks}: {status.name}"
        return status

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self.halts += 1


def loop(root, ctx, tmp_path=None, **kwargs) -> tuple[TickLoop, CellState]:  # type: ignore[no-untyped-def]
    state = CellState()
    state_file = kwargs.pop("state_file", None)
    log = kwargs.pop("log", None) or TickLog(None)
    return (
        TickLoop(root, FakeBackend(ctx), state, log, 125.0, wrench=lambda: None,
                 state_file=state_file, **kwargs),
        state,
    )


# ------------------------------------------------------------------------------- TickLoop
def test_the_loop_ticks_until_the_root_succeeds_and_steps_the_backend_between_ticks(ctx) -> None:
    root = Scripted("root", Status.RUNNING, Status.RUNNING, Status.RUNNING, Status.SUCCESS)
    tl, state = loop(root, ctx)
    result = tl.run(max_time=10.0)
    assert result.status == "success" and result.ticks == 4 and root.ticks == 4
    assert tl.backend.steps == 3  # not after the last tick
    assert result.sim_time == pytest.approx(3 * ctx.devices.clock.dt)
    assert root.setups == 1 and root.halts == 0
    assert state.tick == 4


def test_a_failing_root_ends_the_run_with_failure(ctx) -> None:
    root = Scripted("root", Status.RUNNING, Status.FAILURE)
    result = loop(root, ctx)[0].run(max_time=10.0)
    assert result.status == "failure" and result.ticks == 2


def test_out_of_time_halts_the_running_motion_and_the_arm_stops(ctx) -> None:
    ctx.devices.arm.ticks_per_move = 10**6
    leaf = lv.GoHome("home", ctx)
    tl, _ = loop(leaf, ctx)
    result = tl.run(max_time=0.5)
    assert result.status == "out of time"
    assert result.sim_time == pytest.approx(0.5, abs=ctx.devices.clock.dt)
    assert result.ticks == pytest.approx(0.5 / ctx.devices.clock.dt, abs=1)
    assert leaf.status == Status.INVALID
    assert ctx.devices.arm.stops == 1


def test_the_loop_measures_time_from_where_the_clock_stood_when_it_started(ctx) -> None:
    ctx.devices.clock.t = 1000.0
    times: list[float] = []
    state_box: dict = {}

    def note(_: int) -> None:
        times.append(state_box["state"].time)

    root = Scripted("root", on_update=note)
    tl, state = loop(root, ctx)
    state_box["state"] = state
    result = tl.run(max_time=0.1)
    assert result.status == "out of time"
    assert times[0] == 0.0 and times[1] == pytest.approx(ctx.devices.clock.dt)
    assert result.sim_time == pytest.approx(0.1, abs=ctx.devices.clock.dt)


def test_a_signal_interrupts_the_loop_halts_the_motion_and_restores_the_handlers(ctx) -> None:
    ctx.devices.arm.ticks_per_move = 10**6
    leaf = lv.GoHome("home", ctx)
    before = signal.getsignal(signal.SIGINT)

    def on_tick(tick: int) -> None:
        if tick == 5:
            # Only ever send the signal into the loop's own handler (never the default one,
            # which would interrupt the test run).
            assert signal.getsignal(signal.SIGINT) == tl._handler
            os.kill(os.getpid(), signal.SIGINT)

    tl, _ = loop(leaf, ctx, on_tick=on_tick)
    result = tl.run(max_time=10.0)
    assert result.status == "interrupted" and result.signum == signal.SIGINT
    assert result.ticks == 5  # the tick under way finished; no further tick started
    assert leaf.status == Status.INVALID and ctx.devices.arm.stops == 1
    assert signal.getsignal(signal.SIGINT) == before


def test_an_exception_in_the_tree_still_halts_the_motion_saves_and_restores(ctx, tmp_path) -> None:
    ctx.devices.arm.ticks_per_move = 10**6
    home = lv.GoHome("home", ctx)

    def boom(tick: int) -> None:
        if tick == 3:
            raise RuntimeError("a bug in a leaf")

    root = py_trees.composites.Parallel(
        "root", policy=py_trees.common.ParallelPolicy.SuccessOnAll(),
        children=[home, Scripted("buggy", on_update=boom)],
    )
    before = signal.getsignal(signal.SIGTERM)
    state_file = tmp_path / "state.json"
    tl, _ = loop(root, ctx, state_file=state_file)
    with pytest.raises(RuntimeError):
        tl.run(max_time=10.0)
    assert ctx.devices.arm.stops == 1  # the running home move was halted
    assert signal.getsignal(signal.SIGTERM) == before
    assert json.loads(state_file.read_text())["tick"] == 3


def test_the_state_is_saved_after_every_cycle_and_at_the_end(ctx, tmp_path) -> None:
    state_file = tmp_path / "run" / "state.json"
    seen: dict[int, dict] = {}
    box: dict = {}

    def cycles(tick: int) -> None:
        if tick in (2, 4):
            box["state"].event("cycle_done", cycle=tick // 2)
        if tick == 3:
            box["state"].event("picked")

    def read(tick: int) -> None:
        seen[tick] = json.loads(state_file.read_text()) if state_file.exists() else {}

    root = Scripted("root", *[Status.RUNNING] * 5, Status.SUCCESS, on_update=cycles)
    tl, state = loop(root, ctx, state_file=state_file, on_tick=read)
    box["state"] = state
    tl.run(max_time=10.0)
    assert seen[1] == {}  # nothing to save before the first cycle ended
    assert seen[2]["counts"] == {"cycle_done": 1}
    assert seen[3]["counts"] == {"cycle_done": 1}  # a pick alone does not save
    assert seen[4]["counts"] == {"cycle_done": 2, "picked": 1}
    final = json.loads(state_file.read_text())
    assert final["tick"] == 6 and final["counts"]["cycle_done"] == 2


def test_each_tick_is_logged_with_its_new_events_and_aborts(ctx, tmp_path) -> None:
    box: dict = {}

    def report(tick: int) -> None:
        if tick == 2:
            box["state"].event("fed")
            box["state"].abort("guard tripped")

    log = TickLog(tmp_path / "ticks.jsonl")
    root = Scripted("root", Status.RUNNING, Status.RUNNING, Status.RUNNING, Status.SUCCESS,
                    on_update=report)
    tl, state = loop(root, ctx, log=log)
    box["state"] = state
    tl.run(max_time=10.0)
    log.close()
    lines = [json.loads(x) for x in (tmp_path / "ticks.jsonl").read_text().splitlines()]
    by_tick = {line["tick"]: line for line in lines[1:]}  # [0]: the header
    assert by_tick[2]["events"][0]["kind"] == "fed"
    assert by_tick[2]["aborts"][0]["reason"] == "guard tripped"
    assert 3 not in by_tick  # nothing changed on tick 3
    assert by_tick[4]["changed"] == {"root": "SUCCESS"}


def test_realtime_paces_the_ticks_at_the_control_rate(ctx) -> None:
    root = Scripted("root", *[Status.RUNNING] * 9, Status.SUCCESS)
    tl, _ = loop(root, ctx, realtime=True)
    tl.period = 0.01
    t0 = time.perf_counter()
    result = tl.run(max_time=10.0)
    assert result.status == "success"
    assert time.perf_counter() - t0 >= 9 * 0.01 * 0.9  # 9 waits between 10 ticks



def test_a_paced_loop_ticks_at_its_configured_niceness_and_says_so(ctx) -> None:
    import os
    import threading

    seen: list[int] = []
    before = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    wanted = min(before + 1, 19)  # lowering one's priority is always permitted
    root = Scripted("root", *[Status.RUNNING] * 4, Status.SUCCESS, on_update=lambda n: seen.append(
        os.getpriority(os.PRIO_PROCESS, threading.get_native_id())))
    tl, _ = loop(root, ctx, realtime=True, niceness=wanted)
    try:
        result = tl.run(max_time=10.0)
    finally:
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), before)
        except OSError:
            pass  # not root: this thread stays one step lower
    assert seen and all(n == wanted for n in seen)
    assert result.tick_period_ms is not None and result.tick_period_ms["priority"] == {
        "niceness": wanted, "applied": True}


def test_after_a_stall_the_paced_loop_skips_the_missed_periods_instead_of_bursting(ctx) -> None:
    """A tick that stalls 10 periods (a slow call, a starved host): the loop must not run the
    missed ticks back to back; it skips them, counts them and ticks on a fresh grid."""
    starts: list[float] = []

    def on_update(n: int) -> None:
        starts.append(time.monotonic())
        if n == 3:
            time.sleep(0.2)

    root = Scripted("root", *[Status.RUNNING] * 15, Status.SUCCESS, on_update=on_update)
    tl, _ = loop(root, ctx, realtime=True)
    tl.period = 0.02
    result = tl.run(max_time=10.0)
    assert result.status == "success"
    stall_end = starts[3]  # tick 4 starts right after the stall
    burst = [t for t in starts[3:] if t - stall_end <= 3 * tl.period]
    # resynchronised: tick 4 at once, then at most one tick per period (a burst would be ~10)
    assert len(burst) <= 4, [round((t - stall_end) * 1e3, 1) for t in starts[3:]]
    stats = result.tick_period_ms
    assert stats is not None and stats["skipped_periods"] >= 5
    # the stall is named: the longest tick first, with the leaf it ended on
    longest = stats["longest_ticks"]
    assert longest[0]["ms"] >= 190 and longest[0]["leaf"] == "root"
    assert all(t["ms"] < 100 for t in longest[1:])
    assert len(longest) == 5 and longest[0]["ms"] >= longest[-1]["ms"]
    assert stats["period_p99_ms"] <= stats["period_p999_ms"] <= stats["period_max_ms"]


# ------------------------------------------------------------------------------ CellState
def test_events_are_counted_recorded_with_tick_and_time_and_packing_fills_a_place() -> None:
    state = CellState()
    state.tick, state.time = 7, 1.23456
    state.event("packed", place=3)
    state.event("packed", place="3")  # not an index: counted, but no place filled
    state.event("picked", x=0.41234567, y=np.array([1.0, 2.0]), z=np.float64(0.5))
    assert state.counts == {"packed": 2, "picked": 1}
    assert state.filled == [3]
    rec = state.events[2]
    assert (rec["kind"], rec["tick"], rec["t"]) == ("picked", 7, 1.235)
    assert rec["x"] == 0.412346 and rec["y"] == [1.0, 2.0] and rec["z"] == 0.5
    json.dumps(state.to_json())  # everything recorded is plain JSON


def test_the_judges_verdict_is_recorded_beside_the_event() -> None:
    calls: list = []

    def judge(kind, data):  # type: ignore[no-untyped-def]
        calls.append((kind, data))
        return {"ok": True} if kind == "fed" else None

    state = CellState(on_event=[judge])
    state.event("fed", depth=0.02)
    state.event("picked")
    assert state.events[0]["verdict"] == {"ok": True}
    assert "verdict" not in state.events[1]
    assert calls[0][1] == {"depth": 0.02}


def test_aborts_are_recorded_and_the_first_stop_reason_is_kept() -> None:
    state = CellState()
    state.tick, state.time = 3, 0.5
    state.abort("force-torque abort")
    assert state.aborts[0]["reason"] == "force-torque abort" and state.aborts[0]["tick"] == 3
    assert state.stopped is None
    state.stop("part lost")
    state.stop("later reason")
    assert state.stopped == "part lost" and state.to_json()["stop_reason"] == "part lost"


def test_every_event_abort_and_the_stop_go_to_the_journal_once() -> None:
    class Journal:
        def __init__(self) -> None:
            self.rows: list = []

        def append(self, tick, t, kind, data) -> None:  # type: ignore[no-untyped-def]
            self.rows.append((tick, kind, data))

    journal = Journal()
    state = CellState(journal=journal)
    state.tick = 9
    state.event("packed", place=1)
    state.abort("timeout")
    state.stop("person needed")
    state.stop("again")
    assert [k for _, k, _ in journal.rows] == ["packed", "abort", "stop"]
    assert journal.rows[0] == (9, "packed", {"place": 1})
    assert journal.rows[1][2]["reason"] == "timeout"
    assert journal.rows[2][2]["reason"] == "person needed"


def test_saving_writes_whole_json_and_leaves_no_temporary_file(tmp_path) -> None:
    state = CellState(name="bushing cell")
    state.event("cycle_done", cycle=1)
    path = tmp_path / "deep" / "state.json"
    state.save(path)
    state.event("cycle_done", cycle=2)
    state.save(path)  # replaces the file
    assert json.loads(path.read_text())["counts"] == {"cycle_done": 2}
    assert [p.name for p in path.parent.iterdir()] == ["state.json"]


def test_to_json_never_copies_the_judges() -> None:
    class NoCopy:
        def __call__(self, kind, data):  # type: ignore[no-untyped-def]
            return None

        def __deepcopy__(self, memo):  # type: ignore[no-untyped-def]
            raise AssertionError("deep-copied a judge (the twin's client would disconnect)")

    state = CellState(on_event=[NoCopy()])
    state.event("picked")
    out = state.to_json()
    assert set(out) >= {"name", "counts", "filled", "aborts", "events", "stop_reason", "tick"}
    with pytest.raises(AssertionError):
        copy.deepcopy(NoCopy())


# -------------------------------------------------------------------------------- TickLog
def test_the_log_writes_a_line_only_when_something_changed(ctx, tmp_path) -> None:
    path = tmp_path / "log" / "ticks.jsonl"
    log = TickLog(path)
    root = py_trees.composites.Sequence(
        "root", memory=True, children=[Scripted("a", Status.RUNNING, Status.SUCCESS),
                                       Scripted("b", Status.RUNNING)]
    )
    writer = py_trees.blackboard.Client(name="writer")
    writer.register_key("/part/seen", access=Access.WRITE)
    writer.register_key("/ft/wrench", access=Access.WRITE)
    root.tick_once()
    log.record(1, 0.008, root, np.array([0.0, 0.0, 1.23456, 0, 0, 0]))
    log.record(2, 0.016, root, None)  # nothing changed: no line
    writer.set("/ft/wrench", np.ones(6))  # never logged as a blackboard change
    log.record(3, 0.024, root, None)
    writer.set("/part/seen", 5)
    root.tick_once()  # a succeeds, b starts
    log.record(4, 0.032, root, None)
    log.record(5, 0.040, root, None, extra={"events": [{"kind": "fed"}]})
    log.close()
    log.close()  # idempotent
    header, *lines = [json.loads(x) for x in path.read_text().splitlines()]
    assert header["header"]["format"] == 2 and header["header"]["tree"][0]["name"] == "root"
    assert [line["tick"] for line in lines] == [1, 4, 5] and log.lines == 4
    first, fourth, fifth = lines
    assert first["changed"] == {"root": "RUNNING", "a": "RUNNING", "b": "INVALID"}
    assert first["wrench"] == [0.0, 0.0, 1.235, 0.0, 0.0, 0.0]
    assert fourth["changed"] == {"a": "SUCCESS", "b": "RUNNING"}
    assert fourth["feedback_of"] == {"a": "tick 2: SUCCESS"}
    assert fourth["blackboard"] == {"/part/seen": 5}
    assert fourth["tip"] == "b"
    assert fifth["events"] == [{"kind": "fed"}] and fifth["changed"] == {}


def test_a_log_without_a_path_writes_nothing(ctx, tmp_path) -> None:
    log = TickLog(None)
    root = Scripted("root")
    root.tick_once()
    log.record(1, 0.0, root, None, extra={"events": []})
    log.flush()
    log.close()
    assert log.lines == 0 and list(tmp_path.iterdir()) == []


def test_the_log_writes_blackboard_values_a_person_can_read() -> None:
    """Numbers rounded, a part as x/y/yaw and its sizes, a pose as x/y/z/yaw; never a Python
    repr of an object's internals."""
    from enum import Enum

    from cell.runner import _summary
    from drivers.pose import Pose
    from skills.perception.bin_parts import Detection

    d = Detection(center=np.array([0.444042, 0.002249, 0.016947]), yaw=0.00461, length=0.0652,
                  outer=0.034, part="bushing", open_end=np.array([0.47, 0.0, 0.017]),
                  open_end_seen=True, confidence=0.91234, pixels=500)
    seen = _summary(d)
    assert seen["x"] == 0.444 and seen["y"] == 0.0022 and seen["yaw"] == 0.0046
    assert seen["part"] == "bushing"
    pose = _summary(Pose(np.array([0.4, 0.1, 0.3]), np.array([[0.0, -1.0, 0.0],
                                                              [1.0, 0.0, 0.0],
                                                              [0.0, 0.0, 1.0]])))
    assert pose == {"x": 0.4, "y": 0.1, "z": 0.3, "yaw": round(np.pi / 2, 4)}
    assert _summary(0.123456789) == 0.1235

    class Colour(Enum):
        RED = "red"

    assert _summary(Colour.RED) == "red"

    class Thing:
        pass

    assert _summary(Thing()) == "<Thing>"
    assert _summary(np.array([1.234567, 2.0])) == [1.2346, 2.0]
