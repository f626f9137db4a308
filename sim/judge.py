"""Judging a pivot from the simulated state only, never from the plan (issue 4, item 4).

After the lift the trial succeeds when the part's axis is within 10 deg of vertical with its open
end up, no point of it touches the floor or it is clearly above it, it touches the fingers, and a
fingertip lies inside its hole.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.part_body import PartBody, hull_vertices


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


# ------------------------------------------------------------------ slot and packing judges
def _tilt_deg(part_body: PartBody) -> float:
    """Angle (deg) of the part's axis from vertical, either end up."""
    return math.degrees(math.acos(min(1.0, abs(float(part_body.axis()[2])))))


def _touching(world, a: int, b: int) -> bool:  # type: ignore[no-untyped-def]
    return len(world.p.getContactPoints(bodyA=a, bodyB=b)) > 0


@dataclass(frozen=True)
class SlotVerdict:
    """The part in the machine's slot, from the simulated state (m, deg)."""

    success: bool
    failure: str | None
    tilt_deg: float  #: axis from vertical
    offset_m: float  #: horizontal distance of the part's bottom centre from the slot's centre
    bottom_m: float  #: lowest point of the part above the slot floor
    held: bool  #: touching the gripper


def judge_in_slot(
    world,  # type: ignore[no-untyped-def]
    part_body: PartBody,
    slot_center: np.ndarray,
    slot_width: float,
    gripper_body: int,
    max_tilt_deg: float = 10.0,
    floor_tolerance: float = 0.002,
) -> SlotVerdict:
    """Judge a part fed into the slot: upright, its bottom inside the pocket's square
    (``slot_width`` m, centred on ``slot_center``, the pocket floor's centre), resting on the
    floor (lowest point within ``floor_tolerance`` m of it) and not touching the gripper."""
    tilt = _tilt_deg(part_body)
    bottom = part_body.closed_end_center() if part_body.axis()[2] > 0 else (
        part_body.open_end_center()
    )
    centre = np.asarray(slot_center, float)
    d = bottom[:2] - centre[:2]
    height = part_body.lowest_z() - float(centre[2])
    held = _touching(world, part_body.body_id, gripper_body)
    half_free = 0.5 * (slot_width - part_body.part.outer)
    if held:
        failure = "still held by the gripper"
    elif float(np.max(np.abs(d))) > half_free + 1e-3 or height > 0.5 * part_body.part.length:
        failure = (
            f"not in the slot: bottom {1e3 * float(np.linalg.norm(d)):.1f} mm from its centre, "
            f"{1e3 * height:.1f} mm above its floor"
        )
    elif tilt > max_tilt_deg:
        failure = f"not upright: axis {tilt:.1f} deg from vertical"
    elif height > floor_tolerance:
        failure = f"not on the slot floor: {1e3 * height:.1f} mm above it"
    else:
        failure = None
    return SlotVerdict(failure is None, failure, tilt, float(np.linalg.norm(d)), height, held)


@dataclass(frozen=True)
class PackedPart:
    """One packed part: tilt (deg), lowest point above the tray floor (m), gaps (m) to each
    tray wall (keys ``+x``, ``-x``, ``+y``, ``-y``) and to each neighbour (by index)."""

    index: int
    center: tuple[float, float]
    tilt_deg: float
    height_m: float
    wall_gaps: dict[str, float]
    neighbour_gaps: dict[int, float]
    home: dict[str, float]  #: gap (m) on the +x and +y sides to whatever stops it there


@dataclass(frozen=True)
class PackVerdict:
    success: bool
    failure: str | None
    parts: list[PackedPart]
    max_neighbour_gap_m: float  #: largest gap between adjacent packed parts (0 for one part)
    max_home_gap_m: float  #: largest gap on a part's +x / +y side to a wall or a neighbour


def judge_packed(
    world,  # type: ignore[no-untyped-def]
    part_bodies: list[PartBody],
    tray_roi: tuple[float, float, float, float],
    tray_floor_z: float,
    gripper_body: int,
    max_gap: float = 0.002,
    max_tilt_deg: float = 5.0,
    floor_tolerance: float = 0.002,
) -> PackVerdict:
    """Judge parts packed in the tray, from the simulated state.

    ``tray_roi``: ``(xmin, xmax, ymin, ymax)`` of the tray's inside (m). Each part must stand
    upright (within ``max_tilt_deg``) on the tray floor (lowest point within ``floor_tolerance``),
    inside the tray, free of the gripper. Gaps are true shortest distances: between two parts
    PyBullet's closest points of their collision shapes, to a wall the envelope's vertices.
    Parts are neighbours when their axes are closer than 1.25 outer diameters (adjacent, not
    diagonal). Packed tight means: every pair of neighbours within ``max_gap``, and every part
    within ``max_gap`` of a wall or a neighbour on its ``+x`` and on its ``+y`` side (the sides
    it was pushed towards).
    """
    p = world.p
    x0, x1, y0, y1 = tray_roi
    centres = [b.pose().position[:2] for b in part_bodies]
    parts: list[PackedPart] = []
    failure: str | None = None
    max_pair, max_home = 0.0, 0.0
    for i, body in enumerate(part_bodies):
        hull = body.pose().transform(hull_vertices(body.part, body.staves))
        walls = {
            "+x": float(x1 - hull[:, 0].max()),
            "-x": float(hull[:, 0].min() - x0),
            "+y": float(y1 - hull[:, 1].max()),
            "-y": float(hull[:, 1].min() - y0),
        }
        neighbours: dict[int, float] = {}
        for j, other in enumerate(part_bodies):
            if j == i or np.linalg.norm(centres[j] - centres[i]) > 1.25 * other.part.outer:
                continue
            pts = p.getClosestPoints(body.body_id, other.body_id, distance=0.05)
            neighbours[j] = float(min(pt[8] for pt in pts)) if pts else 0.05
        home = {"+x": walls["+x"], "+y": walls["+y"]}
        for j, gap in neighbours.items():
            dx, dy = centres[j] - centres[i]
            side = "+x" if abs(dx) >= abs(dy) and dx > 0 else "+y" if dy > abs(dx) else None
            if side is not None:
                home[side] = min(home[side], gap)
        tilt = _tilt_deg(body)
        height = body.lowest_z() - tray_floor_z
        parts.append(
            PackedPart(i, (float(centres[i][0]), float(centres[i][1])), tilt, height, walls,
                       neighbours, home)
        )
        max_pair = max([max_pair, *neighbours.values()])
        max_home = max(max_home, *home.values())
        if failure is not None:
            continue
        if _touching(world, body.body_id, gripper_body):
            failure = f"part {i}: still held by the gripper"
        elif min(walls.values()) < -0.001 or height > 0.5 * body.part.length:
            failure = f"part {i}: not in the tray"
        elif tilt > max_tilt_deg:
            failure = f"part {i}: not upright: axis {tilt:.1f} deg from vertical"
        elif height > floor_tolerance:
            failure = f"part {i}: not on the tray floor: {1e3 * height:.1f} mm above it"
        elif any(g > max_gap for g in neighbours.values()):
            j, g = max(neighbours.items(), key=lambda kv: kv[1])
            failure = f"part {i}: {1e3 * g:.1f} mm from part {j} (max {1e3 * max_gap:.1f} mm)"
        elif any(g > max_gap for g in home.values()):
            side, g = max(home.items(), key=lambda kv: kv[1])
            failure = (
                f"part {i}: not pushed home: {1e3 * g:.1f} mm free on its {side} side "
                f"(max {1e3 * max_gap:.1f} mm)"
            )
    return PackVerdict(failure is None, failure, parts, max_pair, max_home)
