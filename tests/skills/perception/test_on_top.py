"""A part lying level on another (a bushing or a bottle on a wiring duct's flat top), as a tipped
bin leaves one: found, fitted as off the floor (its ends not judged), its axis at the height it
lies at -- the cell lays it down before the pivot. Rendered in the twin, scored against its
state; a strip of the duct's own top is no part."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.layout import CellLayout
from drivers.pose import Pose
from sim.camera import SimCamera, default_tool_T_camera
from sim.cell_layout import build_cell
from sim.part_body import lying_pose, spawn_part
from sim.scenes import look_down_pose
from sim.world import SimWorld
from skills.perception.bin_parts import detect_parts

CATALOGUE = load_catalogue()
PARTS = [p for p in CATALOGUE.parts.values() if p.rigid]
LAYOUT = CellLayout()


@pytest.mark.parametrize(("name", "turn"), [("bushing", 0.0), ("medicine_bottle", 90.0)])
def test_a_part_lying_on_a_duct_is_found_at_its_height(name: str, turn: float) -> None:
    duct, part = CATALOGUE.get("wiring_duct"), CATALOGUE.get(name)
    with SimWorld(seed=3) as world:
        build_cell(world, LAYOUT)
        floor = LAYOUT.bin_floor_z
        spawn_part(world, duct, lying_pose(duct, 0.47, 0.0, 0.0, floor))
        over = lying_pose(part, 0.47, 0.0, math.radians(turn), floor)
        top = spawn_part(world, part, Pose(over.position + [0.0, 0.0, duct.outer + 0.001],
                                           over.rotation))
        for _ in range(int(1.0 / world.settings.control_dt)):
            world.step()
        truth = top.pose().position.copy()
        assert truth[2] > floor + duct.outer  # still on the duct
        tool = look_down_pose(LAYOUT.bin_center, 0.5, default_tool_T_camera())
        cam = SimCamera(world, lambda: tool)
        dets = detect_parts(cam.capture(), cam.intrinsics(), tool @ cam.tool_T_camera(), PARTS,
                            LAYOUT.bin_interior())
    on = [d for d in dets if d.part == name]
    assert len(on) == 1, [(d.part, d.center.round(3).tolist()) for d in dets]
    d = on[0]
    assert d.tilted  # off the floor: laid down before the pivot
    if part.open_ends == 1:
        assert not d.open_end_seen  # the end tests assume a part on the floor
    assert float(np.hypot(*(d.center[:2] - truth[:2]))) < 0.004
    assert abs(float(d.center[2]) - float(truth[2])) < 0.003
    # the duct under it is no bushing or bottle, and nothing else is made up
    assert all(d.part in (name, "wiring_duct") for d in dets)
