"""The devices of one cell as one bundle: what a backend (the twin or the real cell) hands up.

The bundle lives in the bottom layer because both sides of the interfaces need it: the twin and
the hardware backend build it from their devices, the skills and the tree drive it. Nothing here
may import the skills, so :meth:`Devices.move` and :meth:`Devices.grip` do not build a guarded
motion themselves: they ask the guard they are given (:class:`skills.motion.Guard` implements
:class:`MotionMaker`), which knows the skills' motions. A skill keeps writing
``dev.move("lift", guard, command)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar

from drivers.arm import Arm
from drivers.camera import Camera
from drivers.clock import Clock
from drivers.ft_sensor import ForceTorqueSensor
from drivers.gripper import Gripper

M = TypeVar("M", covariant=True)


class MotionMaker(Protocol[M]):
    """Builds one guarded motion on a bundle of devices (the limits are the maker's own)."""

    def arm_motion(self, name: str, dev: Devices, command: Callable[[], None]) -> M:
        """A motion that runs ``command`` on the arm and ends when the arm reports done."""
        ...

    def gripper_motion(
        self, name: str, dev: Devices, command: Callable[[], None], settle: float
    ) -> M:
        """A motion that runs ``command`` on the gripper and ends ``settle`` s after the
        fingers stop."""
        ...


@dataclass(frozen=True)
class Devices:
    """The devices a motion skill uses, handed in by the caller (never looked up)."""

    arm: Arm
    gripper: Gripper
    ft: ForceTorqueSensor
    clock: Clock
    camera: Camera | None = None  #: the eye-in-hand RGB-D camera, where a skill needs to look

    def move(self, name: str, guard: MotionMaker[M], command: Callable[[], None]) -> M:
        """An arm motion named ``name`` under ``guard``: ``command`` starts it."""
        return guard.arm_motion(name, self, command)

    def grip(
        self, name: str, guard: MotionMaker[M], command: Callable[[], None], settle: float = 0.1
    ) -> M:
        """A gripper motion named ``name`` under ``guard``, done ``settle`` s after the fingers
        stop moving."""
        return guard.gripper_motion(name, self, command, settle)


__all__ = ["Devices", "MotionMaker"]
