"""PackInBox in the twin, judged from the simulated state.

Two bushings stand in the bin. The first goes the whole way of the cell's cycle -- Align (hole
grasp by physics, found by the wrist camera), FeedSlot, PickFromSlot -- and is packed into the
tray's first place; the second is aligned and packed into the second place, pushed against the
first. The judge measures the gaps with PyBullet's closest points. About 6 s of wall time.
"""

from __future__ import annotations

import pytest

from sim.judge import judge_packed
from skills.packing import PackInBox
from skills.slot import FeedSlot, PickFromSlot
from tests.skills.twin import BIN_SPOTS, make_twin, take_hole_grasp

SEED = 5


@pytest.fixture(scope="module")
def packed() -> dict:
    tw = make_twin(SEED, spots=BIN_SPOTS)
    try:
        L = tw.layout
        places = L.packing_places()
        out: dict = {"steps": []}

        def step(name: str, failure: str | None) -> None:
            out["steps"].append((name, failure))
            assert failure is None, f"{name}: {failure}"

        step("align 1", take_hole_grasp(tw, BIN_SPOTS[0]))
        step("feed", tw.run(FeedSlot(L.slot_center, tw.part, tw.dev), 30.0))
        step("pick", tw.run(PickFromSlot(L.slot_center, tw.part, tw.dev), 30.0))
        first = PackInBox(places[0], tw.part, tw.dev)
        step("pack 1", tw.run(first, 40.0))
        tw.settle(0.3)
        out["one"] = judge_packed(tw.world, tw.bodies[:1], L.tray_interior(), L.tray_floor_z,
                                  tw.robot.body_id)
        step("align 2", take_hole_grasp(tw, BIN_SPOTS[1]))
        second = PackInBox(places[1], tw.part, tw.dev)
        step("pack 2", tw.run(second, 40.0))
        tw.settle(0.5)
        out["two"] = judge_packed(tw.world, tw.bodies, L.tray_interior(), L.tray_floor_z,
                                  tw.robot.body_id)
        out["skills"] = (first, second)
        return out
    finally:
        tw.close()


def test_the_first_part_is_pushed_into_the_corner(packed: dict) -> None:
    v = packed["one"]
    assert v.success, v.failure
    part = v.parts[0]
    assert part.tilt_deg < 2.0 and abs(part.height_m) < 0.001
    assert part.wall_gaps["+x"] <= 0.002 and part.wall_gaps["+y"] <= 0.002
    assert set(packed["skills"][0].contacts) == {"floor", "+x", "+y"}


def test_the_second_part_is_packed_against_the_first_within_2_mm(packed: dict) -> None:
    v = packed["two"]
    assert v.success, v.failure
    assert len(v.parts) == 2
    assert v.max_neighbour_gap_m <= 0.002
    assert v.max_home_gap_m <= 0.002
    second = v.parts[1]
    assert 1 in v.parts[0].neighbour_gaps and second.neighbour_gaps[0] <= 0.002
    assert second.wall_gaps["+y"] <= 0.002
    # the first part was not pushed out of its corner by the second, along either wall
    assert v.parts[0].wall_gaps["+x"] <= 0.002
    assert v.parts[0].wall_gaps["+y"] <= 0.002
