"""A cell context on fake devices, for tree tests."""

from __future__ import annotations

import functools

import numpy as np
import py_trees
from py_trees.behaviour import Behaviour
from py_trees.common import Status

from cell.catalogue import load_catalogue
from cell.reach import ur5_reach
from drivers.devices import Devices
from drivers.events import StopKind
from drivers.machine import TimedMachine
from drivers.parts import Gripper, Part
from drivers.pose import Pose
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import PivotPlan, plan_pivot
from skills.pivot import PivotParams
from skills.status import Failure
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper
from trees.context import CellContext, CellGeometry


class Recorder:
    """An events sink that remembers what it was told."""

    def __init__(self) -> None:
        self.events: list[tuple[str, dict]] = []
        self.aborts: list[str] = []
        self.codes: list[Failure | None] = []
        self._stopped: str | None = None
        self.stop_code: StopKind | None = None

    def abort(self, reason: str, code: Failure | None = None, node: str | None = None) -> None:
        self.aborts.append(reason)
        self.codes.append(code)

    def event(self, kind: str, **data: object) -> None:
        self.events.append((kind, data))

    def stop(self, reason: str, code: StopKind | None = None, cause: str | None = None) -> None:
        if self._stopped is None:
            self._stopped, self.stop_code = reason, code

    @property
    def stopped(self) -> str | None:
        return self._stopped

    def kinds(self) -> list[str]:
        return [k for k, _ in self.events]


@functools.cache
def _bushing() -> tuple[Part, PivotPlan]:
    """The catalogue's bushing and its plan: the same every time, and planning takes 0.1 s."""
    part = load_catalogue(None).get("bushing")
    return part, plan_pivot(part, Gripper(), Frictions())


def make_ctx() -> CellContext:
    """A fresh context (fresh fakes, an empty events sink) around the bushing's plan."""
    part, plan = _bushing()
    clock = FakeClock()
    dev = Devices(FakeArm(Pose(np.array([0.4, 0.0, 0.3]))), FakeGripper(), FakeFT(), clock)
    geometry = CellGeometry(
        bin_roi=(0.22, 0.72, -0.16, 0.16),
        bin_view_xy=(0.47, 0.0),
        bin_floor_z=0.0,
        slot_center=np.array([0.1, 0.45, 0.06]),
        slot_width=0.039,
        machine_top_z=0.1,
        tray_places=np.array([[0.15, -0.40, 0.005], [0.116, -0.40, 0.005]]),
        tray_roi=(0.02, 0.18, -0.51, -0.39),
        tray_floor_z=0.005,
        home_joints=np.radians([167.39, -89.5, 82.82, -83.32, -90.0, -102.61]),
    )
    assert plan.l_a is not None and plan.alpha is not None
    return CellContext(
        devices=dev,
        machine=TimedMachine(clock, 5.0),
        geometry=geometry,
        part=part,
        plan=plan,
        params=PivotParams(l_a=plan.l_a, alpha=plan.alpha),
        events=Recorder(),
        reach=ur5_reach,
    )


def tick_tree(node: Behaviour, ctx: CellContext, ticks: int) -> list[Status]:
    """Tick ``node`` up to ``ticks`` times, stepping the fakes between ticks like the world."""
    out = []
    dev = ctx.devices
    for _ in range(ticks):
        node.tick_once()
        out.append(node.status)
        if node.status != Status.RUNNING:
            break
        dev.arm.tick()
        dev.gripper.tick()
        dev.clock.t += dev.clock.dt
    return out


def fresh_ctx() -> CellContext:
    """A context for one test: the blackboard cleared (py_trees keeps it process-wide)."""
    py_trees.blackboard.Blackboard.clear()
    return make_ctx()
