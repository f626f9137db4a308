"""The static cell: its layout is validated, it builds, and the machine slot admits the bushing."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from sim.cell_layout import CellLayout, build_cell
from sim.part_body import spawn_part, upright_pose
from sim.world import SimWorld
from skills.mechanics.part import Part

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


def test_from_dict_reads_metres_and_reports_file_key_reason() -> None:
    layout = CellLayout.from_dict(
        {"bin_center": [0.5, 0.0], "slot_clearance": 0.004}, source="cell.yaml"
    )
    assert layout.bin_center == (0.5, 0.0) and layout.slot_clearance == 0.004
    bad = [
        ({"bin_centre": [0.5, 0.0]}, "cell.yaml: bin_centre: unknown key; valid keys: "),
        ({"slot_depth": "deep"}, "cell.yaml: slot_depth: expected a finite number"),
        ({"slot_depth": True}, "cell.yaml: slot_depth: expected a finite number"),
        ({"machine_size": [0.1, 0.1]}, "cell.yaml: machine_size: expected a list of 3 numbers"),
        ({"bin_center": [0.15, 0.35]}, "cell.yaml: bin_center: bin (bin_center"),
        ({"slot_clearance": -0.002}, "cell.yaml: slot_clearance: must be >= 0"),
    ]
    for data, message in bad:
        with pytest.raises(ValueError) as err:
            CellLayout.from_dict(data, source="cell.yaml")
        assert str(err.value).startswith(message), str(err.value)
    with pytest.raises(ValueError, match="cell.yaml: expected a mapping"):
        CellLayout.from_dict([1, 2], source="cell.yaml")  # type: ignore[arg-type]


def test_from_yaml(tmp_path) -> None:
    path = tmp_path / "layout.yaml"
    path.write_text("tray_center: [0.1, -0.5]\n", encoding="utf-8")
    assert CellLayout.from_yaml(path).tray_center == (0.1, -0.5)
    with pytest.raises(ValueError, match="cannot read"):
        CellLayout.from_yaml(tmp_path / "missing.yaml")


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


def test_tray_places_lie_inside_the_tray() -> None:
    layout = CellLayout()
    places = layout.tray_places(3, 2)
    x0, x1, y0, y1 = layout.footprints()["tray"][0]
    assert np.all((places[:, 0] > x0) & (places[:, 0] < x1))
    assert np.all((places[:, 1] > y0) & (places[:, 1] < y1))
    assert np.allclose(places[:, 2], layout.tray_floor_z)


def test_the_default_tray_holds_at_least_ten_bushings_in_reach() -> None:
    """Packing places: >= 10 upright bushings, inside the tray, the hole grasp over
    each (set down 4 mm short of it, fingers down, the outer finger on the -x, -y diagonal)
    within the UR5's reach, at the floor and at the travel height."""
    from sim.arm import REACH_TOLERANCE, solve_ik
    from sim.robot import HOME_JOINTS
    from skills.slot import hold_pose

    layout = CellLayout()
    places = layout.packing_places()
    assert len(places) >= 10
    x0, x1, y0, y1 = layout.tray_interior()
    r = 0.5 * layout.slot_part_outer
    assert np.all((places[:, 0] - r > x0) & (places[:, 0] + r < x1))
    assert np.all((places[:, 1] - r > y0) & (places[:, 1] + r < y1))
    assert places[0, 0] > places[1, 0] and places[0, 1] > places[-1, 1]  # from the +x,+y corner
    bushing = Part("bushing", 0.068, 0.034, 0.028, mass=0.156)
    for place in places:
        for bottom_z in (layout.tray_floor_z - 0.004, 0.13):
            pose = hold_pose(place[:2] - 0.004, bottom_z, bushing, (-1.0, -1.0, 0.0), 0.0134,
                             0.020, 0.005)
            _, residual = solve_ik(pose, HOME_JOINTS, iterations=200)
            assert residual < REACH_TOLERANCE, place
