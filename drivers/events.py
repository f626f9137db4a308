"""The cell's workflow vocabulary, shared by the tree that reports it, the state and journal that
remember it, and the twin's judge that checks it against the simulated world.

It lives at the bottom layer because both backends need it: the twin (``sim/``) imports nothing
above ``drivers/``. String enums, so a journal or JSON report written before keeps reading back
as the same values."""

from __future__ import annotations

from enum import StrEnum


class EventKind(StrEnum):
    """A step of the workflow that finished."""

    PICKED = "picked"  #: a part taken from the bin in the hole grasp
    FED = "fed"  #: the part put into the machine's slot
    MACHINED = "machined"  #: the machine finished the part in the slot
    PICKED_FROM_SLOT = "picked_from_slot"  #: the part taken back out of the slot
    PACKED = "packed"  #: the part let go in its place in the box
    BIN_EMPTY = "bin_empty"  #: nothing left to pick (the cycles end)
    REPOSITIONED = "repositioned"  #: a part moved (pushed, dragged, rolled) to be picked
    CYCLE_DONE = "cycle_done"
    CYCLE_FAILED = "cycle_failed"


class SlotState(StrEnum):
    """What the machine's slot holds."""

    EMPTY = "empty"
    FED = "fed"  #: a part waiting to be machined
    MACHINED = "machined"  #: a finished part waiting to be picked


class StopKind(StrEnum):
    """Why the cell stopped and waits for a person."""

    PERSON_NEEDED = "person_needed"  #: a failure a stop_on_failure node says needs a person
    FAILED_CYCLES = "failed_cycles"  #: too many cycles in a row without a pick
    FT_LINK_LOST = "ft_link_lost"  #: the force-torque stream stayed lost past its grace
    ARM_LINK_LOST = "arm_link_lost"  #: the arm's controller stopped answering
    INTERRUPTED = "interrupted"  #: Ctrl-C or SIGTERM: the run was stopped from outside


__all__ = ["EventKind", "SlotState", "StopKind"]
