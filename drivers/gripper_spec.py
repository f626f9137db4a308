"""A gripper as it is: the one description of a parallel-jaw gripper that the twin, the
emulator, the driver and the configuration's checks all read.

Why one description: the 2F-85's facts -- it cannot grip below 20 N, its speed spans 20-150 mm/s,
its fingertips travel along the approach axis as the jaws close, it reports its position in
counts at the rate its driver polls -- were spread over the twin (which could grip at 0.1 N), the
emulator, the driver's register map and a hand-kept check in the hardware path. A skill tuned in
a twin that grips more gently than the device fails on the cell. Each fact now has one home, a
YAML file under ``drivers/data/grippers/`` (the 2F-85's is the shipped default), and a value a skill
asks for outside the unit's range is refused when the configuration loads, not clamped.

The fingertip's travel (``crank_m``, ``knuckle_travel_rad``): the 2F-85 moves each pad on a
parallel four-bar linkage, so the pad stays parallel to the approach axis while its crank turns
about the knuckle and the tip moves on a circle of the crank's radius. With crank length ``L`` and
crank angle ``phi`` from the approach axis (positive: leaning outwards), a pad's distance from
the tool axis is ``h0 + L sin(phi)`` and its tip lies ``L cos(phi)`` below the knuckle. The crank
turns by ``knuckle_travel_rad`` over the whole stroke; the angle at full opening follows from the
stroke (:meth:`GripperSpec._phi_open`), taking the branch where the crank leans outwards when open
(the 2F-85's open fingers splay out and its tips advance as they close). Figures used: the
published ROS-Industrial description of the 2F-85 (``robotiq_arg2f_85``): the inner knuckle's
crank 57.15 mm (its inner-finger joint 37.6 mm across and 43.0 mm down from the knuckle), the
knuckle joint's travel 0-0.8 rad, the 85 mm stroke. They give a phi of 40.2 deg open and -5.6 deg
closed: the tips advance 13.3 mm from open to closed, 2.5 mm over a close from 70.6 to 61.5 mm.

Force and speed registers (Robotiq 2F-85/2F-140 manual, "Control"): rFR 0..255 spans
``force_n`` linearly (0 is the weakest grip, not zero force), rSP 0..255 spans ``speed_m_s``.
Position: gPO counts from ``position_counts[0]`` (fully open) to ``[1]`` (fully closed), linear in
the opening; a unit stops a few counts inside 0..255 and is calibrated per unit by the driver.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

#: Where the shipped descriptions live (``<name>.yaml``).
SHIPPED_DIR = Path(__file__).resolve().parent / "data" / "grippers"
DEFAULT_GRIPPER = "robotiq_2f85"


class GripperSpecError(ValueError):
    """A description that is not a gripper: names the key and the reason."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(f"{key}: {reason}")
        self.key, self.reason = key, reason


