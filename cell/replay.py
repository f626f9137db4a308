"""`cell replay`: the timeline of a run from its JSONL tick log."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

#: Names of tree plumbing whose status changes are noise in a timeline.
_PLUMBING = ("cell", "ft sampler")


def timeline(lines: list[dict[str, Any]], every: bool = False) -> Iterator[str]:
    """One line per behaviour start/end (leaves only unless ``every``), event and abort."""
    lines = [line for line in lines if "header" not in line]  # the tree's shape, no event
    started: dict[str, float] = {}
    last_t = 0.0
    for line in lines:
        t = float(line.get("t", 0.0))
        last_t = t
        tip, feedback = line.get("tip"), line.get("feedback", "")
        for name, status in line.get("changed", {}).items():
            if name in _PLUMBING:
                continue
            is_leafish = not any(w in name for w in ("guard", "timeout")) or every
            if status == "RUNNING":
                started[name] = t
                if every or (name == tip and is_leafish):
                    yield f"{t:9.3f} s  start   {name}"
            elif status in ("SUCCESS", "FAILURE"):
                t0 = started.pop(name, None)
                took = f" after {t - t0:.2f} s" if t0 is not None else ""
                if every or is_leafish:
                    own = line.get("feedback_of", {}).get(name, feedback)
                    why = f": {own}" if status == "FAILURE" and own else ""
                    yield f"{t:9.3f} s  {status.lower():7s} {name}{took}{why}"
            elif every and status == "INVALID" and name in started:
                started.pop(name)
                yield f"{t:9.3f} s  halted  {name}"
        for e in line.get("events", []):
            verdict = e.get("verdict")
            judged = ""
            if isinstance(verdict, dict):
                judged = "  [twin: ok]" if verdict.get("ok") else f"  [twin: {verdict}]"
            extra = {k: v for k, v in e.items() if k not in ("kind", "tick", "t", "verdict")}
            more = f" {extra}" if extra else ""
            yield f"{t:9.3f} s  event   {e['kind']}{more}{judged}"
        for a in line.get("aborts", []):
            yield f"{t:9.3f} s  ABORT   {a['reason']}"
    yield f"{last_t:9.3f} s  end of log ({len(lines)} lines)"
