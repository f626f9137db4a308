"""Judging a pivot from the simulated state only, never from the plan (issue 4, item 4).

After the lift the trial succeeds when the part's axis is within 10 deg of vertical with its open
end up, no point of it touches the floor or it is clearly above it, it touches the fingers, and a
fingertip lies inside its hole.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.part_body import PartBody


@dataclass(frozen=True)
class Verdict:
    success: bool
    failure: str | None
    tilt_deg: float
    height_m: float
    held: bool
    finger_in_hole: str | None


def finger_in_hole(part_body: PartBody, tip: np.ndarray, margin: float = 0.0) -> bool:
    """Whether the world point ``tip`` lies inside the part's hole (part frame test)."""
    part = part_body.part
    local = part_body.pose().inverse().transform(tip)
    if abs(local[0]) > 0.5 * part.length:
        return False
    r = 0.5 * part.hole - margin
    if part.hole_shape == "circle":
        return math.hypot(local[1], local[2]) < r
    return abs(local[1]) < r and abs(local[2]) < r


def judge(
    world,
    part_body: PartBody,
    floor_id: int,
    gripper_body: int,
    finger_links: dict[str, int],
    finger_tips: dict[str, np.ndarray],
    floor_z: float = 0.0,
    max_tilt_deg: float = 10.0,
    min_height: float = 0.01,
) -> Verdict:
    """Judge the hole grasp. ``finger_tips``: world positions of each fingertip centre."""
    p = world.p
    axis = part_body.axis()
    tilt = math.degrees(math.acos(float(np.clip(axis[2], -1.0, 1.0))))
    height = part_body.lowest_z() - floor_z
    on_floor = len(p.getContactPoints(bodyA=part_body.body_id, bodyB=floor_id)) > 0
    held_by = [
        name
        for name, link in finger_links.items()
        if p.getContactPoints(bodyA=part_body.body_id, bodyB=gripper_body, linkIndexB=link)
    ]
    inside = [name for name, tip in finger_tips.items() if finger_in_hole(part_body, tip)]
    if on_floor or height < min_height:
        failure = "on the floor after the lift" if not held_by else "not lifted off the floor"
    elif not held_by:
        failure = "not held"
    elif tilt > max_tilt_deg:
        failure = f"not upright: axis {tilt:.1f} deg from vertical"
    elif not inside:
        failure = "no finger inside the hole"
    else:
        failure = None
    return Verdict(
        success=failure is None,
        failure=failure,
        tilt_deg=tilt,
        height_m=height,
        held=bool(held_by),
        finger_in_hole=inside[0] if inside else None,
    )
