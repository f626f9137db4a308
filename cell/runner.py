"""The tick loop, the cell's state and the JSONL tick log.

One tick = one control step: the tree ticks once (every running leaf advances its motion by one
step), then the backend advances (the twin steps its physics; on hardware the loop waits for the
next period of the wall clock -- the only place anything waits). The clock is injected: the
twin's simulation time or monotonic wall time, so timeouts mean the same on both.
"""

from __future__ import annotations

import enum
import gc
import heapq
import json
import os
import signal
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import py_trees
from py_trees import common
from py_trees.behaviour import Behaviour

from cell.journal import JournalKind
from cell.phases import PhaseTimes
from drivers.clock import Clock
from drivers.events import EventKind, StopKind
from drivers.health import DeviceError
from drivers.priority import set_thread_niceness
from skills.status import Failure

#: The events that end a cycle (the state file is saved on them).
CYCLE_ENDS = frozenset({EventKind.CYCLE_DONE, EventKind.CYCLE_FAILED})


class Backend(Protocol):
    name: str

    @property
    def clock(self) -> Clock: ...

    def step(self) -> None: ...

    def close(self) -> None: ...

    def judge(self, kind: str, data: dict[str, Any]) -> dict[str, Any] | None: ...


@dataclass
class CellState:
    """What the cell has done: counts, filled box places, aborts, why it stopped.

    Implements the tree's :class:`~trees.context.Events`; saved as JSON after every cycle and
    on exit (written to a temporary file and renamed, so a crash never leaves half a file).
    """

    name: str = "cell"
    counts: dict[str, int] = field(default_factory=dict)
    filled: list[int] = field(default_factory=list)
    aborts: list[dict[str, Any]] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    stop_reason: str | None = None
    stop_code: StopKind | None = None
    #: the configured reason of the node that stopped the cell (a stop_on_failure's), if any
    stop_cause: str | None = None
    tick: int = 0
    time: float = 0.0
    on_event: list[Callable[[str, dict[str, Any]], dict[str, Any] | None]] = field(
        default_factory=list, repr=False
    )
    #: The crash-safe journal (cell/journal.py); every event is committed as it happens.
    journal: Any = field(default=None, repr=False)

    def _journal(self, kind: str, data: dict[str, Any]) -> None:
        if self.journal is not None:
            self.journal.append(self.tick, self.time, kind, data)

    # -- trees.context.Events ------------------------------------------------------------
    def abort(self, reason: str, code: Failure | None = None, node: str | None = None) -> None:
        why = None if code is None else code.value
        self.aborts.append(
            {
                "reason": reason,
                "code": why,
                "node": node,
                "tick": self.tick,
                "t": round(self.time, 3),
            }
        )
        self._journal(JournalKind.ABORT, {"reason": reason, "code": why, "node": node})

    def event(self, kind: EventKind, **data: object) -> None:
        kind = EventKind(kind)
        self.counts[kind.value] = self.counts.get(kind.value, 0) + 1
        if kind is EventKind.PACKED and isinstance(data.get("place"), int):
            self.filled.append(int(data["place"]))  # type: ignore[arg-type]
        record: dict[str, Any] = {"kind": kind.value, "tick": self.tick, "t": round(self.time, 3)}
        record.update({k: _jsonable(v) for k, v in data.items()})
        for fn in self.on_event:
            verdict = fn(kind, dict(data))
            if verdict is not None:
                record["verdict"] = _jsonable(verdict)
        self.events.append(record)
        self._journal(kind, {k: v for k, v in record.items() if k not in ("kind", "tick", "t")})

    def stop(self, reason: str, code: StopKind | None = None, cause: str | None = None) -> None:
        if self.stop_reason is None:
            self.stop_reason, self.stop_code, self.stop_cause = reason, code, cause
            self._journal(JournalKind.STOP, {"reason": reason, "code": code, "cause": cause})

    @property
    def stopped(self) -> str | None:
        return self.stop_reason

    # -- persistence ------------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        # Not dataclasses.asdict: it deep-copies every field, ``on_event`` included -- and a
        # deep copy of the twin's PyBullet client disconnects the real one when it is freed.
        return {
            "name": self.name,
            "counts": dict(self.counts),
            "filled": list(self.filled),
            "aborts": _jsonable(self.aborts),
            "events": _jsonable(self.events),
            "stop_reason": self.stop_reason,
            "stop_code": self.stop_code,
            # the journal's run number (None without a journal): the state file and the
            # journal name the same run
            "run": getattr(self.journal, "run", None),
            "tick": self.tick,
            "time": round(self.time, 4),
        }

    def save(self, path: str | Path) -> None:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        tmp = p.with_suffix(p.suffix + ".tmp")
        tmp.write_text(json.dumps(self.to_json(), indent=1) + "\n", encoding="utf-8")
        os.replace(tmp, p)


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        return _jsonable(v.item())  # an np.float64 rounds as a float does
    if isinstance(v, float):
        return round(v, 6)
    if v is None or isinstance(v, bool | int | str):
        return v
    return repr(v)[:200]


