"""The gripper description: the 2F-85's registers, counts and linkage as the unit has them, and a
description that is not a gripper refused with the key that is wrong."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from drivers.gripper_spec import (
    GripperSpecError,
    default_gripper,
    load_gripper,
    shipped_grippers,
    spec_from_mapping,
)

SHIPPED = Path(__file__).resolve().parents[2] / "drivers" / "data" / "grippers"


def test_the_2f85_grips_with_20_n_at_least_and_its_registers_span_the_range() -> None:
    g = default_gripper()
    assert (g.force_min, g.force_max) == (20.0, 235.0)
    assert g.force_register(20.0) == 0 and g.force_register(235.0) == 255
    assert g.applied_force(2.0) == 20.0  # register 0 is the weakest grip, not zero force
    assert g.applied_force(400.0) == 235.0
    assert g.applied_force(100.0) == pytest.approx(100.0, abs=(215.0 / 255) / 2 + 1e-9)
    assert g.applied_speed(0.001) == pytest.approx(0.020)


def test_the_opening_is_reported_in_position_counts() -> None:
    g = default_gripper()
    assert g.count(g.stroke) == 3 and g.count(0.0) == 228  # nominal open and closed counts
    step = g.count_step
    assert step == pytest.approx(0.085 / 225)
    for width in (0.0102, 0.0333, 0.0611):
        assert abs(g.reported_width(width) - width) <= 0.5 * step + 1e-12
        assert g.reported_width(g.reported_width(width)) == g.reported_width(width)


def test_the_tips_advance_13_mm_from_open_to_closed_along_the_linkage() -> None:
    g = default_gripper()
    assert g.tip_advance(0.0) == pytest.approx(0.0, abs=1e-12)
    travel = g.tip_advance(0.0) - g.tip_advance(g.stroke)
    assert travel == pytest.approx(0.0132, abs=0.0003)
    # closing advances the tips over all but the last 20 mm, where the crank's arc passes its
    # lowest point and turns back by a fraction of a millimetre
    widths = [0.02 + i * (g.stroke - 0.02) / 40 for i in range(41)]
    advances = [g.tip_advance(w) for w in widths]
    assert all(a >= b for a, b in zip(advances, advances[1:], strict=False))
    assert max(g.tip_advance(i * 0.001) for i in range(21)) < 0.0005
    # the Grasp's close, 70.6 -> 61.5 mm, moves them about 2.5 mm
    assert g.tip_advance(0.0615) - g.tip_advance(0.0706) == pytest.approx(0.0025, abs=0.0007)


def test_the_shipped_descriptions_load_and_a_gripper_without_a_linkage_has_no_tip_travel() -> None:
    assert {"robotiq_2f85", "gentle_wire"} <= set(shipped_grippers())
    gentle = load_gripper("gentle_wire")
    assert gentle.force_min == 0.5 and gentle.tip_advance(0.03) == 0.0


def _mapping() -> dict:
    return yaml.safe_load((SHIPPED / "robotiq_2f85.yaml").read_text())


@pytest.mark.parametrize(
    ("change", "key"),
    [
        (lambda d: d.update(stroke_m=-0.01), "stroke"),
        (lambda d: d.update(force_n=[235.0, 20.0]), "force_n"),
        (lambda d: d.update(position_counts=[228, 3]), "position_counts"),
        (lambda d: d["detection"].update(kind="vision"), "detection"),
    ],
)
def test_a_description_that_is_not_a_gripper_names_the_key(change, key) -> None:  # type: ignore[no-untyped-def]
    data = _mapping()
    change(data)
    with pytest.raises(GripperSpecError) as info:
        spec_from_mapping(data)
    assert key in info.value.key


def test_an_unknown_name_lists_the_shipped_ones(tmp_path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(GripperSpecError, match="shipped: .*robotiq_2f85"):
        load_gripper("robotiq_3f")
    with pytest.raises(GripperSpecError):
        load_gripper(tmp_path / "missing.yaml")
