"""The cell's crash-safe journal: every workflow event, committed before the next tick.

Why SQLite in WAL mode: one file, atomic commits that survive a killed process (and, with
``synchronous=FULL``, a lost power supply), readable by any tool, in the standard library. The
journal is append-only; the cell's state on resume is *derived* from it (which box places are
filled, whether the slot holds a part and whether it was machined, whether the hand holds one),
so a resumed cell never feeds a slot twice nor fills a box place twice.

A journal that cannot be read is an error naming the file; it is never silently discarded.
"""

from __future__ import annotations

import json
import sqlite3
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

from drivers.events import EventKind, SlotState


class JournalError(Exception):
    """A journal that cannot be opened or read (corrupt, not a journal, another version)."""


SCHEMA_VERSION = 1


class Journal:
    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None)  # autocommit per event
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)"
            )
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS events (seq INTEGER PRIMARY KEY AUTOINCREMENT, "
                "run INTEGER NOT NULL, tick INTEGER NOT NULL, t REAL NOT NULL, "
                "kind TEXT NOT NULL, data TEXT NOT NULL)"
            )
            if _schema(self._db, self.path) is None:
                self._db.execute(
                    "INSERT OR IGNORE INTO meta VALUES ('schema', ?)", (str(SCHEMA_VERSION),)
                )
            self.run = _next_run(self._db)
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{self.path}: not a readable cell journal: {exc}") from None

    def begin_run(self) -> int:
        """Count this run in the journal (a reader that only opens it counts nothing)."""
        self._db.execute("INSERT OR REPLACE INTO meta VALUES ('runs', ?)", (str(self.run),))
        return self.run

    def append(self, tick: int, t: float, kind: str, data: dict[str, Any]) -> None:
        self._db.execute(
            "INSERT INTO events (run, tick, t, kind, data) VALUES (?, ?, ?, ?, ?)",
            (self.run, tick, t, kind, json.dumps(data, default=repr)),
        )

    def events(self) -> list[dict[str, Any]]:
        try:
            return _events(self._db)
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{self.path}: not a readable cell journal: {exc}") from None

    def close(self) -> None:
        self._db.close()


def _schema(db: sqlite3.Connection, path: Path) -> str | None:
    """The journal's schema version (None: a new file), refused when it is another one."""
    row = db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()
    if row is not None and row[0] != str(SCHEMA_VERSION):
        raise JournalError(f"{path}: journal schema {row[0]}, this build reads {SCHEMA_VERSION}")
    return None if row is None else str(row[0])


def _next_run(db: sqlite3.Connection) -> int:
    last = db.execute("SELECT MAX(run) FROM events").fetchone()[0]
    # Runs are counted in meta too: a run that ended before its first event still has its
    # number, so the next run's number is never given twice.
    row = db.execute("SELECT value FROM meta WHERE key='runs'").fetchone()
    counted = int(row[0]) if row is not None else 0
    return max(counted, 0 if last is None else int(last)) + 1


def _events(db: sqlite3.Connection) -> list[dict[str, Any]]:
    rows = db.execute("SELECT seq, run, tick, t, kind, data FROM events ORDER BY seq").fetchall()
    return [
        {"seq": s, "run": r, "tick": k, "t": t, "kind": kind, **json.loads(d)}
        for s, r, k, t, kind, d in rows
    ]


def read_journal(path: Path) -> tuple[list[dict[str, Any]], int]:
    """The journal's events and the number the next run would get, read without writing.

    Why: a start that is refused after this read (a device that does not answer, a busy
    monitor port) must leave the journal as it was, or the ``--resume`` that follows would not
    find the run it continues. A journal closed cleanly has no ``-wal`` file: it is opened
    immutable, so SQLite creates none; one left by a crash is read with its ``-wal`` (the
    events committed there) in read-only mode."""
    wal = Path(str(path) + "-wal")
    mode = "mode=ro" if wal.exists() else "immutable=1"
    try:
        db = sqlite3.connect(f"{path.resolve().as_uri()}?{mode}", uri=True)
        try:
            if db.execute(
                "SELECT COUNT(*) FROM sqlite_master WHERE name IN ('meta', 'events')"
            ).fetchone()[0] != 2:
                raise sqlite3.DatabaseError("no meta and events tables")
            _schema(db, path)
            return _events(db), _next_run(db)
        finally:
            db.close()
    except sqlite3.DatabaseError as exc:
        raise JournalError(f"{path}: not a readable cell journal: {exc}") from None


