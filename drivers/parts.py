"""A hollow part's geometry and the gripper's, in SI units, validated on construction.

These are the plain parameter objects the mechanics and the skills plan with, the twin builds its
bodies from and the hardware path carries through the cell. They live in the bottom layer so that
``sim`` (which implements the device interfaces) can take a :class:`Part` without importing the
skills above it; the YAML catalogue that produces them lives in :mod:`cell.catalogue`.

With the part comes the geometry of where a flat finger of width ``w`` touches the hole (the
paper's Eq. 2-3) and the section constants of Table 1 (:class:`Section`): they are properties of
the part and the finger alone, which the mechanics in :mod:`skills.mechanics.contact` then use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from drivers.gripper_spec import GripperSpec
from drivers.tool import FINGER_LENGTH

HOLE_SHAPES = ("circle", "rectangle")


def _positive(owner: str, name: str, value: float) -> None:
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{owner}: {name} must be a finite number, got {value!r}")
    if value <= 0:
        raise ValueError(f"{owner}: {name} must be > 0, got {value:g}")


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return value


def _finger_fits(hole: float, finger_width: float) -> tuple[float, float]:
    """Validate ``0 < w < d`` (Eq. 2's ``0 < w/d < 1``) and return ``(d, w)``."""
    d = _finite("hole size d", hole)
    w = _finite("finger width w", finger_width)
    if d <= 0.0:
        raise ValueError(f"hole size d must be > 0 m, got {d:g}")
    if w <= 0.0:
        raise ValueError(f"finger width w must be > 0 m, got {w:g}")
    if w >= d:
        raise ValueError(
            f"finger width w = {w * 1e3:.1f} mm is not narrower than the hole "
            f"d = {d * 1e3:.1f} mm: the finger cannot enter the hole (needs 0 < w/d < 1)"
        )
    return d, w


def hole_offset(hole: float, finger_width: float) -> float:
    """Eq. 2: distance x (m) from the hole's axis to the flat face of a finger of width ``w``.

    A flat finger of width ``w`` inside a round hole of diameter ``d`` touches the hole along a
    chord of length ``w``; that chord lies ``x = d/2 * sqrt(1 - (w/d)^2)`` from the axis.
    """
    d, w = _finger_fits(hole, finger_width)
    return 0.5 * d * math.sqrt(1.0 - (w / d) ** 2)


def delta_round(outer: float, hole: float, finger_width: float) -> float:
    """Eq. 3 for a round hole: ``delta = D/2 - x`` (m), the depth of H below the top corner."""
    outer = _finite("outer size D", outer)
    x = hole_offset(hole, finger_width)
    if outer <= hole:
        raise ValueError(f"outer size D = {outer:g} m must exceed the hole d = {hole:g} m")
    return 0.5 * outer - x


def delta_rectangular(outer: float, hole: float, finger_width: float) -> float:
    """``delta`` (m) for a rectangular hole: the finger's face lies flat on the inner wall.

    The contact is then the wall's inner edge, one wall thickness ``(D - d)/2`` below the top.
    (The paper's Table 3 lists ``D - d`` for its two prismatic parts; see docs/results.md.)
    """
    outer = _finite("outer size D", outer)
    hole, _ = _finger_fits(hole, finger_width)
    if outer <= hole:
        raise ValueError(f"outer size D = {outer:g} m must exceed the hole d = {hole:g} m")
    return 0.5 * (outer - hole)


@dataclass(frozen=True)
class Frictions:
    """Coulomb friction coefficients at S, H and G (dimensionless, >= 0): the planner's model
    and the twin's contacts use the same set.

    Defaults are the set the paper infers from its experiments (Sec. IV-B).
    """

    mu_s: float = 0.2
    mu_h: float = 0.4
    mu_g: float = 0.4

    def __post_init__(self) -> None:
        for name in ("mu_s", "mu_h", "mu_g"):
            value = _finite(name, getattr(self, name))
            if value < 0.0:
                raise ValueError(f"{name} must be >= 0 (a friction coefficient), got {value:g}")

    @property
    def gammas(self) -> tuple[float, float, float]:
        """Friction-cone half angles ``gamma = atan(mu)`` at S, H, G (rad)."""
        return (math.atan(self.mu_s), math.atan(self.mu_h), math.atan(self.mu_g))

    @property
    def frictionless(self) -> bool:
        return self.mu_s == 0.0 and self.mu_h == 0.0 and self.mu_g == 0.0


@dataclass(frozen=True)
class Section:
    """The constant geometry of Table 1 for one part and finger: ``a``, ``b``, ``delta`` (m)."""

    a: float
    b: float
    delta: float

    def __post_init__(self) -> None:
        a = _finite("half length a", self.a)
        b = _finite("half height b", self.b)
        delta = _finite("delta", self.delta)
        if a <= 0.0 or b <= 0.0:
            raise ValueError(f"half length a and half height b must be > 0 m, got a={a:g}, b={b:g}")
        if not 0.0 <= delta <= 2.0 * b:
            raise ValueError(f"delta must lie in [0, D] = [0, {2 * b:g}] m, got {delta:g}")

    @property
    def tip_angle(self) -> float:
        """Tilt ``beta`` (rad) at which the centre of mass passes over G: ``atan(a/b)``.

        Beyond it gravity turns the part towards upright about G (Sec. III-B).
        """
        return math.atan2(self.a, self.b)


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
    (Not the device: that is :class:`drivers.gripper.Gripper`, the interface a gripper driver
    implements.)
    """

    name: str = "robotiq-2f85"
    finger_width: float = 0.020
    stroke: float = 0.085
    clearance: float = 0.010
    finger_length: float = FINGER_LENGTH  #: the tool's (drivers.tool)
    finger_thickness: float = 0.008  #: from a pad's face to the back of its finger

    def __post_init__(self) -> None:
        owner = f"gripper {self.name!r}"
        for name in ("finger_width", "stroke", "finger_length", "finger_thickness"):
            _positive(owner, name, getattr(self, name))
        if not math.isfinite(self.clearance) or self.clearance < 0:
            raise ValueError(f"{owner}: clearance must be >= 0, got {self.clearance!r}")
        if self.clearance >= self.stroke:
            raise ValueError(f"{owner}: clearance {self.clearance:g} m leaves no usable stroke")

    @classmethod
    def from_spec(cls, spec: GripperSpec) -> Gripper:
        """The planner's model of a gripper description: its pads and stroke (the clearance is
        the approach's, not the unit's)."""
        return cls(
            name=spec.name, finger_width=spec.pad_width, stroke=spec.stroke,
            finger_length=spec.pad_length, finger_thickness=spec.pad_thickness,
        )


__all__ = [
    "HOLE_SHAPES",
    "Frictions",
    "Gripper",
    "Part",
    "Section",
    "delta_rectangular",
    "delta_round",
    "hole_offset",
]
