"""The freest part first: room to the neighbours and the walls, from the detections."""

from __future__ import annotations

import math

import numpy as np

from skills.perception.bin_parts import Detection
from skills.perception.pick_order import clearance, freest_first

ROI = (0.2, 0.7, -0.2, 0.2)


def _det(x: float, y: float, yaw: float = 0.0) -> Detection:
    c = np.array([x, y, 0.017])
    return Detection(c, yaw, 0.068, 0.034, "bushing", c, True, 1.0, 100)


def test_a_part_against_a_wall_or_a_neighbour_has_no_room() -> None:
    lone, wall = _det(0.45, 0.0), _det(0.45, 0.2 - 0.017)
    a, b = _det(0.3, -0.1), _det(0.3, -0.1 + 0.034)  # side by side, touching
    seen = [lone, wall, a, b]
    assert clearance(lone, seen, ROI) > 0.05
    assert abs(clearance(wall, seen, ROI)) < 1e-6
    assert abs(clearance(a, seen, ROI)) < 1e-6
    order = freest_first(seen, seen, ROI)
    assert order[0] is lone


def test_ties_go_to_the_part_nearer_the_robot() -> None:
    near, far = _det(0.35, 0.0, math.pi / 2), _det(0.55, 0.0, math.pi / 2)
    assert freest_first([far, near], [far, near], (0.0, 0.9, -0.5, 0.5))[0] is near
