"""Skill parameters that a cell's configuration may set: their units, ranges and key names.

Why here: a skill's parameter dataclass is the one place its defaults are written. Each field an
integrator may change is declared with :func:`si` -- default, unit, range, a sentence -- and the
configuration (``skills:`` in the cell YAML, per-node overrides in the tree YAML), the JSON
Schema and ``cell tree --types`` are all generated from that declaration, so none of them keeps
its own copy of a default. Values are SI inside the code; the configuration key carries the unit
in its name (``tilt_speed_m_s``), and angles are given in degrees there (``_deg``).

A field typed :class:`~skills.motion.Guard` is a stricter limit for some of a skill's motions
(the descent onto a rim must stop at 25 N, not at the arm's abort limit): it appears in the
configuration as ``<name>_max_force_n`` and ``<name>_timeout_s``. The skill's ``guard`` field
itself is not configured here: its force and torque are the tree node's limits (see
:func:`with_limits`), its time the ``motion_timeout_s`` key.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from typing import Any, TypeVar

from skills.motion import MAX_FORCE_LIMIT, Guard

#: unit -> (suffix of the configuration key, factor from the configured value to SI)
UNITS: dict[str, tuple[str, float]] = {
    "m": ("_m", 1.0),
    "m/s": ("_m_s", 1.0),
    "m/s^2": ("_m_s2", 1.0),
    "N": ("_n", 1.0),
    "N*m": ("_nm", 1.0),
    "s": ("_s", 1.0),
    "rad": ("_deg", math.pi / 180.0),
    "rad/s": ("_deg_s", math.pi / 180.0),
    "rad/s^2": ("_deg_s2", math.pi / 180.0),
    "m/(N*s)": ("_m_per_n_s", 1.0),
    "1": ("", 1.0),
}
SHOWN_UNIT = {"rad": "deg", "rad/s": "deg/s", "rad/s^2": "deg/s^2"}


#: What a gripper-facing parameter commands, for the check against the gripper's description:
#: ``grip_force`` (N per finger, within its force range), ``finger_speed`` (m/s, its speed range).
ACTUATORS = ("grip_force", "finger_speed")


def si(
    default: float, unit: str, low: float, high: float, doc: str, actuator: str | None = None
) -> Any:
    """A configurable field: ``default`` in SI, accepted range ``[low, high]`` in SI.
    ``actuator``: what it commands the gripper (:data:`ACTUATORS`), so a configuration asking
    the gripper for what it cannot do is refused at load, against the gripper's description."""
    if actuator is not None and actuator not in ACTUATORS:
        raise ValueError(f"unknown actuator {actuator!r}; known: {', '.join(ACTUATORS)}")
    if unit not in UNITS:
        raise ValueError(f"unknown unit {unit!r}; known: {', '.join(UNITS)}")
    if not low <= default <= high:
        raise ValueError(f"default {default} outside [{low}, {high}]")
    return field(default=default, metadata={"unit": unit, "low": low, "high": high, "doc": doc,
                                            "actuator": actuator})


def guard_field(max_force: float, timeout: float, doc: str) -> Any:
    """A configurable stricter guard (force in N, time in s; torque: the node's)."""
    return field(
        default_factory=lambda: Guard(max_force=max_force, timeout=timeout),
        metadata={"guard": True, "doc": doc},
    )


@dataclass(frozen=True)
class ConfigKey:
    """One key of a skill's configuration section."""

    key: str  #: name in the YAML, unit in the name
    field: str  #: the dataclass field it sets
    part: str | None  #: for a guard field: "max_force" or "timeout"
    unit: str  #: SI unit of the field ("1": none)
    scale: float  #: configured value * scale = SI value
    low: float  #: SI
    high: float  #: SI
    default: float  #: SI
    doc: str
    actuator: str | None = None  #: what it commands the gripper (:data:`ACTUATORS`), if anything

    @property
    def shown_unit(self) -> str:
        """The unit of the configured value, as a person reads it."""
        return SHOWN_UNIT.get(self.unit, self.unit if self.unit != "1" else "-")

    def shown(self, si_value: float) -> float:
        return si_value / self.scale


