"""What the monitor page shows, folded from tick-log lines: live (line by line as the cell ticks)
and in a replay (any line of a recorded run).

One fold for both on purpose: the live page and the replay of the same run show the same thing
at the same tick, because both are built from the lines the tick log writes.

Copy-on-write: :meth:`Fold.apply` never changes a dict or list a reader may hold -- it builds new
status and feedback dicts and only appends to the event and wrench lists -- so the tick thread
publishes a :class:`View` (a handful of references) and the server thread reads it without a
lock and without ever making the tick wait.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Any

#: Seconds of wrench the page plots.
WRENCH_WINDOW_S = 10.0
#: Statuses as BehaviorTree.CPP and Groot2 name them (py_trees says the same words in capitals).
STATUSES = ("RUNNING", "SUCCESS", "FAILURE", "INVALID")


@dataclass(frozen=True)
class View:
    """The page's data at one tick. Holds references only; nothing in it is mutated later."""

    tick: int
    t: float
    status: dict[str, str]
    feedback: dict[str, str]
    last: dict[str, dict[str, Any]]  #: name -> the node's last SUCCESS/FAILURE and when
    blackboard: dict[str, Any]
    events: list[dict[str, Any]]
    n_events: int
    aborts: list[dict[str, Any]]
    n_aborts: int
    frame: dict[str, Any] | None
    tip: str | None


@dataclass
class Fold:
    """The running state of a run, advanced one tick-log line at a time."""

    tick: int = 0
    t: float = 0.0
    status: dict[str, str] = field(default_factory=dict)
    feedback: dict[str, str] = field(default_factory=dict)
    last: dict[str, dict[str, Any]] = field(default_factory=dict)
    blackboard: dict[str, Any] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    aborts: list[dict[str, Any]] = field(default_factory=list)
    frame: dict[str, Any] | None = None
    tip: str | None = None

    def apply(self, line: dict[str, Any]) -> None:
        self.tick, self.t = int(line["tick"]), float(line["t"])
        changed: dict[str, str] = line.get("changed", {})
        tip, tip_feedback = line.get("tip"), line.get("feedback", "")
        self.tip = tip
        own: dict[str, str] = line.get("feedback_of", {})
        if changed or own or (tip is not None and self.feedback.get(tip) != tip_feedback):
            feedback = dict(self.feedback)
            if tip is not None and tip_feedback:
                feedback[tip] = tip_feedback
            feedback.update(own)
            self.feedback = feedback
        if changed:
            self.status = self.status | changed
            done = {
                name: {"status": s, "tick": self.tick, "t": self.t, "feedback": own.get(name, "")}
                for name, s in changed.items()
                if s in ("SUCCESS", "FAILURE")
            }
            if done:
                self.last = self.last | done
        if "blackboard" in line:
            self.blackboard = self.blackboard | line["blackboard"]
        self.events.extend(line.get("events", []))  # append only: a view holds its length
        self.aborts.extend(line.get("aborts", []))
        if "frame" in line:
            self.frame = line["frame"]

    def view(self) -> View:
        return View(
            self.tick,
            self.t,
            self.status,
            self.feedback,
            self.last,
            self.blackboard,
            self.events,
            len(self.events),
            self.aborts,
            len(self.aborts),
            self.frame,
            self.tip,
        )

    def checkpoint(self) -> Fold:
        """The fold without its events and aborts (a replay keeps those once, by line): the
        dicts are shared, which is safe as they are never mutated."""
        return Fold(
            self.tick,
            self.t,
            self.status,
            self.feedback,
            self.last,
            self.blackboard,
            [],
            [],
            self.frame,
            self.tip,
        )