#: How many earlier journals a fresh run keeps beside the new one (``NAME.1.sqlite`` the newest).
KEEP_JOURNALS = 5


def _with_wal(path: Path) -> list[tuple[Path, str]]:
    return [(Path(str(path) + s), s) for s in ("", "-wal", "-shm")]


def numbered(path: Path, k: int) -> Path:
    """``out/cell_journal.sqlite`` -> ``out/cell_journal.2.sqlite``."""
    return path.with_name(f"{path.stem}.{k}{path.suffix}")


def keep_earlier(path: Path, keep: int = KEEP_JOURNALS) -> Path | None:
    """Before a fresh run: move the journal at ``path`` to ``NAME.1.SUFFIX``, shifting the
    earlier ones up (``.1`` to ``.2`` ...) and dropping the one past ``keep``. Returns where the
    journal went (None when there was none). Never deletes the newest earlier journals: a run
    started by mistake without ``--resume`` can still be resumed by moving ``.1`` back."""
    if not path.exists():
        return None
    if Path(str(path) + "-wal").exists():
        # A crashed run's events may still sit in its -wal file: fold them into the journal
        # first, so the move below is one rename, whole or not at all, whenever it is killed.
        try:
            db = sqlite3.connect(path)
            try:
                db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            finally:
                db.close()
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{path}: not a readable cell journal: {exc}") from None
    for src, _suffix in _with_wal(numbered(path, keep)):
        src.unlink(missing_ok=True)
    for k in range(keep - 1, 0, -1):
        for src, suffix in _with_wal(numbered(path, k)):
            if src.exists():
                src.replace(Path(str(numbered(path, k + 1)) + suffix))
    for src, suffix in _with_wal(path):
        if src.exists():
            src.replace(Path(str(numbered(path, 1)) + suffix))
    return numbered(path, 1)


class JournalKind(StrEnum):
    """Records of the journal that are not workflow events."""

    ABORT = "abort"
    STOP = "stop"
    RETURNED_TO_BIN = "returned_to_bin"  #: the part held at a crash went back to the bin
    RETURNED_TO_SLOT = "returned_to_slot"  #: a machined part held at a crash went back


RETURNED_TO_BIN, RETURNED_TO_SLOT = JournalKind.RETURNED_TO_BIN, JournalKind.RETURNED_TO_SLOT


@dataclass
class Resume:
    """What the journal says the cell had done when it stopped."""

    filled: list[int] = field(default_factory=list)  #: box places, in packing order
    slot: SlotState = SlotState.EMPTY
    #: What the gripper held: None, "bin" (a part picked from the bin, not yet fed) or
    #: "machined" (a part taken from the slot, not yet packed).
    in_hand: str | None = None
    picked_from: list[list[float]] = field(default_factory=list)  #: bin (x, y) of parts taken
    cycles_done: int = 0
    runs: int = 0

    @classmethod
    def from_events(cls, events: list[dict[str, Any]]) -> Resume:
        r = cls()
        for e in events:
            kind = e["kind"]
            r.runs = max(r.runs, int(e["run"]))
            if kind == EventKind.PICKED:
                r.in_hand = "bin"
                if "x" in e and "y" in e:
                    r.picked_from.append([float(e["x"]), float(e["y"])])
            elif kind == EventKind.FED:
                if r.slot is not SlotState.EMPTY:
                    raise JournalError(f"the slot was fed twice (event {e['seq']})")
                r.in_hand, r.slot = None, SlotState.FED
            elif kind == EventKind.MACHINED:
                r.slot = SlotState.MACHINED
            elif kind == EventKind.PICKED_FROM_SLOT:
                r.in_hand, r.slot = "machined", SlotState.EMPTY
            elif kind == EventKind.PACKED:
                r.in_hand = None
                place = int(e["place"])
                if place in r.filled:
                    raise JournalError(f"box place {place} packed twice (event {e['seq']})")
                r.filled.append(place)
            elif kind == EventKind.CYCLE_DONE:
                r.cycles_done += 1
            elif kind == RETURNED_TO_BIN:  # the part held at a crash went back to the bin
                r.in_hand = None
                if r.picked_from:
                    r.picked_from.pop()
            elif kind == RETURNED_TO_SLOT:  # a machined part held at a crash went back
                r.in_hand, r.slot = None, SlotState.MACHINED
        return r


__all__ = [
    "KEEP_JOURNALS",
    "Journal",
    "JournalError",
    "JournalKind",
    "Resume",
    "keep_earlier",
    "read_journal",
]
