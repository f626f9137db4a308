"""The emulated FT300 in a process of its own, its load read from shared memory.

Why a process: the stream's frames are due every 10 ms, and in the emulator's process its thread
waits for the interpreter while the stepping thread is inside PyBullet (a control step took up
to 66 ms there, holding the GIL): the cell's driver then saw its stream stale past its 50 ms
limit and stopped the arm (docs/emulator.md). Here the :class:`FT300Emulator` runs in a spawned
child; the emulator's stepping thread copies the twin wrist's noiseless load into shared memory
after every step (no lock: six doubles, a torn read mixes two steps 8 ms apart), and the child
streams it on its own core.

The parent keeps the same handles the emulator used on an in-process sensor: :attr:`port`,
:meth:`pull_cable`, :meth:`restore`, :meth:`close`, the stream's counters (:meth:`stats`) and a
wrist (:class:`SharedWrist`) whose :meth:`SharedWrist.inject` / :meth:`SharedWrist.clear` add a
load step the child reads, and whose ``first_stepped`` is the time (``time.monotonic``, the same
clock in both processes) the child first streamed it.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: doubles in the shared block: the load (6), the injected step (6), its "on" flag, and the
#: time the child first streamed the step (NaN: not yet)
_LOAD, _STEP, _ON, _FIRST, _SIZE = 0, 6, 12, 13, 14
#: s the parent waits for the child to come up (imports and the line) or to answer
_ANSWER_S = 20.0


class _SharedLoad:
    """:class:`sim.emulate.ft300_stream.WrenchBackend` in the child: the shared load, plus the
    step while it is on."""

    def __init__(self, block: Any) -> None:
        self._block = block

    def wrench(self) -> NDArray[np.float64]:
        b = self._block
        load = np.array(b[_LOAD:_LOAD + 6], dtype=float)
        if b[_ON] == 0.0:
            return load
        if math.isnan(b[_FIRST]):
            b[_FIRST] = time.monotonic()
        return load + np.array(b[_STEP:_STEP + 6], dtype=float)


class SharedWrist:
    """The parent's side of the load: fed from the twin's sensor after every step; the load step
    a ``force_step`` fault injects."""

    def __init__(self, block: Any, ft: Any) -> None:
        """``ft``: the twin's ``SimForceTorqueSensor``."""
        self._block, self._ft = block, ft
        self.closed = False

    def feed(self) -> None:
        """Copy the newest noiseless load (a world ``after_step`` callback; a no-op once the
        process is closed: the world keeps its callbacks)."""
        if self.closed:
            return
        self._block[_LOAD:_LOAD + 6] = [float(v) for v in self._ft.sampled_true_load()]

    def inject(self, wrench: NDArray[np.float64]) -> None:
        b = self._block
        b[_ON] = 0.0
        b[_STEP:_STEP + 6] = [float(v) for v in np.asarray(wrench, float)]
        b[_FIRST] = math.nan
        b[_ON] = 1.0

    def clear(self) -> None:
        self._block[_ON] = 0.0

    @property
    def first_stepped(self) -> float | None:
        first = float(self._block[_FIRST])
        return None if math.isnan(first) else first


def _child(block: Any, unit_id: int, seed: int, listen: tuple[str, int] | None,
           control: Connection) -> None:
    import signal

    from sim.emulate.ft300_stream import FT300Emulator

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops it, after the cell's run
    try:
        emu = FT300Emulator(_SharedLoad(block), unit_id=unit_id, seed=seed, listen=listen)
        emu.start()
    except OSError as exc:
        control.send(("error", str(exc)))
        return
    control.send(("port", emu.port))
    try:
        while True:
            try:
                command = control.recv()
            except EOFError:
                break  # the parent is gone
            if command == "close":
                break
            if command == "stats":
                control.send((emu.frames_sent, emu.max_gap, emu.late_frames))
            elif command in ("pull_cable", "restore", "go_silent", "resume"):
                getattr(emu, command)()
    finally:
        emu.close()


class FT300Process:
    """The FT300 emulator (:class:`sim.emulate.ft300_stream.FT300Emulator`) in a spawned child
    process. ``ft``: the twin's wrist sensor; ``world``: the twin, whose ``after_step`` feeds the
    shared load. Start it before the emulator's own threads."""

    def __init__(self, ft: Any, world: Any, unit_id: int = 9, seed: int = 0,
                 listen: tuple[str, int] | None = None) -> None:
        ctx = mp.get_context("spawn")  # a clean interpreter: nothing of the twin, no threads
        self._block = ctx.Array("d", _SIZE, lock=False)
        self._block[_FIRST] = math.nan
        self.wrist = SharedWrist(self._block, ft)
        self._ctx, self._unit, self._seed, self._listen = ctx, unit_id, seed, listen
        self._world = world
        self._conn: Connection | None = None
        self._proc: Any = None
        self.port = ""

    def start(self) -> FT300Process:
        """Spawn the child, wait for its line; :class:`OSError` when it cannot open it."""
        self.wrist.feed()
        self._world.after_step(self.wrist.feed)
        parent, child = self._ctx.Pipe()
        self._proc = self._ctx.Process(
            target=_child, args=(self._block, self._unit, self._seed, self._listen, child),
            name="ft300", daemon=True,
        )
        self._proc.start()
        child.close()
        self._conn = parent
        try:
            if not parent.poll(_ANSWER_S):
                raise OSError("the FT300 emulator's process did not come up")
            kind, value = parent.recv()
        except (EOFError, OSError) as exc:  # it died before it answered
            self.close()
            raise OSError(f"the FT300 emulator's process: {exc or 'ended'}") from None
        if kind == "error":
            self.close()
            raise OSError(value)
        self.port = value
        return self

    def _send(self, command: str) -> None:
        if self._conn is not None:
            try:
                self._conn.send(command)
            except (BrokenPipeError, OSError):
                pass

    def pull_cable(self) -> None:
        self._send("pull_cable")

    def restore(self) -> None:
        self._send("restore")

    def go_silent(self) -> None:
        self._send("go_silent")

    def resume(self) -> None:
        self._send("resume")

    def stats(self) -> tuple[int, float, int]:
        """(frames sent, the longest gap between two (s), frames later than two periods)."""
        self._send("stats")
        try:
            if self._conn is None or not self._conn.poll(_ANSWER_S):
                return 0, 0.0, 0
            frames, gap, late = self._conn.recv()
        except (EOFError, OSError):  # the child is gone
            return 0, 0.0, 0
        return int(frames), float(gap), int(late)

    def close(self) -> None:
        self.wrist.closed = True
        self._send("close")
        if self._proc is not None:
            self._proc.join(timeout=5.0)
            if self._proc.is_alive():
                self._proc.terminate()
                self._proc.join(timeout=2.0)
            self._proc = None
        if self._conn is not None:
            self._conn.close()
            self._conn = None
