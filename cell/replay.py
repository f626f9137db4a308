"""`cell replay`: the timeline of a run from its JSONL tick log.

A crash (a killed process, a lost power supply) can leave the log's last line cut off: the log is
written a line at a time and flushed every few lines. That log is still the best record of what
happened, so it replays up to the cut with a warning; anything else that is not a tick log --
another JSON file, a line that is not an object, binary data -- is refused naming the file and
the line.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cell.errors import UserError


@dataclass
class TickLogText:
    """The lines of a tick log, and a warning when its last line was cut off."""

    lines: list[dict[str, Any]]
    warning: str | None = None


def _kind(value: Any) -> str:
    return {list: "a JSON array", str: "a JSON string", bool: "a JSON boolean"}.get(
        type(value), "a JSON number" if isinstance(value, int | float) else "JSON null"
    )


def read_tick_log(path: Path) -> TickLogText:
    """The parsed lines of the tick log at ``path``; :class:`UserError` naming the file and the
    line when it is not one."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise UserError(f"{path}: cannot read the tick log: {exc.strerror}") from None
    nul = raw.find(b"\0")
    if nul >= 0:
        raise UserError(f"{path}: not a tick log: binary data (byte {nul})")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"{path}: not a tick log: not UTF-8 text (byte {exc.start})") from None
    rows = text.splitlines()
    last = max((n for n, r in enumerate(rows, start=1) if r.strip()), default=0)
    lines: list[dict[str, Any]] = []
    warning = None
    for n, row in enumerate(rows, start=1):
        if not row.strip():
            continue
        try:
            value = json.loads(row)
        except json.JSONDecodeError as exc:
            if n == last and lines and not text.endswith("\n"):
                warning = (
                    f"{path}:{n}: the last line is cut off (the run ended abruptly); "
                    f"replaying the {len(lines)} complete lines before it"
                )
                break
            where = f"{path}:{n}"
            raise UserError(f"{where}: not a JSON line: {exc.msg} (column {exc.colno})") from None
        if not isinstance(value, dict):
            raise UserError(
                f"{path}:{n}: not a tick log: {_kind(value)}, expected an object with a 'tick'"
            )
        if "header" in value and n == 1:  # the tree's shape (format 2 on): kept for the timeline
            lines.append(value)
            continue
        if not isinstance(value.get("tick"), int):
            keys = ", ".join(list(value)[:6]) or "none"
            raise UserError(
                f"{path}:{n}: not a tick log: the object has no integer 'tick' (its keys: {keys})"
            )
        lines.append(value)
    if not lines:
        raise UserError(f"{path}: empty tick log")
    return TickLogText(lines, warning)


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