class TickLog:
    """A JSONL line per tick where something changed: time, statuses that changed, the tip of
    the tree and its feedback, blackboard keys that changed, the wrench, and what the taps add
    (the events, the aborts, a camera frame's file).

    The first line is a header, ``{"header": {"format": 2, "tree": [...], ...}}``: the tree's
    shape (:func:`trees.nodes.node_table`) that `cell replay --serve` draws. The wrench is
    logged as a change too: on every line written, and on a tick where it moved more than the
    deadband (``log.wrench_deadband_n`` / ``_nm``) from the last one logged -- contact is
    logged at the full tick rate, free motion costs nothing.
    """

    SKIP_KEYS = ("/ft/wrench",)
    FORMAT = 2

    def __init__(
        self,
        path: str | Path | None,
        deadband: tuple[float, float] = (1.0, 0.1),
        meta: dict[str, Any] | None = None,
    ) -> None:
        self.path = Path(path) if path is not None else None
        self._fh = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = open(self.path, "w", encoding="utf-8")  # noqa: SIM115 -- kept for the run
        self._status: dict[str, str] = {}
        self._bb: dict[str, int] = {}
        self._wrench: np.ndarray | None = None
        self.deadband = deadband
        self.meta = dict(meta or {})
        self.header: dict[str, Any] | None = None
        #: build the lines without a file too (the live monitor folds them)
        self.keep_lines = False
        self.lines = 0
        self.phases = PhaseTimes()  #: how long each leaf ran (kept with or without a file)

    def _write(self, line: dict[str, Any]) -> None:
        if self._fh is not None:
            self._fh.write(json.dumps(line) + "\n")
            self.lines += 1
            if self.lines % 50 == 0:
                self._fh.flush()  # a crash loses at most the last few lines

    def record(
        self, tick: int, t: float, root: Behaviour, wrench: Any, extra: dict | None = None
    ) -> dict[str, Any] | None:
        """Log this tick if anything changed; the line written (None: nothing changed)."""
        if self.header is None:
            from trees.nodes import node_table

            self.header = {"format": self.FORMAT, "tree": node_table(root), **self.meta}
            self._write({"header": self.header})
        changed, why = {}, {}
        for node in root.iterate():
            s = node.status.value
            if self._status.get(node.name) != s:
                self._status[node.name] = s
                changed[node.name] = s
                if not node.children and node.parent is not root:  # not the FT sampler
                    self.phases.change(node.name, s, t)
                if s in ("FAILURE", "SUCCESS") and node.feedback_message:
                    why[node.name] = node.feedback_message
        bb_changed = {}
        storage = py_trees.blackboard.Blackboard.storage
        for key, value in storage.items():
            if key in self.SKIP_KEYS:
                continue
            ident = id(value) if not isinstance(value, bool | int | float | str) else hash(value)
            if self._bb.get(key) != ident:
                self._bb[key] = ident
                bb_changed[key] = _summary(value)
        w = None if wrench is None else np.asarray(wrench, dtype=float).ravel()
        moved = w is not None and (
            self._wrench is None
            or float(np.max(np.abs(w[:3] - self._wrench[:3]))) > self.deadband[0]
            or float(np.max(np.abs(w[3:] - self._wrench[3:]))) > self.deadband[1]
        )
        if (self._fh is None and not self.keep_lines) or (
            not changed and not bb_changed and not extra and not moved
        ):
            return None
        tip = root.tip()
        line: dict[str, Any] = {
            "tick": tick,
            "t": round(t, 4),
            "changed": changed,
            "tip": tip.name if tip is not None else None,
            "feedback": tip.feedback_message if tip is not None else "",
        }
        if why:
            line["feedback_of"] = why
        if bb_changed:
            line["blackboard"] = bb_changed
        if w is not None:
            self._wrench = w
            line["wrench"] = [round(float(x), 3) for x in w]
        if extra:
            line.update(_jsonable(extra))
        self._write(line)
        return line

    def flush(self) -> None:
        if self._fh is not None:
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def _summary(value: Any) -> Any:
    if isinstance(value, list):
        if value and all(hasattr(v, "center") and hasattr(v, "yaw") for v in value):
            return [_detection(v) for v in value]  # what the camera found: drawn on its frame
        return f"{len(value)} item(s)"
    if isinstance(value, dict) and "detection" in value:
        d = value["detection"]
        return {
            "x": round(float(d.center[0]), 4),
            "y": round(float(d.center[1]), 4),
            "yaw": round(float(d.yaw), 4),
        }
    if hasattr(value, "center") and hasattr(value, "yaw") and hasattr(value, "length"):
        return _detection(value)  # one part the camera found
    if hasattr(value, "center") and hasattr(value, "yaw") and hasattr(value, "section"):
        return {  # a pivot frame: where the part lies, and its floor
            "x": round(float(value.center[0]), 4),
            "y": round(float(value.center[1]), 4),
            "yaw": round(float(value.yaw), 4),
            "floor_z": round(float(value.floor_z), 4),
        }
    if hasattr(value, "position") and hasattr(value, "rotation"):
        r = np.asarray(value.rotation, dtype=float)
        x, y, z = (round(float(c), 4) for c in value.position)
        return {"x": x, "y": y, "z": z, "yaw": round(float(np.arctan2(r[1, 0], r[0, 0])), 4)}
    if isinstance(value, float):
        return round(value, 4)
    if isinstance(value, bool | int | str):
        return _jsonable(value)
    if isinstance(value, enum.Enum):
        return _summary(value.value)
    if isinstance(value, np.ndarray) and value.size <= 12:
        return [round(float(v), 4) for v in value.ravel()]
    # Anything else by its type's name: a repr of its internals is no reading for a person.
    return f"<{type(value).__name__}>"


