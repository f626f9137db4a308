"""The slot and packing judges on states set up directly (parts spawned where a test wants them:
these test the judges, not the skills). Under a second."""

from __future__ import annotations

import pytest

from drivers.layout import CellLayout
from sim.cell_layout import build_cell
from sim.judge import judge_in_slot, judge_packed
from sim.part_body import spawn_part, upright_pose
from sim.robot import SimRobot
from sim.world import SimWorld
from tests.skills.twin import bushing

LAYOUT = CellLayout()


@pytest.fixture
def world():
    with SimWorld(seed=1) as w:
        build_cell(w, LAYOUT)
        w.robot = SimRobot(w)  # type: ignore[attr-defined]
        yield w


def settle(world: SimWorld, seconds: float = 0.5) -> None:
    for _ in range(int(seconds / world.settings.control_dt)):
        world.step()


def test_judge_packed_measures_gaps_and_fails_a_loose_pack(world: SimWorld) -> None:
    part = bushing()
    (x0, x1, y0, y1) = LAYOUT.tray_interior()
    r = 0.5 * part.outer
    a = spawn_part(world, part, upright_pose(part, x1 - r - 0.0005, y1 - r - 0.0005, 0.005))
    b = spawn_part(world, part, upright_pose(part, x1 - 3 * r - 0.0055, y1 - r - 0.0005, 0.005))
    settle(world)
    v = judge_packed(world, [a, b], LAYOUT.tray_interior(), LAYOUT.tray_floor_z,
                     world.robot.body_id)  # type: ignore[attr-defined]
    assert not v.success and "from part" in (v.failure or "")
    # 5 mm between the flats (the 12-gon's corners can come ~0.6 mm closer, depending on turn)
    assert 0.0035 < v.max_neighbour_gap_m < 0.0055
    assert v.parts[0].home["+x"] < 0.002
    loose = judge_packed(world, [a, b], LAYOUT.tray_interior(), LAYOUT.tray_floor_z,
                         world.robot.body_id, max_gap=0.006)  # type: ignore[attr-defined]
    assert loose.success, loose.failure


def test_judge_in_slot_fails_a_part_standing_beside_the_slot(world: SimWorld) -> None:
    part = bushing()
    sx, sy, _ = LAYOUT.slot_center
    on_top = spawn_part(world, part, upright_pose(part, sx + 0.045, sy, LAYOUT.machine_top_z))
    settle(world)
    v = judge_in_slot(world, on_top, LAYOUT.slot_center, LAYOUT.slot_width,
                      world.robot.body_id)  # type: ignore[attr-defined]
    assert not v.success and "not in the slot" in (v.failure or "")
