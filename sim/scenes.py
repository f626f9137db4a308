"""Random bin scenes for perception: parts lying on the bin floor, some touching, and the wrist
camera's view of them. Ground truth is returned for *scoring only*; nothing here reaches a skill.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from drivers.layout import CellLayout
from drivers.parts import Part
from drivers.pose import Pose
from sim.part_body import PartBody, lying_pose, spawn_part
from sim.world import SimWorld

#: Tool pointing straight down (tool z = -world z): the wrist camera then looks down too.
DOWN = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class PartTruth:
    """Where a spawned part really is (m, rad; world = robot base frame)."""

    name: str
    center: NDArray[np.float64]  #: part centre
    yaw: float  #: direction of the part's +x axis (towards its open end), in (-pi, pi]
    open_end: NDArray[np.float64]  #: centre of the +x end face
    body: int


def _footprint(part: Part, x: float, y: float, yaw: float, margin: float) -> NDArray[np.float64]:
    c, s = math.cos(yaw), math.sin(yaw)
    hl, hw = 0.5 * part.length + margin, 0.5 * part.outer + margin
    corners = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]])
    return corners @ np.array([[c, s], [-s, c]]) + [x, y]


def _overlap(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """Separating-axis test of two convex quadrilaterals (corners in order)."""
    for poly in (a, b):
        for i in range(4):
            edge = poly[(i + 1) % 4] - poly[i]
            n = np.array([-edge[1], edge[0]])
            pa, pb = a @ n, b @ n
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def random_bin_scene(
    world: SimWorld,
    layout: CellLayout,
    parts: list[Part],
    rng: np.random.Generator,
    n_parts: int,
    touching: float = 0.4,
    wall_margin: float = 0.02,
    settle_s: float = 0.6,
) -> list[tuple[PartBody, PartTruth]]:
    """Spawn ``n_parts`` parts drawn from ``parts`` lying in the bin at random poses; with
    probability ``touching`` a part is laid side by side against one already there. Lets them
    settle, then reports where they really are."""
    x0, x1, y0, y1 = layout.bin_interior()
    placed: list[tuple[Part, float, float, float]] = []
    shapes: list[NDArray[np.float64]] = []
    for _ in range(n_parts):
        part = parts[int(rng.integers(len(parts)))]
        for _attempt in range(200):
            if placed and rng.random() < touching:
                other, ox, oy, oyaw = placed[int(rng.integers(len(placed)))]
                side = 1.0 if rng.random() < 0.5 else -1.0
                gap = 0.5 * (part.outer + other.outer) + 0.0005
                n = np.array([-math.sin(oyaw), math.cos(oyaw)])
                slide = rng.uniform(-0.3, 0.3) * other.length
                x = ox + side * gap * n[0] + slide * math.cos(oyaw)
                y = oy + side * gap * n[1] + slide * math.sin(oyaw)
                yaw = oyaw + (math.pi if rng.random() < 0.5 else 0.0)
            else:
                x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
                yaw = rng.uniform(-math.pi, math.pi)
            box = _footprint(part, x, y, yaw, 0.0)
            inside = (
                box[:, 0].min() > x0 + wall_margin
                and box[:, 0].max() < x1 - wall_margin
                and box[:, 1].min() > y0 + wall_margin
                and box[:, 1].max() < y1 - wall_margin
            )
            shrunk = _footprint(part, x, y, yaw, -0.0003)
            if inside and not any(_overlap(shrunk, s) for s in shapes):
                placed.append((part, x, y, yaw))
                shapes.append(box)
                break
    bodies = [
        spawn_part(world, part, lying_pose(part, x, y, yaw, layout.bin_floor_z))
        for part, x, y, yaw in placed
    ]
    for _ in range(int(settle_s / world.settings.control_dt)):
        world.step()
    out = []
    for (part, *_), body in zip(placed, bodies, strict=True):
        axis = body.axis()
        out.append(
            (
                body,
                PartTruth(
                    name=part.name,
                    center=body.pose().position.copy(),
                    yaw=math.atan2(axis[1], axis[0]),
                    open_end=body.open_end_center(),
                    body=body.body_id,
                ),
            )
        )
    return out


def look_down_pose(
    target_xy: NDArray[np.float64] | tuple[float, float],
    height: float,
    tool_T_camera: Pose,
) -> Pose:
    """Tool pose (tool pointing down) that puts the camera's optical centre ``height`` (m) above
    ``target_xy`` on the floor."""
    offset = DOWN @ tool_T_camera.position
    return Pose(np.array([target_xy[0], target_xy[1], height]) - offset, DOWN)


def random_floor_pose(
    layout: CellLayout, part: Part, rng: np.random.Generator, wall_gap: float = 0.001
) -> tuple[float, float, float]:
    """A lying part's centre and yaw drawn uniformly over the bin floor: any yaw, either end
    towards the robot, anywhere its footprint at that yaw fits (up against a wall included)."""
    x0, x1, y0, y1 = layout.bin_interior()
    yaw = rng.uniform(-math.pi, math.pi)
    hx = 0.5 * (part.length * abs(math.cos(yaw)) + part.outer * abs(math.sin(yaw))) + wall_gap
    hy = 0.5 * (part.length * abs(math.sin(yaw)) + part.outer * abs(math.cos(yaw))) + wall_gap
    return rng.uniform(x0 + hx, x1 - hx), rng.uniform(y0 + hy, y1 - hy), yaw


def dropped_bin_fill(
    world: SimWorld,
    layout: CellLayout,
    part: Part | Sequence[Part],
    rng: np.random.Generator,
    n_parts: int,
    spawn: Callable[[Pose], PartBody] | Callable[[Part, Pose], PartBody],
    drop_height: float = 0.04,
    wall_margin: float = 0.005,
    settle_s: float = 1.5,
) -> list[PartBody]:
    """A bin filled as a person tips parts into it: each part released at a random orientation
    (any yaw, either end first, any roll) a little above the floor or the parts already there,
    one after the other, then left to settle. Where they end -- against walls, touching or
    leaning on a neighbour -- is physics' answer, not a staged pose.

    ``part``: one kind, or several, one drawn at random for each drop (a mixed bin); ``spawn``
    creates one part at a pose (the caller's body options: friction, sleeping), and for a
    mixed bin is called with the kind first.
    """
    mixed = not isinstance(part, Part)
    kinds = list(part) if mixed else [part]  # type: ignore[arg-type]
    bodies: list[PartBody] = []
    for _ in range(n_parts):
        kind = kinds[int(rng.integers(len(kinds)))] if mixed else kinds[0]
        half_diag = 0.5 * math.hypot(kind.length, kind.outer)
        x, y, yaw = random_floor_pose(layout, kind, rng, wall_margin)
        tilt = rng.uniform(-0.35, 0.35)  # rad off horizontal: one end leads the fall
        roll = rng.uniform(-math.pi, math.pi)
        rotation = (
            Rotation.from_euler("z", yaw)
            * Rotation.from_euler("y", tilt)
            * Rotation.from_euler("x", roll)
        ).as_matrix()
        tops = [b.pose().position[2] + 0.5 * b.part.outer for b in bodies]
        top = max([layout.bin_floor_z, *tops])
        z = top + drop_height + half_diag
        pose = Pose(np.array([x, y, z]), rotation)
        bodies.append(spawn(kind, pose) if mixed else spawn(pose))  # type: ignore[call-arg]
        for _ in range(int(0.25 / world.settings.control_dt)):  # it lands before the next
            world.step()
    for _ in range(int(settle_s / world.settings.control_dt)):
        world.step()
    return bodies


@dataclass(frozen=True)
class Situation:
    """How a settled part lies, from the simulated contacts (for splitting scores only)."""

    tilt: float  #: rad, of the part's axis from the floor plane
    touching: bool  #: in contact with another part
    wall: bool  #: in contact with the bin's walls
    in_bin: bool  #: its centre over the bin's inside
    raised: float  #: m, its lowest point above the bin floor (0 lying on the floor)

    @property
    def standing(self) -> bool:
        """On an end: not a lying part (nothing in the pick works on it)."""
        return self.tilt > math.radians(45.0)

    @property
    def leaning(self) -> bool:
        """Lying, but an end raised (on a neighbour, a wall, or one part's rim on another)."""
        return math.radians(4.0) < self.tilt <= math.radians(45.0)

    def label(self) -> str:
        """One word: standing, leaning, on_top (level, on other parts), touching, wall (alone
        against a wall) or free."""
        if not self.in_bin:
            return "outside"
        if self.standing:
            return "standing"
        if self.leaning:
            return "leaning"
        if self.raised > 0.003:
            return "on_top"  # lying level on other parts
        if self.touching:
            return "touching"
        return "wall" if self.wall else "free"


def situation(
    world: SimWorld,
    body: PartBody,
    others: Sequence[PartBody],
    wall_body: int,
    layout: CellLayout,
    reach: float = 0.001,
) -> Situation:
    """Where ``body`` lies: its axis' tilt, and whether it touches another part or the walls
    (closest points within ``reach``, m)."""
    p = world.p
    axis = body.axis()
    tilt = math.asin(min(1.0, abs(float(axis[2])) / max(float(np.linalg.norm(axis)), 1e-12)))
    touching = any(
        p.getClosestPoints(body.body_id, o.body_id, reach) for o in others if o is not body
    )
    wall = bool(p.getClosestPoints(body.body_id, wall_body, reach))
    x0, x1, y0, y1 = layout.bin_interior()
    c = body.pose().position
    lo, _ = p.getAABB(body.body_id)
    return Situation(
        tilt,
        touching,
        wall,
        bool(x0 < c[0] < x1 and y0 < c[1] < y1),
        max(0.0, float(lo[2]) - layout.bin_floor_z),
    )