MOTION_TIMEOUT = "motion_timeout_s"
#: s, the shortest timeout a motion may be configured with (``motion_timeout_s`` and each
#: stricter guard's ``*_timeout_s``): a tenth of a second, below which a guarded motion would
#: time out before the arm carried out even a short move
MIN_MOTION_TIMEOUT = 0.1
#: s, the longest: ten minutes, far beyond any one motion of the cell, so a configured timeout
#: still ends a motion that never finishes (a lost reply, a stalled arm)
MAX_MOTION_TIMEOUT = 600.0


@functools.cache
def config_keys(cls: type) -> tuple[ConfigKey, ...]:
    """The configuration keys of a parameter dataclass, in declaration order (read once per
    class: a leaf asks for them each time its skill starts)."""
    keys: list[ConfigKey] = []
    for f in dataclasses.fields(cls):
        meta = f.metadata
        if f.name == "guard":
            g = f.default_factory() if f.default_factory is not dataclasses.MISSING else Guard()
            keys.append(
                ConfigKey(MOTION_TIMEOUT, "guard", "timeout", "s", 1.0, MIN_MOTION_TIMEOUT,
                          MAX_MOTION_TIMEOUT, g.timeout,
                          "the longest one motion of the skill may take")
            )
        elif meta.get("guard"):
            g = f.default_factory()  # type: ignore[misc]
            stem = f.name.removesuffix("_guard")
            keys.append(
                ConfigKey(f"{stem}_max_force_n", f.name, "max_force", "N", 1.0, 1.0,
                          MAX_FORCE_LIMIT, g.max_force,
                          f"{meta['doc']}: abort force, capped by the node's limit")
            )
            keys.append(
                ConfigKey(f"{stem}_timeout_s", f.name, "timeout", "s", 1.0,
                          MIN_MOTION_TIMEOUT, MAX_MOTION_TIMEOUT, g.timeout,
                          f"{meta['doc']}: timeout of each such motion")
            )
        elif "unit" in meta:
            suffix, scale = UNITS[meta["unit"]]
            keys.append(
                ConfigKey(f.name + suffix, f.name, None, meta["unit"], scale, meta["low"],
                          meta["high"], float(f.default), meta["doc"], meta.get("actuator"))
            )
    return tuple(keys)


P = TypeVar("P")


def apply_config(params: P, values: dict[str, float]) -> P:
    """``params`` with configured ``values`` (keys as :func:`config_keys` names them, values as
    configured, e.g. degrees) set. Unknown keys are a ``KeyError``: validation is the caller's,
    this only converts."""
    by_key = {k.key: k for k in config_keys(type(params))}
    changes: dict[str, Any] = {}
    for key, value in values.items():
        k = by_key[key]
        v = float(value) * k.scale
        if k.part is None:
            changes[k.field] = v
        else:
            current = changes.get(k.field, getattr(params, k.field))
            changes[k.field] = dataclasses.replace(current, **{k.part: v})
    return dataclasses.replace(params, **changes)  # type: ignore[type-var]


def with_limits(params: P, max_force: float, max_torque: float) -> P:
    """``params`` whose every motion runs under the tree node's abort limits.

    The skill's ``guard`` takes the node's force and torque (its time stays the motion timeout);
    each stricter guard keeps its own force where that is lower and takes the node's torque. So a
    limit changed in the YAML is the limit the skill stops at, and no skill limit exceeds it."""
    changes: dict[str, Any] = {}
    for f in dataclasses.fields(params):  # type: ignore[arg-type]
        value = getattr(params, f.name)
        if not isinstance(value, Guard):
            continue
        if f.name == "guard":
            changes[f.name] = Guard(max_force, max_torque, value.timeout)
        else:
            changes[f.name] = Guard(min(value.max_force, max_force), max_torque, value.timeout)
    return dataclasses.replace(params, **changes)  # type: ignore[type-var]


__all__ = [
    "ConfigKey",
    "MAX_MOTION_TIMEOUT",
    "MIN_MOTION_TIMEOUT",
    "MOTION_TIMEOUT",
    "UNITS",
    "apply_config",
    "config_keys",
    "guard_field",
    "si",
    "with_limits",
]