class WrenchTrace:
    """Wrench samples (t, [fx, fy, fz, tx, ty, tz]); append-only so a reader's slice is stable."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.w: list[list[float]] = []

    def add(self, t: float, w: Any) -> None:
        self.w.append([round(float(x), 3) for x in w])
        self.t.append(round(float(t), 4))  # appended last: a reader sees t only with its w

    def window(self, t_end: float, seconds: float = WRENCH_WINDOW_S, n: int | None = None) -> Any:
        n = len(self.t) if n is None else n
        hi = bisect.bisect_right(self.t, t_end, 0, n)
        lo = bisect.bisect_left(self.t, t_end - seconds, 0, hi)
        return {"t": self.t[lo:hi], "w": self.w[lo:hi]}


def tree_json(header: dict[str, Any], view: View) -> dict[str, Any]:
    """``GET /api/tree``: every node with its status and feedback (ids as in the header)."""
    nodes = []
    for row in header["tree"]:
        name = row["name"]
        node = {
            "id": row["id"],
            "name": name,
            "type": row["type"],
            "status": view.status.get(name, "INVALID"),
            "feedback": view.feedback.get(name, ""),
            "children": row["children"],
        }
        if "limits" in row:
            node["limits"] = row["limits"]
        if name in view.last:
            node["last"] = view.last[name]
        nodes.append(node)
    return {"tick": view.tick, "t": round(view.t, 4), "tip": view.tip, "nodes": nodes}


def events_json(view: View) -> list[dict[str, Any]]:
    """``GET /api/events``: the workflow events so far (with the twin's verdicts in simulation)
    and the aborts (``"kind": "abort"``), in the order they happened."""
    merged = list(view.events[: view.n_events])
    merged += [{"kind": "abort", **a} for a in view.aborts[: view.n_aborts]]
    merged.sort(key=lambda e: (e.get("tick", 0), e.get("kind") == "abort"))
    return merged


def active_limits(header: dict[str, Any], view: View) -> dict[str, Any]:
    """The FT limits in force now: the innermost running guard's, else the safety section's."""
    active = None
    for row in header["tree"]:  # pre-order: a later running guard is deeper
        if row["type"] == "ft_guard" and view.status.get(row["name"]) == "RUNNING":
            active = row
    if active is not None:
        return {**active["limits"], "node": active["name"]}
    safety = header.get("safety", {})
    return {
        "force_n": safety.get("max_force_n"),
        "torque_nm": safety.get("max_torque_nm"),
        "node": None,
    }


def counts(view: View) -> dict[str, int]:
    out: dict[str, int] = {}
    for e in view.events[: view.n_events]:
        out[e["kind"]] = out.get(e["kind"], 0) + 1
    out["aborts"] = view.n_aborts
    return out


def project_detections(frame: dict[str, Any], detections: Any) -> list[dict[str, Any]]:
    """Each detection's outline (its axis and its outer size, a rectangle on the floor) in the
    frame's pixels, from the camera's intrinsics and pose at the capture (OpenCV optical frame:
    x right, y down, z forward)."""
    if not isinstance(detections, list) or not frame or "K" not in frame or "pose" not in frame:
        return []
    fx, fy, cx, cy = frame["K"][:4]
    pose = frame["pose"]
    rot = [row[:3] for row in pose[:3]]
    pos = [row[3] for row in pose[:3]]

    def pixel(p: list[float]) -> list[float] | None:
        d = [p[i] - pos[i] for i in range(3)]
        c = [sum(rot[r][k] * d[r] for r in range(3)) for k in range(3)]  # R^T (p - t)
        if c[2] <= 1e-6:
            return None
        return [round(fx * c[0] / c[2] + cx, 1), round(fy * c[1] / c[2] + cy, 1)]

    out = []
    for d in detections:
        if not isinstance(d, dict) or "x" not in d:
            continue
        ux, uy = math.cos(d["yaw"]), math.sin(d["yaw"])
        hl, hw = 0.5 * d.get("length", 0.0), 0.5 * d.get("outer", 0.0)
        z = d.get("z", 0.0)
        corners = [
            [d["x"] + sl * hl * ux - sw * hw * uy, d["y"] + sl * hl * uy + sw * hw * ux, z]
            for sl, sw in ((1, 1), (1, -1), (-1, -1), (-1, 1))
        ]
        pixels = [pixel(c) for c in corners]
        if any(p is None for p in pixels):
            continue
        label = f"{d.get('part') or '?'} {d.get('confidence', 0):.2f}"
        out.append({"outline": pixels, "label": label})
    return out


class RunModel:
    """A recorded run: its header, its lines, and a checkpoint every ``every`` lines, so the
    state at any line is one checkpoint plus at most ``every`` folds. Events, aborts and wrench
    samples are kept once, with the line each came on."""

    def __init__(self, header: dict[str, Any], lines: list[dict[str, Any]], every: int = 200):
        self.header, self.lines, self.every = header, lines, every
        self.checkpoints: list[Fold] = []
        self.wrench = WrenchTrace()
        self.events: list[dict[str, Any]] = []
        self.event_line: list[int] = []
        self.aborts: list[dict[str, Any]] = []
        self.abort_line: list[int] = []
        self.first_failure: int | None = None
        self.first_abort: int | None = None
        self.first_failed_cycle: int | None = None
        leaves = {r["name"] for r in header["tree"] if not r["children"]}
        fold = Fold()
        for i, line in enumerate(lines):
            if i % every == 0:
                self.checkpoints.append(fold.checkpoint())
            fold.apply(line)
            fold.events.clear()
            fold.aborts.clear()
            if "wrench" in line:
                self.wrench.add(line["t"], line["wrench"])
            for e in line.get("events", []):
                self.events.append(e)
                self.event_line.append(i)
                if self.first_failed_cycle is None and e.get("kind") == "cycle_failed":
                    self.first_failed_cycle = i
            for a in line.get("aborts", []):
                self.aborts.append(a)
                self.abort_line.append(i)
            if self.first_abort is None and line.get("aborts"):
                self.first_abort = i
            if self.first_failure is None and any(
                s == "FAILURE" and n in leaves for n, s in line.get("changed", {}).items()
            ):
                self.first_failure = i

    def view_at(self, index: int) -> View:
        """The page's data just after line ``index`` (clamped to the run)."""
        index = max(0, min(index, len(self.lines) - 1))
        start = (index // self.every) * self.every
        fold = self.checkpoints[index // self.every].checkpoint()
        for line in self.lines[start : index + 1]:
            fold.apply(line)
        return View(
            fold.tick,
            fold.t,
            fold.status,
            fold.feedback,
            fold.last,
            fold.blackboard,
            self.events,
            bisect.bisect_right(self.event_line, index),
            self.aborts,
            bisect.bisect_right(self.abort_line, index),
            fold.frame,
            fold.tip,
        )

    def marks(self) -> dict[str, int | None]:
        """Lines to jump to: the first leaf that failed, the first abort, the first failed
        cycle."""
        return {
            "first_failure": self.first_failure,
            "first_abort": self.first_abort,
            "first_failed_cycle": self.first_failed_cycle,
        }


__all__ = [
    "STATUSES",
    "Fold",
    "RunModel",
    "View",
    "WrenchTrace",
    "active_limits",
    "counts",
    "events_json",
    "project_detections",
    "tree_json",
]
