"""Progress that suits where it goes: a live bar on a terminal, a plain line now and then into a
file or a pipe.

Why: a bar is redrawn with carriage returns, which a terminal turns into one changing line but a
log file keeps, every redraw of it, on one line (a 200-scene run left 20,000 characters). So the
bar is drawn only when the stream is a terminal; otherwise a whole line is written every
``every_s`` seconds (:data:`PLAIN_EVERY_S`, or the environment's ``CELL_PROGRESS_EVERY_S``; 0:
none until the end) and once at the end, so a log shows that the run is alive and how far it got
without drowning what matters.
"""

from __future__ import annotations

import os
import sys
import time
from typing import TextIO

#: Seconds between progress lines into a file or a pipe.
PLAIN_EVERY_S = 10.0
#: Seconds between redraws of the bar on a terminal.
BAR_EVERY_S = 0.2


def plain_every_s() -> float:
    """The interval of plain lines: ``CELL_PROGRESS_EVERY_S`` when set (0: none), else 10 s."""
    raw = os.environ.get("CELL_PROGRESS_EVERY_S")
    if raw is None:
        return PLAIN_EVERY_S
    try:
        return max(0.0, float(raw))
    except ValueError:
        return PLAIN_EVERY_S


class Progress:
    """``done`` of ``total`` with a short detail text; :meth:`line` for lines that stay."""

    def __init__(
        self,
        total: int,
        label: str = "",
        *,
        stream: TextIO | None = None,
        quiet: bool = False,
        every_s: float | None = None,
        tty: bool | None = None,
        width: int = 30,
    ) -> None:
        self.total, self.label, self.quiet, self.width = max(0, total), label, quiet, width
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.every_s = plain_every_s() if every_s is None else every_s
        self.t0 = time.perf_counter()
        self._last = self.t0 if not self.tty else 0.0
        self._drawn = False
        self._final = False

    def _text(self, done: int, detail: str) -> str:
        wall = time.perf_counter() - self.t0
        head = f"{self.label} " if self.label else ""
        tail = f"  {detail}" if detail else ""
        if self.tty:
            filled = int(round(self.width * min(done, self.total) / max(1, self.total)))
            bar = "#" * filled + "." * (self.width - filled)
            return f"{head}[{bar}] {done}/{self.total}{tail}  {wall:.0f} s"
        return f"{head}{done}/{self.total}{tail}  (wall {wall:.0f} s)"

    def update(self, done: int, detail: str = "") -> None:
        if self.quiet:
            return
        now = time.perf_counter()
        last = done >= self.total
        if self.tty:
            if last or now - self._last >= BAR_EVERY_S:
                self._last = now
                self.stream.write("\r\033[K" + self._text(done, detail))
                self._drawn = True
                self.stream.flush()
            return
        due = self.every_s > 0 and now - self._last >= self.every_s
        if (due or last) and not (last and self._final):
            self._last = now
            self._final = last
            self.stream.write(self._text(done, detail) + "\n")
            self.stream.flush()

    def line(self, text: str) -> None:
        """A line that stays (an event, an abort): the bar is cleared and redrawn below it."""
        if self.quiet:
            return
        if self._drawn:
            self.stream.write("\r\033[K")
            self._drawn = False
        self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self._drawn:
            self.stream.write("\n")
            self._drawn = False
        self.stream.flush()


__all__ = ["PLAIN_EVERY_S", "Progress", "plain_every_s"]