@dataclass(frozen=True)
class GripperSpec:
    """A parallel-jaw gripper's facts (SI). Units in the YAML are in each key's name."""

    name: str
    stroke: float  #: m, largest opening between the pads
    force_min: float  #: N per finger, the weakest grip it can make (force register 0)
    force_max: float  #: N per finger, the strongest (the register's top)
    speed_min: float  #: m/s per finger, the slowest (speed register 0)
    speed_max: float  #: m/s per finger, the fastest
    registers: int  #: top value of the force, speed and position registers (0..registers)
    open_count: int  #: position count fully open (nominal; a unit is calibrated)
    closed_count: int  #: position count fully closed
    poll_hz: float  #: how often the driver reads the unit's status (position, object flag)
    pad_width: float  #: m, ``w`` of Eq. 2, the pad width that enters the hole
    pad_length: float  #: m, how far a pad reaches below the gripper body
    pad_thickness: float  #: m, from a pad's face to the back of its finger
    pad_friction: float  #: the pad material's coefficient against steel (silicone)
    crank: float  #: m, the linkage's crank; 0: the tips do not travel along the approach
    knuckle_travel: float  #: rad the crank turns over the whole stroke
    #: how the unit tells an object: "contact" -- the fingers stopped by contact (motor current
    #: at its limit) before reaching the requested position (the 2F-85's gOBJ)
    detection: str = "contact"
    #: m/s, a finger whose position moved slower than this over ``stall_time`` counts as
    #: stopped by contact
    stall_speed: float = 0.002
    stall_time: float = 0.04  #: s

    def __post_init__(self) -> None:
        for key in ("stroke", "force_max", "speed_max", "poll_hz", "pad_width", "pad_length",
                    "pad_thickness", "stall_speed", "stall_time"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise GripperSpecError(key, f"must be a positive number, got {value!r}")
        for key in ("force_min", "speed_min", "crank", "knuckle_travel", "pad_friction"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise GripperSpecError(key, f"must be >= 0, got {value!r}")
        if self.force_min >= self.force_max:
            raise GripperSpecError("force_n", "the weakest grip must be below the strongest")
        if self.speed_min >= self.speed_max:
            raise GripperSpecError("speed_m_s", "the slowest speed must be below the fastest")
        if not 0 <= self.open_count < self.closed_count <= self.registers:
            raise GripperSpecError(
                "position_counts", f"need 0 <= open < closed <= {self.registers}, got "
                f"{self.open_count}, {self.closed_count}")
        if self.detection != "contact":
            raise GripperSpecError("detection", f"unknown {self.detection!r}; known: contact")
        if self.crank > 0:
            if not 0 < self.knuckle_travel < math.pi:
                raise GripperSpecError("knuckle_travel_rad", "must lie in (0, pi) with a crank")
            if 0.5 * self.stroke > 2 * self.crank * math.sin(0.5 * self.knuckle_travel):
                raise GripperSpecError(
                    "crank_m", "too short to give the stroke over the knuckle's travel")

    # --- registers ------------------------------------------------------------------------
    def force_register(self, force: float) -> int:
        """rFR for a grip of ``force`` N per finger (nearest; refuse out of range upstream)."""
        frac = (force - self.force_min) / (self.force_max - self.force_min)
        return int(round(min(max(frac, 0.0), 1.0) * self.registers))

    def register_force(self, register: int) -> float:
        """N per finger that rFR ``register`` stands for."""
        r = min(max(int(register), 0), self.registers)
        return self.force_min + r / self.registers * (self.force_max - self.force_min)

    def speed_register(self, speed: float) -> int:
        frac = (speed - self.speed_min) / (self.speed_max - self.speed_min)
        return int(round(min(max(frac, 0.0), 1.0) * self.registers))

    def register_speed(self, register: int) -> float:
        r = min(max(int(register), 0), self.registers)
        return self.speed_min + r / self.registers * (self.speed_max - self.speed_min)

    def applied_force(self, force: float) -> float:
        """What the unit applies when asked for ``force`` (N): the register's step, in range."""
        return self.register_force(self.force_register(force))

    def applied_speed(self, speed: float) -> float:
        return self.register_speed(self.speed_register(speed))

    # --- position -------------------------------------------------------------------------
    @property
    def count_step(self) -> float:
        """m of opening per position count."""
        return self.stroke / (self.closed_count - self.open_count)

    def count(self, width: float) -> int:
        """The nominal position count (gPO) of an opening of ``width`` m."""
        frac = min(max(width / self.stroke, 0.0), 1.0)
        return int(round(self.closed_count - frac * (self.closed_count - self.open_count)))

    def count_width(self, count: int) -> float:
        """The opening (m) a nominal position count stands for."""
        c = min(max(int(count), self.open_count), self.closed_count)
        return (self.closed_count - c) / (self.closed_count - self.open_count) * self.stroke

    def reported_width(self, width: float) -> float:
        """The opening as the unit reports it: rounded to its position counts."""
        return self.count_width(self.count(width))

    # --- the fingertips' travel along the approach axis -------------------------------------
    def _phi_open(self) -> float:
        """Crank angle (rad) at full opening: ``L (sin phi - sin(phi - T)) = stroke / 2`` on the
        branch where the crank leans outwards open (see the module doc)."""
        L, T = self.crank, self.knuckle_travel
        c = 0.5 * self.stroke / (2.0 * L * math.sin(0.5 * T))
        return 0.5 * T + math.acos(min(c, 1.0))

    def tip_advance(self, width: float) -> float:
        """m the fingertips reach further along the approach axis at opening ``width`` than when
        fully closed (<= 0 with the 2F-85's linkage over most of the stroke: closing advances
        the tips). 0 for a gripper without a crank."""
        if self.crank <= 0:
            return 0.0
        L = self.crank
        phi_o = self._phi_open()
        phi_c = phi_o - self.knuckle_travel
        h0 = 0.5 * self.stroke - L * math.sin(phi_o)
        h = 0.5 * min(max(width, 0.0), self.stroke)
        phi = math.asin(min(max((h - h0) / L, -1.0), 1.0))
        return L * (math.cos(phi) - math.cos(phi_c))

    def tip_slope(self, width: float, step: float = 1e-4) -> float:
        """d(tip_advance)/d(width): how far the tips move along the approach per metre of
        closing, at ``width`` (for a coupled joint that follows the linkage)."""
        lo, hi = max(width - step, 0.0), min(width + step, self.stroke)
        return (self.tip_advance(hi) - self.tip_advance(lo)) / (hi - lo)

    def describe(self) -> dict[str, Any]:
        """The description as its YAML keys (units in the names)."""
        return {
            "name": self.name,
            "stroke_m": self.stroke,
            "force_n": [self.force_min, self.force_max],
            "speed_m_s": [self.speed_min, self.speed_max],
            "registers": self.registers,
            "position_counts": [self.open_count, self.closed_count],
            "poll_hz": self.poll_hz,
            "pad": {"width_m": self.pad_width, "length_m": self.pad_length,
                    "thickness_m": self.pad_thickness, "friction": self.pad_friction},
            "linkage": {"crank_m": self.crank, "knuckle_travel_rad": self.knuckle_travel},
            "detection": {"kind": self.detection, "stall_speed_m_s": self.stall_speed,
                          "stall_time_s": self.stall_time},
        }


#: YAML key -> (field, kind): the keys a description file has
_PAIRS = {"force_n": ("force_min", "force_max"), "speed_m_s": ("speed_min", "speed_max"),
          "position_counts": ("open_count", "closed_count")}
_SCALARS = {"name": "name", "stroke_m": "stroke", "registers": "registers", "poll_hz": "poll_hz"}
_NESTED = {
    "pad": {"width_m": "pad_width", "length_m": "pad_length", "thickness_m": "pad_thickness",
            "friction": "pad_friction"},
    "linkage": {"crank_m": "crank", "knuckle_travel_rad": "knuckle_travel"},
    "detection": {"kind": "detection", "stall_speed_m_s": "stall_speed",
                  "stall_time_s": "stall_time"},
}
_OPTIONAL = {"detection", "stall_speed", "stall_time"}
_INTS = {"registers", "open_count", "closed_count"}


def _number(key: str, value: Any, integer: bool) -> float | int:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise GripperSpecError(key, f"expected a number, got {value!r}")
    if integer and (not isinstance(value, int)):
        raise GripperSpecError(key, f"expected a whole number, got {value!r}")
    return value


def spec_from_mapping(data: Any) -> GripperSpec:
    """A description from its YAML mapping; :class:`GripperSpecError` names the bad key."""
    if not isinstance(data, dict):
        raise GripperSpecError("", "a gripper description is a mapping of keys")
    known = set(_PAIRS) | set(_SCALARS) | set(_NESTED)
    for key in data:
        if key not in known:
            raise GripperSpecError(str(key), f"unknown key; valid keys: {', '.join(sorted(known))}")
    values: dict[str, Any] = {}
    for key, (lo, hi) in _PAIRS.items():
        if key in data:
            pair = data[key]
            if not (isinstance(pair, list) and len(pair) == 2):
                raise GripperSpecError(key, f"expected [low, high], got {pair!r}")
            values[lo] = _number(key, pair[0], lo in _INTS)
            values[hi] = _number(key, pair[1], hi in _INTS)
    for key, name in _SCALARS.items():
        if key in data:
            values[name] = (str(data[key]) if name == "name"
                            else _number(key, data[key], name in _INTS))
    for section, keys in _NESTED.items():
        sub = data.get(section, {})
        if not isinstance(sub, dict):
            raise GripperSpecError(section, "expected a mapping")
        for key in sub:
            if key not in keys:
                raise GripperSpecError(f"{section}.{key}",
                                       f"unknown key; valid keys: {', '.join(keys)}")
        for key, name in keys.items():
            if key in sub:
                values[name] = (str(sub[key]) if name == "detection"
                                else _number(f"{section}.{key}", sub[key], False))
    missing = [f.name for f in fields(GripperSpec) if f.name not in values
               and f.name not in _OPTIONAL]
    if missing:
        raise GripperSpecError(missing[0], "missing")
    return GripperSpec(**values)


def shipped_grippers() -> list[str]:
    """Names of the shipped descriptions."""
    return sorted(p.stem for p in SHIPPED_DIR.glob("*.yaml"))


def load_gripper(
    name_or_path: str | Path = DEFAULT_GRIPPER, base: Path | None = None
) -> GripperSpec:
    """A shipped description by name (``robotiq_2f85``) or a YAML file (relative to ``base``).

    Raises :class:`GripperSpecError` (unknown name, unreadable or invalid file)."""
    text = str(name_or_path)
    if not text.endswith((".yaml", ".yml")):
        path = SHIPPED_DIR / f"{text}.yaml"
        if not path.is_file():
            raise GripperSpecError(
                "", f"unknown gripper {text!r}; shipped: {', '.join(shipped_grippers())} "
                "(or the path of a description .yaml)")
    else:
        path = Path(text)
        if not path.is_absolute() and base is not None:
            path = base / path
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise GripperSpecError("", f"cannot read {path}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise GripperSpecError("", f"{path} is not YAML: {exc}") from None
    try:
        return spec_from_mapping(data)
    except GripperSpecError as exc:
        raise GripperSpecError(f"{path}: {exc.key}" if exc.key else str(path), exc.reason) from None


_DEFAULT: GripperSpec | None = None


def default_gripper() -> GripperSpec:
    """The shipped 2F-85 (read once)."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = load_gripper(DEFAULT_GRIPPER)
    return _DEFAULT


__all__ = [
    "DEFAULT_GRIPPER",
    "GripperSpec",
    "GripperSpecError",
    "default_gripper",
    "load_gripper",
    "shipped_grippers",
    "spec_from_mapping",
]
