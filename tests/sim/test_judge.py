"""The judge's hole volume: a pad pressed flat on a rectangular hole's inner wall is in the hole;
a pad on the outer wall, or beyond the open end, is not."""

from __future__ import annotations

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from sim.judge import TOUCH, hook_in_hole
from sim.part_body import spawn_part, upright_pose
from sim.world import SimWorld


@pytest.fixture(scope="module")
def duct():
    part = load_catalogue(None).get("wiring_duct")  # rectangular hole, 1.5 mm walls
    with SimWorld(seed=1) as world:
        body = spawn_part(world, part, upright_pose(part, 0.5, 0.0, 0.0))
        yield part, body


def _at(body, local: list[float]) -> np.ndarray:
    return body.pose().transform(np.asarray(local, float))


def test_pad_on_the_inner_wall_counts_as_in_the_hole(duct) -> None:
    part, body = duct
    half = 0.5 * part.hole
    depth = 0.02
    x = 0.5 * part.length - depth  # the part frame's +x runs towards the open end
    for into_wall in (0.0, 0.3 * TOUCH, 0.9 * TOUCH):  # the contact's penetration
        inside, d = hook_in_hole(body, _at(body, [x, half + into_wall, 0.0]))
        assert inside and d == pytest.approx(depth, abs=1e-6)


def test_pad_on_the_outer_wall_or_past_the_end_is_not(duct) -> None:
    part, body = duct
    x = 0.5 * part.length - 0.02
    outer = 0.5 * part.outer
    assert not hook_in_hole(body, _at(body, [x, outer, 0.0]))[0]
    assert not hook_in_hole(body, _at(body, [x, 0.5 * part.hole + 2 * TOUCH, 0.0]))[0]
    inside, depth = hook_in_hole(body, _at(body, [0.5 * part.length + 0.003, 0.0, 0.0]))
    assert not inside and depth < 0


@pytest.mark.parametrize(("name", "tilt"), [("bushing", 0.0), ("medicine_bottle", 180.0)])
def test_a_tube_is_upright_either_end_up_a_bottle_only_open_end_up(name: str, tilt: float) -> None:
    """A tube has two open ends: standing on either, a finger can be in its hole from above."""
    from sim.judge import judge

    part = load_catalogue(None).get(name)
    with SimWorld(seed=1) as world:
        body = spawn_part(world, part, upright_pose(part, 0.5, 0.0, 0.0, open_up=False))
        verdict = judge(world, body, -1, -1, {}, {})
    assert verdict.tilt_deg == pytest.approx(tilt, abs=0.5)
