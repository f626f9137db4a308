"""The crash-safe journal and `--resume`: state derived from events, refusals, and one real
SIGKILL in the middle of a simulated run followed by a resume that finishes the job."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cell.journal import (
    KEEP_JOURNALS,
    Journal,
    JournalError,
    Resume,
    keep_earlier,
    read_journal,
)
from tests.addresses import quiet_host


def _ev(kind: str, seq: int, **data: object) -> dict:
    return {"kind": kind, "seq": seq, "run": 1, "tick": seq, "t": float(seq), **data}


def test_state_follows_the_events() -> None:
    events = [
        _ev("picked", 1, x=0.5, y=0.0),
        _ev("fed", 2),
        _ev("machined", 3),
        _ev("picked_from_slot", 4),
        _ev("packed", 5, place=0),
        _ev("cycle_done", 6),
        _ev("picked", 7, x=0.5, y=0.1),
        _ev("fed", 8),
    ]
    r = Resume.from_events(events)
    assert r.filled == [0] and r.slot == "fed" and r.in_hand is None and r.cycles_done == 1
    assert r.picked_from == [[0.5, 0.0], [0.5, 0.1]]
    r = Resume.from_events(events[:4])
    assert r.in_hand == "machined" and r.slot == "empty"
    r = Resume.from_events([*events[:1], _ev("returned_to_bin", 2)])
    assert r.in_hand is None and r.picked_from == []


def test_a_box_place_filled_twice_or_a_slot_fed_twice_is_refused() -> None:
    with pytest.raises(JournalError, match="box place 0 packed twice"):
        Resume.from_events([_ev("packed", 1, place=0), _ev("packed", 2, place=0)])
    with pytest.raises(JournalError, match="slot was fed twice"):
        Resume.from_events([_ev("fed", 1), _ev("fed", 2)])


def test_events_survive_reopening_and_runs_are_numbered(tmp_path) -> None:
    j = Journal(tmp_path / "j.sqlite")
    j.append(3, 0.1, "picked", {"x": 0.5, "y": 0.0})
    j.close()
    j = Journal(tmp_path / "j.sqlite")
    assert j.run == 2
    assert [e["kind"] for e in j.events()] == ["picked"] and j.events()[0]["x"] == 0.5


def test_a_run_without_events_keeps_its_number_and_readers_count_none(tmp_path) -> None:
    j = Journal(tmp_path / "j.sqlite")
    assert j.begin_run() == 1
    j.close()  # run 1 ended before its first event (a crash at start-up)
    assert Journal(tmp_path / "j.sqlite").run == 2  # a reader: counts nothing
    j = Journal(tmp_path / "j.sqlite")
    assert j.begin_run() == 2
    j.close()
    assert Journal(tmp_path / "j.sqlite").run == 3


def test_a_fresh_run_keeps_the_earlier_journals_numbered(tmp_path) -> None:
    path = tmp_path / "j.sqlite"
    assert keep_earlier(path) is None  # nothing to keep
    for n in range(KEEP_JOURNALS + 2):
        j = Journal(path)
        j.append(0, 0.0, "picked", {"generation": n})
        j.close()
        kept = keep_earlier(path)
        assert kept == tmp_path / "j.1.sqlite" and not path.exists()
    names = sorted(p.name for p in tmp_path.glob("j.*.sqlite"))
    assert names == [f"j.{k}.sqlite" for k in range(1, KEEP_JOURNALS + 1)]
    newest = Journal(tmp_path / "j.1.sqlite").events()[0]["generation"]
    oldest = Journal(tmp_path / f"j.{KEEP_JOURNALS}.sqlite").events()[0]["generation"]
    assert (newest, oldest) == (KEEP_JOURNALS + 1, 2)  # generations 0 and 1 dropped


def test_a_crashed_journal_is_kept_whole_with_the_events_of_its_wal(tmp_path) -> None:
    path = tmp_path / "j.sqlite"
    code = (
        "import os; from cell.journal import Journal; "
        f"j = Journal({str(path)!r}); j.begin_run(); j.append(1, 0.1, 'fed', {{}}); os._exit(9)"
    )
    subprocess.run([sys.executable, "-c", code], check=False, timeout=60)
    assert Path(f"{path}-wal").exists()  # the killed run's event is in the WAL only
    kept = keep_earlier(path)
    assert kept is not None and not kept.with_name(kept.name + "-wal").exists()
    assert [e["kind"] for e in read_journal(kept)[0]] == ["fed"]
    assert not path.exists() and not Path(f"{path}-wal").exists()


def test_a_corrupt_journal_is_an_error_naming_it_never_discarded(tmp_path) -> None:
    bad = tmp_path / "j.sqlite"
    bad.write_bytes(b"this is not a database, but somebody's file" * 100)
    with pytest.raises(JournalError, match=str(bad)):
        Journal(bad).events()
    assert bad.read_bytes().startswith(b"this is not")  # left as it was


CONFIG = """\
sim: {{seed: 0}}
bin: {{parts: 2}}
workflow: {{machining_time_s: 1, cycles: 2}}
log: {{tick_log: {d}/ticks.jsonl, state_file: {d}/state.json, journal: {d}/journal.sqlite}}
"""


def _cell(*args: str) -> list[str]:
    return [sys.executable, "-m", "cell.cli", *args]


def _files(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` and its bytes, but SQLite's shared-memory index (a reader
    maps it; it holds no record)."""
    return {
        str(f.relative_to(folder)): f.read_bytes()
        for f in sorted(folder.rglob("*"))
        if f.is_file() and not f.name.endswith("-shm")
    }