def _detection(d: Any) -> dict[str, Any]:
    """A part the camera found, in the robot base frame (m, rad), small enough for every look."""
    return {
        "x": round(float(d.center[0]), 4),
        "y": round(float(d.center[1]), 4),
        "z": round(float(d.center[2]), 4),
        "yaw": round(float(d.yaw), 4),
        "length": round(float(d.length), 4),
        "outer": round(float(d.outer), 4),
        "part": d.part,
        "confidence": round(float(d.confidence), 3),
    }


LONGEST_KEPT = 5  #: the longest ticks a paced run reports


class Interrupted(Exception):
    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@dataclass
class RunResult:
    status: str  # "success" | "failure" | "interrupted" | "out of time"
    ticks: int
    sim_time: float
    wall_s: float
    signum: int | None = None
    #: paced runs (`cell run`): the wall-clock period between tick starts (ms): median, p99,
    #: max, the jitter |period - 1/control_hz| at the median, p99 and max, and the periods
    #: skipped after stalls (the loop resynchronises instead of bursting), the p99.9, and the
    #: longest tree ticks with the leaf each ended on
    tick_period_ms: dict[str, Any] | None = None


def _period_stats(starts: list[float], period: float, skipped: int = 0,
                  longest: list[tuple[float, int, str]] | None = None,
                  works: list[float] | None = None) -> dict[str, Any] | None:
    if len(starts) < 3:
        return None
    d = np.diff(np.asarray(starts)) * 1e3
    j = np.abs(d - period * 1e3)
    # Periods over twice the configured one, split by where the time went: the loop's own
    # work (tick, log, devices) took over a period, or it waited past its wake-up (for a core
    # or for the interpreter, behind the process's other threads).
    late = d > 2e3 * period
    over: dict[str, Any] = {"n": int(np.sum(late))}
    if works is not None and len(works) >= len(d):
        w = np.asarray(works[: len(d)]) * 1e3
        over["busy"] = int(np.sum(late & (w > 1e3 * period)))
        over["waited"] = over["n"] - over["busy"]
        over["work_p999_ms"] = round(float(np.percentile(w, 99.9)), 3)
    return {
        "over_2x_periods": over,
        "ticks": len(starts),
        "skipped_periods": skipped,
        "period_median_ms": round(float(np.median(d)), 3),
        "period_p99_ms": round(float(np.percentile(d, 99)), 3),
        "period_p999_ms": round(float(np.percentile(d, 99.9)), 3),
        "period_max_ms": round(float(d.max()), 3),
        # the longest tree ticks and the leaf each ended on: where a long period comes from
        "longest_ticks": [
            {"tick": n, "ms": round(1e3 * dt, 1), "leaf": leaf}
            for dt, n, leaf in sorted(longest or [], reverse=True)
        ],
        "jitter_median_ms": round(float(np.median(j)), 3),
        "jitter_p99_ms": round(float(np.percentile(j, 99)), 3),
        "jitter_max_ms": round(float(j.max()), 3),
    }


