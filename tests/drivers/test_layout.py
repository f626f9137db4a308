"""The cell's layout as a description (no simulator): reading it from data, the errors that
name the key, the tray's places and their reach. Building it in the twin: tests/sim."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.layout import CellLayout
from drivers.parts import Part


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
    from drivers.ur5.kinematics import HOME_JOINTS, REACH_TOLERANCE, solve_ik
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
