"""The machine-tool interface: the cell loads a part into its slot, starts it and waits.

On hardware this is a few digital lines to the machine's controller (start, busy, fault); in the
twin a timer on simulation time. Nothing here blocks: ``start()`` returns at once and the tree
polls ``busy()`` once per tick.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable


@runtime_checkable
class Machine(Protocol):
    def start(self) -> None:
        """Start a machining cycle on the part in the slot."""
        ...

    def busy(self) -> bool:
        """True while the machining cycle runs."""
        ...

    def fault(self) -> str | None:
        """Why the machine cannot run (None: healthy)."""
        ...


class TimedMachine:
    """A machine whose cycle takes ``duration`` seconds of the given clock (the twin's machine,
    and a stand-in for a machine that reports nothing but needs a known time)."""

    def __init__(self, clock, duration: float) -> None:  # type: ignore[no-untyped-def]
        if duration < 0:
            raise ValueError(f"machining duration must be >= 0 s, got {duration}")
        self.clock, self.duration = clock, duration
        self._t_end: float | None = None
        self.cycles = 0

    def start(self) -> None:
        self._t_end = self.clock.now() + self.duration
        self.cycles += 1

    def busy(self) -> bool:
        return self._t_end is not None and self.clock.now() < self._t_end

    def fault(self) -> str | None:
        return None
