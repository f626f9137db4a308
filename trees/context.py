"""What the behaviours are handed: devices, the cell's geometry, the part, and where to report.

The tree never looks anything up and never knows which backend runs: the cell builds a
:class:`CellContext` from the configuration and passes it to the tree builder.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from drivers.devices import Devices
from drivers.events import EventKind, SlotState, StopKind
from drivers.machine import Machine
from drivers.parts import Part
from skills.home import HomeParams, PutBackParams
from skills.mechanics.planner import PivotPlan
from skills.motion import Guard
from skills.packing import PackInBox, PackParams
from skills.perception.look import LookParams
from skills.pivot import PivotParams
from skills.pivot.clearance import Reach
from skills.reposition import RepositionParams
from skills.slot import FeedSlot, PickFromSlot, SlotParams
from skills.status import Failure
from skills.travel import ArmModel

#: The ``skills:`` sections of a cell's configuration: name -> the parameter dataclass whose
#: :func:`~skills.params.si` fields are its keys. A leaf of the tree names the section it reads.
SKILL_SECTIONS: dict[str, type] = {
    "pivot": PivotParams,
    "perceive": LookParams,
    "slot": SlotParams,
    "pack_in_box": PackParams,
    "put_back": PutBackParams,
    "go_home": HomeParams,
    "reposition": RepositionParams,
}
SECTION_DOCS: dict[str, str] = {
    "pivot": "Grasp, Tilt, Align and the recovery's pick from above (the paper's maneuver)",
    "perceive": "the look over the bin",
    "slot": "feeding the machine's slot and picking the part back out of it",
    "pack_in_box": "packing in the box by force-guided pushes",
    "put_back": "the recovery after a failed pick",
    "go_home": "the joint move home",
    "reposition": "the drag of a part no pivot clears where it lies",
}


@dataclass(frozen=True)
class CellGeometry:
    """Where things are in the robot base frame (m, rad); the cell derives it from its layout."""

    bin_roi: tuple[float, float, float, float]  #: (xmin, xmax, ymin, ymax) of the bin's inside
    bin_view_xy: tuple[float, float]  #: where the camera looks down on the bin from
    bin_floor_z: float
    slot_center: NDArray[np.float64]  #: centre of the slot pocket's floor
    slot_width: float
    machine_top_z: float
    tray_places: NDArray[np.float64]  #: (n, 3) packing places, in packing order
    tray_roi: tuple[float, float, float, float]
    tray_floor_z: float
    home_joints: NDArray[np.float64]  #: home joint angles (rad)
    bin_wall_height: float = 0.08  #: m above the bin's floor
    bin_wall_thickness: float = 0.005  #: m


class Events(Protocol):
    """Where behaviours report what the cell's state and log must remember."""

    def abort(self, reason: str, code: Failure | None = None, node: str | None = None) -> None:
        """A guard, a timeout or a skill's check stopped a motion; ``code`` says which, ``node``
        the tree leaf it stopped."""

    def event(self, kind: EventKind, **data: object) -> None:
        """A step of the workflow finished."""

    def stop(self, reason: str, code: StopKind | None = None, cause: str | None = None) -> None:
        """The cell must stop and wait for a person; ``cause``: the configured reason of the
        node that stopped it (a fixed text from the tree YAML), if any."""

    @property
    def stopped(self) -> str | None:
        """Why the cell stopped, or None."""


@dataclass
class WorkflowLimits:
    max_failures_per_part: int = 2
    max_failed_cycles: int = 3
    cycles: int = 10
    #: s a lost force-torque stream may stay lost before the cell stops (0: stop at once).
    ft_link_grace: float = 0.0
    #: s a motion about to start waits for a wrench over its limits to fall back (a spike of a
    #: few samples) before its guard fails it without a start.
    ft_settle: float = 0.5
    cycles_done: int = 0  #: cycles a resumed cell had already done
    #: "nearest": the part nearest the robot (the one the look examined twice); "freest": the
    #: part with the most room around it (a bin tipped full).
    pick_order: str = "nearest"


@dataclass
class CellContext:
    devices: Devices
    machine: Machine
    geometry: CellGeometry
    part: Part
    plan: PivotPlan
    params: PivotParams
    events: Events
    #: The arm's reach, for the plans that must stay inside it (the cell builds it from its
    #: arm's kinematics: the tree knows no particular arm): from where the arm stands, or
    #: else from home, where the arm can go first by a joint move.
    reach: Reach
    #: The reach from where the arm stands, along straight moves (None: ``reach``): a plan
    #: that only ``reach`` clears is carried out from home.
    reach_here: Reach | None = None
    #: The arm's kinematics for the skills' travel by joint moves (None: straight travel paths
    #: only); the cell hands in its arm's.
    arm_model: ArmModel | None = None
    limits: WorkflowLimits = field(default_factory=WorkflowLimits)
    #: The safety section's abort force and torque, for leaves whose node gives none.
    default_guard: Guard = field(default_factory=Guard)
    #: Each skill section's parameters as configured (SI), before a node's overrides and limits;
    #: a section missing here has its dataclass defaults. The pivot's is ``params``.
    skill_params: dict[str, Any] = field(default_factory=dict)
    #: Tray places already filled (by index); the cell restores it from its saved state.
    filled: set[int] = field(default_factory=set)
    #: Failed picks per remembered part location (x, y rounded to 1 cm).
    failures: dict[tuple[int, int], int] = field(default_factory=dict)
    #: Called once per tick by the loop before the tree ticks (sim stepping is not here).
    on_tick: list[Callable[[], None]] = field(default_factory=list)
    tick: int = 0
    #: What the machine's slot holds (restored on resume).
    slot_state: SlotState = SlotState.EMPTY
    #: The machine was started on the part in the slot and has not been waited for yet (a look
    #: at the bin runs in between: ``start_machining`` then ``wait_machining``).
    machining_started: bool = False
    #: ``/part/target`` was planned from a look taken while the machine ran, and nothing has
    #: touched the bin since: the next pick may use it instead of looking again (once).
    planned_ahead: bool = False
    #: The arm's joints (rad) where ``feed_slot`` left it, over the slot: a look while the
    #: machine runs returns there by a joint move, and the pick from the slot starts where it
    #: always does.
    feed_end_joints: NDArray[np.float64] | None = None
    #: A packing that stopped after its let go began (a spike, a protective stop on the way
    #: up): the place it let go in and the stopped skill, whose ``leave()`` finishes the way
    #: out (``leave_box``). None when no packing is left half done.
    left_in_box: tuple[int, PackInBox] | None = None
    #: A feed that stopped after its let go began: its ``leave()`` finishes the way out of
    #: the slot (``leave_slot``). None when no feed is left half done.
    left_in_slot: FeedSlot | None = None
    #: A pick from the slot that stopped after its pinch, the part still held: its
    #: ``finish()`` lifts it the rest of the way (``lift_from_slot``).
    lifting_from_slot: PickFromSlot | None = None
    #: Parts perception may match (the bin may hold others than ``part``); empty: ``[part]``.
    catalogue: list[Part] = field(default_factory=list)

    def section(self, name: str) -> Any:
        """The configured parameters of one ``skills:`` section."""
        if name == "pivot":
            return self.params
        if name in self.skill_params:
            return self.skill_params[name]
        return SKILL_SECTIONS[name]()
