"""The result of one step of a skill, shared by every skill and adapted by the behaviours."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, StrEnum


class Status(Enum):
    RUNNING = "running"
    SUCCESS = "success"
    FAILURE = "failure"


class Failure(StrEnum):
    """Why a step failed. The tree, the soak and the reports decide on these codes; the message
    beside them is for people and may change wording freely."""

    FORCE_TORQUE = "force_torque"  #: the wrench passed a guard's limit; the arm was stopped
    TIMEOUT = "timeout"  #: a motion or a leaf ran out of time; the arm was stopped
    ARM_FAULT = "arm_fault"  #: the controller faulted (protective stop, ...)
    ARM_STOPPED = "arm_stopped"  #: the arm stopped without reaching its target
    GRIPPER_FAULT = "gripper_fault"  #: the gripper reported a fault code
    DEVICE_LOST = "device_lost"  #: a device stopped answering (link, stale stream, no frame)
    FT_LINK_LOST = "ft_link_lost"  #: the force-torque stream is gone (every motion stopped)
    BAD_INPUT = "bad_input"  #: a sensor gave something unusable (a frame with no depth)
    NOTHING_FOUND = "nothing_found"  #: the camera found no part
    MISSED = "missed"  #: a grasp closed on nothing
    CHECK_FAILED = "check_failed"  #: a skill's own check of the outcome failed
    CANNOT_START = "cannot_start"  #: nothing to act on (no part chosen, the box full)
    BLOCKED = "blocked"  #: something stands where the part must go (a box place not free)
    NO_CONTACT = "no_contact"  #: a push met nothing where a wall or a packed part should be
    NO_CLEAR_PIVOT = "no_clear_pivot"  #: the pivot's gripper would hit a wall or a neighbour


@dataclass(frozen=True)
class StepResult:
    """``status`` of this step, a sentence a person can read (the behaviour's feedback) and,
    for a failure, its code."""

    status: Status
    message: str = ""
    code: Failure | None = None

    def failed(self, message: str) -> StepResult:
        """This failure with another message (a skill prefixing its name), the code kept."""
        return StepResult(self.status, message, self.code)

    @property
    def done(self) -> bool:
        return self.status is not Status.RUNNING


RUNNING = StepResult(Status.RUNNING)


class SkillInputError(ValueError):
    """What a skill was given cannot be used (a depth frame with no valid pixel, a frame of the
    wrong shape). A guarded step that meets one fails with the reason instead of crashing the
    tree: on a running cell a bad frame is an event to retry, not a bug."""
