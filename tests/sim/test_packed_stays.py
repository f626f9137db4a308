"""The twin's packing verdict: a packing that moves a part already in the box fails, judged
from where each part stood when its own packing was judged."""

from __future__ import annotations

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from cell.journal import Resume
from drivers.events import EventKind
from drivers.layout import CellLayout
from sim.cell_twin import PACKED_MOVE, SimCellBackend, TwinOptions


@pytest.fixture()
def twin():  # type: ignore[no-untyped-def]
    part = load_catalogue(None).get("bushing")
    backend = SimCellBackend(
        CellLayout(), part, TwinOptions(seed=3, parts_in_bin=2), Resume(filled=[0, 1])
    )
    yield backend
    backend.close()


def _judge_packing_of(twin, body):  # type: ignore[no-untyped-def]
    """The verdict for a packing that ends with the tool over ``body``."""
    twin._tcp = lambda: body.pose().position  # the packing's hand stands over this part
    return twin.judge(EventKind.PACKED, {})


def test_a_packing_that_left_the_others_in_place_is_not_failed_for_moving(twin) -> None:  # type: ignore[no-untyped-def]
    first, second = (b for b in twin.bodies if b.body_id in twin.packed_bodies)
    verdict = _judge_packing_of(twin, second)
    assert verdict["moved_mm"] < 1e3 * PACKED_MOVE
    assert verdict["ok"], verdict["failure"]


def test_a_packing_that_shoved_a_packed_part_fails(twin) -> None:  # type: ignore[no-untyped-def]
    first, second = (b for b in twin.bodies if b.body_id in twin.packed_bodies)
    p = twin.world.p
    position, orientation = p.getBasePositionAndOrientation(first.body_id)
    # the disturbance a careless packing would cause: the first part shoved 5 mm along -x
    p.resetBasePositionAndOrientation(
        first.body_id, np.array(position) - np.array([0.005, 0.0, 0.0]), orientation
    )
    verdict = _judge_packing_of(twin, second)
    assert verdict["moved_mm"] == pytest.approx(5.0, abs=0.3)
    assert not verdict["ok"]
    assert verdict["failure"].startswith(f"part 0 (body {first.body_id}): a packed part moved")


def test_a_place_is_recorded_by_a_good_packing_only_and_forgotten_with_the_part(twin) -> None:  # type: ignore[no-untyped-def]
    first, second = (b for b in twin.bodies if b.body_id in twin.packed_bodies)
    # A good packing records where a part without a place stands.
    del twin.packed_where[second.body_id]
    assert _judge_packing_of(twin, second)["ok"]
    assert np.allclose(twin.packed_where[second.body_id], second.pose().position[:2])
    # A packing judged bad (a part still lying in the bin) records nothing for it.
    in_bin = next(b for b in twin.bodies if b.body_id not in twin.packed_bodies)
    assert not _judge_packing_of(twin, in_bin)["ok"]
    assert in_bin.body_id not in twin.packed_where
    # A part a person takes out is no longer compared.
    twin.remove_part(first)
    assert first.body_id not in twin.packed_where
