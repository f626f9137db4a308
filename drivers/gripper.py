"""The parallel-jaw gripper interface (a Robotiq 2F-85 or its twin). Commands return at once."""

from __future__ import annotations

from typing import Protocol, runtime_checkable


@runtime_checkable
class Gripper(Protocol):
    stroke: float  #: largest opening between the finger pads (m)
    finger_width: float  #: pad width, the ``w`` of the paper's Eq. 2 (m)

    def open(self, width: float | None = None, speed: float = 0.1) -> None:
        """Start opening to ``width`` (m; full stroke if None) at ``speed`` (m/s)."""
        ...

    def close(self, force: float, speed: float = 0.05, width: float = 0.0) -> None:
        """Start closing towards ``width`` (m; 0 = fully) with at most ``force`` (N) per finger
        at ``speed`` (m/s). A ``width`` just short of the part's caps how far the fingers may
        follow a part that yields (the 2F-85's position request with its force setting)."""
        ...

    def width(self) -> float:
        """Current opening between the pads (m)."""
        ...

    def tip_advance(self, width: float) -> float:
        """How far (m) the fingertips reach further along the approach axis at opening ``width``
        (m) than when fully closed: a linkage-driven gripper's tips travel as its jaws move (the
        2F-85's advance 13 mm from open to closed), which a skill setting a fingertip on a
        surface must take into account. 0 for fingers on a slide."""
        ...

    def moving(self) -> bool:
        """True while the fingers still travel."""
        ...

    def object_detected(self) -> bool:
        """True when the fingers stalled on an object before reaching their target."""
        ...

    def fault(self) -> str | None:
        """A fault description, or None when healthy."""
        ...