HW_CONFIG = """\
cell: {{backend: hw}}
devices:
  arm: {{host: {host}}}
  gripper: {{port: {d}/no_tty0}}
  ft: {{port: {d}/no_tty1}}
skills:
  pivot: {{grip_force_n: 20, hold_force_n: 20}}
  slot: {{hold_force_n: 20}}
workflow: {{cycles: 3}}
log: {{tick_log: {d}/ticks.jsonl, state_file: {d}/state.json, journal: {d}/journal.sqlite}}
"""


def test_a_run_refused_by_its_devices_leaves_the_journal_it_would_resume(tmp_path) -> None:
    cfg = tmp_path / "hw.yaml"
    cfg.write_text(HW_CONFIG.format(d=tmp_path, host=quiet_host()))
    journal = Journal(tmp_path / "journal.sqlite")
    journal.begin_run()
    for i, (kind, data) in enumerate([
        ("picked", {"x": 0.5, "y": 0.0}), ("fed", {}), ("machined", {}),
        ("picked_from_slot", {}), ("packed", {"place": 0}), ("cycle_done", {}),
    ]):
        journal.append(i, float(i), kind, data)
    journal.close()
    files = _files(tmp_path)
    for extra in ([], ["--resume"]):
        r = subprocess.run(
            _cell("run", "--config", str(cfg), *extra), capture_output=True, text=True,
            timeout=120, cwd=tmp_path,
        )
        assert r.returncode == 2, r.stdout + r.stderr
        assert "start-up checks failed, nothing moved" in r.stderr
        assert _files(tmp_path) == files, extra
    events, run = read_journal(tmp_path / "journal.sqlite")
    assert run == 2 and Resume.from_events(events).filled == [0]


def test_cli_refuses_resume_without_or_with_a_corrupt_journal(tmp_path) -> None:
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(CONFIG.format(d=tmp_path))
    r = subprocess.run(
        _cell("sim", "--config", str(cfg), "--resume"), capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 2 and "no journal at" in r.stderr and "Traceback" not in r.stderr
    (tmp_path / "journal.sqlite").write_bytes(b"garbage" * 500)
    r = subprocess.run(
        _cell("sim", "--config", str(cfg), "--resume"), capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 2 and "not a readable cell journal" in r.stderr
    assert "journal.sqlite" in r.stderr


def test_sigkill_mid_run_then_resume_finishes_without_doing_anything_twice(tmp_path) -> None:
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(CONFIG.format(d=tmp_path))
    journal = tmp_path / "journal.sqlite"
    proc = subprocess.Popen(
        _cell("sim", "--config", str(cfg), "--quiet"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:  # kill it once the first part is in the slot
        if journal.exists():
            # read-only: a writable connection of this test, closed whenever it is collected,
            # would fold the killed run's -wal into the journal after the snapshot below
            try:
                kinds = [e["kind"] for e in read_journal(journal)[0]]
            except JournalError:  # caught while the run creates it
                kinds = []
            if "fed" in kinds:
                break
        time.sleep(0.3)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = Resume.from_events(read_journal(journal)[0])
    assert before.slot in ("fed", "machined") or before.filled, before
    # Starts refused after the journal was read (the monitor's port is taken): nothing on disk
    # changes, fresh or resumed, so the resume below still finds run 1 where it stopped.
    files = _files(tmp_path)
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        monitor = f"127.0.0.1:{busy.getsockname()[1]}"
        for extra in ([], ["--resume"]):
            r = subprocess.run(
                _cell("sim", "--config", str(cfg), "--quiet", "--monitor", monitor, *extra),
                capture_output=True, text=True, timeout=120,
            )
            assert r.returncode == 2 and "cannot listen" in r.stderr, r.stderr[-2000:]
            assert _files(tmp_path) == files, extra
    # Resumes killed during their start-up, while the twin is built and just after.
    for delay in (1.5, 4.0):
        proc = subprocess.Popen(
            _cell("sim", "--config", str(cfg), "--quiet", "--resume"),
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    out = tmp_path / "final.json"
    r = subprocess.run(
        _cell("sim", "--config", str(cfg), "--resume", "--quiet", "--json", str(out)),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert re.search(r"run \d+ resumes where run \d+ of", r.stdout), r.stdout
    after = Resume.from_events(Journal(journal).events())  # raises on a double feed or fill
    assert sorted(after.filled) == [0, 1] and after.cycles_done == 2
    parts = json.loads(out.read_text())["parts"]
    assert parts == {"in_bin": 0, "in_hand": 0, "in_slot": 0, "packed": 2, "on_floor": 0}
    assert Path(str(journal)).exists()
