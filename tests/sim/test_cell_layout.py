"""The static cell: its layout is validated, it builds, and the machine slot admits the bushing."""

from __future__ import annotations

import dataclasses
import math

import pytest

from cell.catalogue import load_catalogue
from drivers.layout import CellLayout
from drivers.parts import Part
from sim.cell_layout import build_cell
from sim.part_body import spawn_part, upright_pose
from sim.world import SimWorld

BUSHING = load_catalogue().get("bushing")


def test_default_layout_validates_and_builds() -> None:
    layout = CellLayout().validate()
    assert layout.slot_width == pytest.approx(BUSHING.outer + 0.005)
    with SimWorld() as world:
        bodies = build_cell(world, layout, floor_friction=0.4)
        p = world.p
        assert len(set(bodies.all())) == 4
        for body in bodies.all():
            assert p.getDynamicsInfo(body, -1)[0] == 0.0  # static
        assert p.getDynamicsInfo(bodies.floor, -1)[1] == pytest.approx(0.4)
        assert p.getAABB(bodies.floor)[1][2] == pytest.approx(0.0, abs=1e-3)
        (x0, y0, _), (x1, y1, z1) = p.getAABB(bodies.bin)
        bx0, bx1, by0, by1 = layout.footprints()["bin"][0]
        assert (x0, x1, y0, y1) == pytest.approx((bx0, bx1, by0, by1), abs=2e-3)
        assert z1 == pytest.approx(layout.bin_wall_height, abs=2e-3)
        assert p.getAABB(bodies.machine)[1][2] == pytest.approx(layout.machine_top_z, abs=2e-3)
    assert layout.tray_places().shape == (6, 3)
    ix0, ix1, iy0, iy1 = layout.bin_interior()
    assert (ix1 - ix0, iy1 - iy0) == pytest.approx(layout.bin_inner_size)


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"bin_center": (0.15, 0.35)}, ("bin_center", "machine_center")),
        ({"tray_center": (0.10, 0.40)}, ("machine_center", "tray_center")),
        ({"slot_clearance": -0.001}, ("slot_clearance",)),
        ({"bin_wall_height": 0.0}, ("bin_wall_height",)),
        ({"machine_size": (0.04, 0.16, 0.10)}, ("machine_size",)),
        ({"slot_depth": 0.2}, ("slot_depth",)),
        ({"bin_center": (0.95, 0.0)}, ("bin_center", "floor_size")),
        ({"machine_center": (0.0, 0.05)}, ("machine_center", "robot_keepout_radius")),
    ],
)
def test_a_bad_layout_is_refused_naming_the_fields(change: dict, named: tuple[str, ...]) -> None:
    layout = dataclasses.replace(CellLayout(), **change)
    with pytest.raises(ValueError) as err:
        layout.validate()
    for key in named:
        assert key in str(err.value)
    with SimWorld() as world, pytest.raises(ValueError):
        build_cell(world, layout, floor_friction=0.4)


def _drop_into_slot(part: Part, layout: CellLayout) -> tuple[float, float]:
    """Drop ``part`` upright from 5 mm above the slot; return its lowest z and tilt after 1 s."""
    with SimWorld(seed=2) as world:
        build_cell(world, layout, floor_friction=0.4)
        x, y = layout.machine_center
        body = spawn_part(world, part, upright_pose(part, x, y, layout.machine_top_z + 0.005))
        for _ in range(125):
            world.step()
        return body.lowest_z(), body.tilt()


def test_the_bushing_drops_into_the_slot() -> None:
    layout = CellLayout()
    lowest, tilt = _drop_into_slot(BUSHING, layout)
    assert lowest < layout.machine_top_z - 0.03
    assert lowest == pytest.approx(layout.slot_floor_z, abs=0.002)
    assert tilt > math.radians(80)


@pytest.mark.parametrize(
    ("excess", "sink"),
    [
        (0.001, 0.010),  # 1 mm too wide: it may tip and wedge a few mm into the rim, no deeper
        (0.006, 0.001),  # 6 mm too wide: it stands on the top
    ],
)
def test_a_part_wider_than_the_slot_does_not_fit(excess: float, sink: float) -> None:
    layout = CellLayout()
    outer = layout.slot_width + excess
    wide = Part("wide", BUSHING.length, outer, outer - 0.006, mass=BUSHING.mass)
    lowest, _ = _drop_into_slot(wide, layout)
    assert lowest > layout.machine_top_z - sink
