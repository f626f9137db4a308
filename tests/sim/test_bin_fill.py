"""A bin filled as a person would: parts tipped in from random poses, left where physics
settles them, not staged where the pivot works."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.layout import CellLayout
from sim.cell_twin import SimCellBackend, TwinOptions


@pytest.fixture(scope="module")
def twin():  # type: ignore[no-untyped-def]
    part = load_catalogue(None).get("bushing")
    backend = SimCellBackend(
        CellLayout(), part, TwinOptions(seed=5, parts_in_bin=10, fill="random")
    )
    yield backend
    backend.close()


def test_every_part_tipped_in_lands_in_the_bin(twin) -> None:  # type: ignore[no-untyped-def]
    assert twin.account()["in_bin"] == 10


def test_the_parts_lie_any_way_round(twin) -> None:  # type: ignore[no-untyped-def]
    """Any yaw and either open end towards the robot: not the staged radial rows."""
    axes = [b.axis() for b in twin.bodies]
    radial = []
    for b, a in zip(twin.bodies, axes, strict=True):
        c = b.pose().position
        out = np.array([c[0], c[1]]) / math.hypot(c[0], c[1])
        radial.append(float(a[:2] @ out) / max(1e-9, math.hypot(a[0], a[1])))
    assert min(radial) < -0.3 and max(radial) > 0.3  # open ends both ways
    yaws = sorted(math.degrees(math.atan2(a[1], a[0])) % 180 for a in axes)
    assert yaws[-1] - yaws[0] > 60  # spread, not a row


def test_the_parts_rest_where_physics_left_them(twin) -> None:  # type: ignore[no-untyped-def]
    before = [b.pose().position.copy() for b in twin.bodies]
    for _ in range(60):
        twin.step()
    moved = max(
        float(np.linalg.norm(b.pose().position - p))
        for b, p in zip(twin.bodies, before, strict=True)
    )
    assert moved < 0.002
