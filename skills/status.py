"""The result of one step of a skill, shared by every skill and adapted by the behaviours."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Status(Enum):
    RUNNING = "running"
    SUCCESS = "success"
    FAILURE = "failure"


@dataclass(frozen=True)
class StepResult:
    """``status`` of this step and a sentence a person can read (the behaviour's feedback)."""

    status: Status
    message: str = ""

    @property
    def done(self) -> bool:
        return self.status is not Status.RUNNING


RUNNING = StepResult(Status.RUNNING)


class SkillInputError(ValueError):
    """What a skill was given cannot be used (a depth frame with no valid pixel, a frame of the
    wrong shape). A guarded step that meets one fails with the reason instead of crashing the
    tree: on a running cell a bad frame is an event to retry, not a bug."""