class TickLoop:
    """Ticks ``root`` at ``control_hz`` until it ends, a signal arrives, or ``max_time`` passes."""

    def __init__(
        self,
        root: Behaviour,
        backend: Backend,
        state: CellState,
        log: TickLog,
        control_hz: float,
        wrench: Callable[[], Any],
        on_tick: Callable[[int], None] | None = None,
        realtime: bool = False,
        state_file: str | Path | None = None,
        taps: Sequence[Callable[[], dict[str, Any]]] = (),
        monitor: Any = None,
        niceness: int = 0,
    ) -> None:
        """``niceness``: the tick loop's thread's nice value in paced runs (0: as it is)."""
        self.root, self.backend, self.state, self.log = root, backend, state, log
        self.niceness = niceness
        self.period = 1.0 / control_hz
        self.wrench, self.on_tick, self.realtime = wrench, on_tick, realtime
        self.state_file = state_file
        #: what else a tick logs (a camera frame's file): each gives a dict for the line
        self.taps = taps
        #: the live monitor (cell/monitor): handed each tick's wrench and line, never waits
        self.monitor = monitor
        self._signal: int | None = None

    def _handler(self, signum: int, _frame: Any) -> None:
        self._signal = signum

    def run(self, max_time: float) -> RunResult:
        wall0 = time.perf_counter()
        old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
        for s in old:
            signal.signal(s, self._handler)
        clock = self.backend.clock
        t_start = clock.now()
        tick = 0
        status = "out of time"
        starts: list[float] = []  # wall time of each tick's start (paced runs)
        works: list[float] = []  # each iteration's own time before its sleep (paced runs)
        skipped = 0  # periods skipped after stalls (paced runs)
        longest: list[tuple[float, int, str]] = []  # a min-heap of the longest tree ticks
        priority: dict[str, Any] | None = None
        try:
            self.root.setup_with_descendants()
            if self.realtime:
                # What start-up built (modules, configuration, the tree, the drivers) lives as
                # long as the run: out of the collector's sight, its full collections scan what
                # the ticks make, not 45 000 objects for 25 ms on the tick loop's thread. No
                # collection first: it would hold the interpreter for tens of ms while the
                # devices' readers already run (the FT300's stream went stale on the first tick).
                gc.freeze()
                # Threads started from here on (the off-tick planners) inherit it too.
                priority = set_thread_niceness(self.niceness)
            next_wall = time.monotonic()
            while clock.now() - t_start < max_time:
                if self._signal is not None:
                    status = "interrupted"
                    name = signal.Signals(self._signal).name
                    self.state.stop(f"interrupted by {name}", StopKind.INTERRUPTED)
                    break
                tick += 1
                if self.realtime:
                    starts.append(time.monotonic())
                self.state.tick, self.state.time = tick, clock.now() - t_start
                n_events, n_aborts = len(self.state.events), len(self.state.aborts)
                t_tick = time.monotonic()
                self.root.tick_once()
                if self.realtime:
                    spent = time.monotonic() - t_tick
                    if len(longest) < LONGEST_KEPT or spent > longest[0][0]:
                        tip = self.root.tip()
                        entry = (spent, tick, tip.name if tip is not None else "")
                        (heapq.heappush if len(longest) < LONGEST_KEPT else heapq.heapreplace)(
                            longest, entry)
                extra: dict[str, Any] = {}
                if len(self.state.events) > n_events:
                    extra["events"] = self.state.events[n_events:]
                if len(self.state.aborts) > n_aborts:
                    extra["aborts"] = self.state.aborts[n_aborts:]
                for tap in self.taps:
                    extra.update(tap())
                try:
                    wrench = self.wrench()
                except DeviceError:  # a lost sensor is the guards' business; the log has none
                    wrench = None
                line = self.log.record(tick, self.state.time, self.root, wrench, extra)
                if self.monitor is not None:
                    self.monitor.publish(tick, self.state.time, wrench, line, self.log.header)
                if (
                    "events" in extra
                    and self.state_file is not None
                    and any(e["kind"] in CYCLE_ENDS for e in extra["events"])
                ):
                    self.state.save(self.state_file)  # crash-safe: after every cycle
                if self.on_tick is not None:
                    self.on_tick(tick)
                if self.root.status != common.Status.RUNNING:
                    status = self.root.status.value.lower()
                    break
                self.backend.step()
                if self.realtime:
                    next_wall += self.period
                    now = time.monotonic()
                    delay = next_wall - now
                    works.append(now - starts[-1])
                    if delay > 0:
                        time.sleep(delay)  # the loop paces; behaviours never wait
                    elif delay <= -self.period:
                        # A stall (the host, a slow call): the missed periods are skipped and
                        # counted, and the loop restarts its grid from now. Catching up would
                        # run the missed ticks back to back, each a control step of ~0 s, and
                        # a motion's per-tick limits would mean nothing during the burst.
                        missed = int(-delay // self.period)
                        skipped += missed
                        next_wall += missed * self.period
        finally:
            if self.root.status == common.Status.RUNNING:
                # Out of time or interrupted: halt every running leaf, which stops the arm.
                self.root.stop(common.Status.INVALID)
            self.log.flush()
            if self.state_file is not None:
                self.state.save(self.state_file)
            for s, h in old.items():
                signal.signal(s, h)
        stats = (_period_stats(starts, self.period, skipped, longest, works)
                 if self.realtime else None)
        if stats is not None:
            stats["priority"] = priority
        return RunResult(
            status, tick, clock.now() - t_start, time.perf_counter() - wall0, self._signal, stats
        )


__all__ = ["Backend", "CellState", "Interrupted", "RunResult", "TickLog", "TickLoop"]
