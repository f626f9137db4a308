"""Progress suits where it goes: a bar redrawn in place on a terminal; whole lines, every few
seconds and at the end, into a file or a pipe (never carriage returns there)."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import pytest

import cell.progress as progress_mod
from cell.progress import Progress


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    c = FakeClock()
    monkeypatch.setattr(progress_mod.time, "perf_counter", c)
    return c


def test_into_a_file_a_line_every_interval_and_one_at_the_end(clock: FakeClock) -> None:
    out = io.StringIO()
    bar = Progress(200, "scenes", stream=out, tty=False, every_s=10.0)
    for done in range(1, 201):
        clock.t += 0.5  # 100 s in all: 10 interval lines, the last one the end's
        bar.update(done, f"missed {done // 50}")
    bar.close()
    text = out.getvalue()
    assert "\r" not in text and "\033" not in text
    lines = text.splitlines()
    assert len(lines) == 10, lines
    assert lines[-1].startswith("scenes 200/200  missed 4")
    assert lines[0].startswith("scenes 20/200")


def test_into_a_file_with_interval_0_only_the_end(clock: FakeClock) -> None:
    out = io.StringIO()
    bar = Progress(50, stream=out, tty=False, every_s=0.0)
    for done in range(1, 51):
        clock.t += 5.0
        bar.update(done)
    assert out.getvalue().count("\n") == 1 and out.getvalue().startswith("50/50")


def test_the_interval_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CELL_PROGRESS_EVERY_S", "2.5")
    assert Progress(3, stream=io.StringIO(), tty=False).every_s == 2.5
    monkeypatch.setenv("CELL_PROGRESS_EVERY_S", "0")
    assert Progress(3, stream=io.StringIO(), tty=False).every_s == 0.0


def test_on_a_terminal_a_bar_redrawn_in_place(clock: FakeClock) -> None:
    out = io.StringIO()
    bar = Progress(4, "trials", stream=out, tty=True)
    for done in range(1, 5):
        clock.t += 1.0
        bar.update(done, f"ok {done}")
        if done == 2:
            bar.line("  an event")
    bar.close()
    text = out.getvalue()
    assert text.count("\r\033[K") >= 4
    assert "trials [" + "#" * 30 + "] 4/4  ok 4" in text
    assert "\r\033[K  an event\n" in text  # the bar is cleared, the line stays
    assert text.endswith("\n")


def test_quiet_writes_nothing(clock: FakeClock) -> None:
    out = io.StringIO()
    bar = Progress(3, stream=out, tty=True, quiet=True)
    bar.update(3)
    bar.line("x")
    bar.close()
    assert out.getvalue() == ""


def test_perceive_into_a_pipe_writes_lines_not_a_redrawn_bar(tmp_path: Path) -> None:
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cell.cli",
            "perceive",
            "--scenes",
            "3",
            "--seed",
            "0",
            "--json",
            str(tmp_path / "p.json"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "\r" not in r.stderr
    assert "scenes 3/3" in r.stderr
    assert max(len(line) for line in r.stderr.splitlines()) < 200
