"""A hollow part's geometry and the gripper's, in SI units, validated on construction.

These are the plain parameter objects the mechanics and the skills receive; the YAML catalogue
that produces them lives in :mod:`cell.catalogue`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from skills.mechanics.contact import Section, delta_rectangular, delta_round

HOLE_SHAPES = ("circle", "rectangle")


def _positive(owner: str, name: str, value: float) -> None:
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{owner}: {name} must be a finite number, got {value!r}")
    if value <= 0:
        raise ValueError(f"{owner}: {name} must be > 0, got {value:g}")


@dataclass(frozen=True)
class Part:
    """A hollow part lying on the bin floor.

    ``length`` is the part's length along its axis (the first number of Table 3's l x D x d, and
    ``2a`` of Table 1), ``outer`` its outer diameter or side ``D``, ``hole`` the hole's diameter
    or side ``d`` (m). ``open_ends`` is 2 for a tube, 1 for a cup or bottle: it says which ends a
    finger may enter. ``mass`` (kg) does not change the stability question (Eq. 8 is scale-free)
    but sets forces in the cell.
    """

    name: str
    length: float
    outer: float
    hole: float
    hole_shape: str = "circle"
    mass: float = 0.1
    rigid: bool = True
    open_ends: int = 2
    reference: dict[str, object] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        owner = f"part {self.name!r}"
        for name in ("length", "outer", "hole", "mass"):
            _positive(owner, name, getattr(self, name))
        if self.hole >= self.outer:
            raise ValueError(
                f"{owner}: hole ({self.hole * 1e3:g} mm) must be smaller than outer size "
                f"({self.outer * 1e3:g} mm)"
            )
        if self.hole_shape not in HOLE_SHAPES:
            raise ValueError(
                f"{owner}: hole_shape must be one of {', '.join(HOLE_SHAPES)}, "
                f"got {self.hole_shape!r}"
            )
        if self.open_ends not in (1, 2):
            raise ValueError(f"{owner}: open_ends must be 1 or 2, got {self.open_ends!r}")

    def delta(self, finger_width: float) -> float:
        """Eq. 2-3: depth of the hole contact H below the top corner (m) for this finger."""
        try:
            if self.hole_shape == "circle":
                return delta_round(self.outer, self.hole, finger_width)
            return delta_rectangular(self.outer, self.hole, finger_width)
        except ValueError as exc:
            raise ValueError(f"part {self.name!r}: {exc}") from None

    def section(self, finger_width: float) -> Section:
        """The constants of Table 1 for this part and finger."""
        return Section(a=0.5 * self.length, b=0.5 * self.outer, delta=self.delta(finger_width))


@dataclass(frozen=True)
class Gripper:
    """A parallel-jaw gripper as the planner sees it (m).

    ``finger_width`` is the pad width that must enter the hole (``w`` of Eq. 2); ``stroke`` the
    largest jaw opening; ``clearance`` the extra opening the approach needs so the inner finger
    can drop into the hole and the outer one land on the surface without touching first.
    The default width, 20 mm, is the one at which Eq. 3 reproduces Table 3's bushing and cookie
    can; set it to your pads. ``finger_length`` is how far the pads reach below the palm: the
    inner finger cannot hook deeper behind the rim than that (less a margin for the palm).
    """

    name: str = "robotiq-2f85"
    finger_width: float = 0.020
    stroke: float = 0.085
    clearance: float = 0.010
    finger_length: float = 0.055
    finger_thickness: float = 0.008  #: from a pad's face to the back of its finger

    def __post_init__(self) -> None:
        owner = f"gripper {self.name!r}"
        for name in ("finger_width", "stroke", "finger_length", "finger_thickness"):
            _positive(owner, name, getattr(self, name))
        if not math.isfinite(self.clearance) or self.clearance < 0:
            raise ValueError(f"{owner}: clearance must be >= 0, got {self.clearance!r}")
        if self.clearance >= self.stroke:
            raise ValueError(f"{owner}: clearance {self.clearance:g} m leaves no usable stroke")
