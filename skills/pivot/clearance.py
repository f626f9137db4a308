"""Will the pivot's gripper clear the bin's walls and the neighbours? Which end to pivot from?

A part lying where physics left it may have a wall or a neighbour where the Grasp puts the palm
(beyond the open end, tilted by alpha) or where the Tilt carries it (over the pivot end, up to
upright). In the twin, most pivots from a random pose that the FT guard stopped had the gripper
body or a finger on a wall's top edge, not a problem of the mechanics. Before the first motion,
this module sweeps a box model of the tool (fingers at the planned opening, the 2F-85's body,
the FT300 puck, the wrist) along the Grasp's approach and the Tilt's arc and tests it against
the walls (from the cell's configured layout) and the neighbours (from the cell's own
detections), never against the simulator's truth.

For a tube (two open ends) both ends are tried and the one with the larger clearance is
pivoted from; for a part with one open end only that end exists. When neither clears, the
caller passes the part over (or moves it) and says what was in the way.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.pose import Pose
from drivers.tool import FINGER_LENGTH, FT_HEIGHT, FT_RADIUS, GRIPPER_BODY_SIZE, WRIST_SIZE
from skills.axes import XY, Z
from skills.mechanics.contact import HALF_PI
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams

#: The arm's reach, as the cell's arm has it: given TCP poses in the order the arm passes them
#: (each solved from the one before, starting at the arm's home), the index of the first it
#: cannot reach, or None when it reaches them all. The cell builds it from its arm's kinematics;
#: skills know no particular arm.
Reach = Callable[[Sequence[Pose]], int | None]

#: The tool above the fingers, as boxes in the TCP frame (x: closing axis, z: along the
#: fingers, origin at the TCP, the fingertips ``tip_offset`` below it): (centre, half sizes).
_FINGER_TOP = -FINGER_LENGTH  # relative to the fingertips
_BODY = GRIPPER_BODY_SIZE  #: the 2F-85's body, x along the closing axis
_PUCK = (2.0 * FT_RADIUS, 2.0 * FT_RADIUS, FT_HEIGHT)  #: the FT300, its cylinder's bounding box
_WRIST = WRIST_SIZE  #: the UR5's wrist 3 and the end of wrist 2 above the flange

# How finely the tool model and its sweep are sampled: a point model tested at poses, so an
# obstacle's edge can slip between two points by up to about one step; the clearance margin
# (``clearance_margin``, 6 mm by default) is larger than the fingers' step.
#: m between neighbouring surface points of a finger's box: the fingers come nearest the walls
#: and the neighbours, so they are sampled finest
FINGER_STEP = 0.005
#: m between surface points of the gripper body's box: larger, and it meets only a wall's top
BODY_STEP = 0.01
#: m between surface points of the FT300's and the wrist's boxes: the largest, highest boxes
WRIST_STEP = 0.012
#: m, how near a grid point must lie to a face of its box to count as on it: rounding only
FACE_TOL = 1e-12
#: Poses of the straight move down from ``approach_height`` above the pre-approach pose to it,
#: both ends included (2 cm apart with the default 0.10 m)
DESCENT_POSES = 6
#: Poses of the approach at alpha from the pre-approach pose to the grasp, the first (the
#: pre-approach pose, already checked) dropped (1.5 cm apart with the default 0.06 m)
APPROACH_POSES = 5
#: Angles of the Tilt's arc, 0 to its end, the first (the grasp) dropped: 15 steps of at most 6
#: deg, about 3 cm of travel at the fingertips for a 0.3 m radius
ARC_POSES = 16
#: The phase of the sweep's approach at alpha, whose last pose is the grasp
AT_ALPHA = "on the approach at alpha"
#: The phase of the part's own sweep: turning about G, it stands on its base end, which swings
#: back beyond G by up to its height (a cookie can's 90 mm)
STANDING_UP = "standing up"
#: Angles of the part's turn about G, 0 to upright (10 deg apart)
STAND_POSES = 10
#: Points along the part's axis (from G) and across it (each way) of its box in the sweep
STAND_ALONG, STAND_ACROSS = 5, 3
#: m, the thinnest a bin wall is modelled, its inside face where it is and the rest outward:
#: the tool's model is points on its boxes' faces, as far apart as ``WRIST_STEP``, and a wall
#: thinner than that can pass between two of them unseen. (A drag planned the 2F-85's body
#: down over the 5 mm +x wall's top, its outer finger 0.7 mm outside the wall: 273 N in the
#: twin, seed 20601.) Outside the bin nothing is planned to go below its walls' top.
MIN_WALL_THICKNESS = WRIST_STEP


@dataclass(frozen=True)
class Obstacle:
    """A box in the world (m): centre, half sizes along its own axes, yaw of its x axis."""

    what: str
    center: NDArray[np.float64]
    half: NDArray[np.float64]
    yaw: float = 0.0

    def distance(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Signed distance (m) of each point to the box: negative inside."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        d = points - self.center
        local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, Z]])
        q = np.abs(local) - self.half
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(np.max(q, axis=1), 0.0)
        return outside + inside


def bin_walls(
    interior: tuple[float, float, float, float],
    floor_z: float,
    wall_height: float,
    wall_thickness: float,
) -> list[Obstacle]:
    """The bin's four walls around its free inside ``(xmin, xmax, ymin, ymax)``."""
    x0, x1, y0, y1 = interior
    t, h = max(wall_thickness, MIN_WALL_THICKNESS), wall_height
    ht, hh = 0.5 * t, 0.5 * h  # exact: a wall box's half sizes
    zc = floor_z + hh
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)  # exact: the middle of the inside
    hx, hy = 0.5 * (x1 - x0) + t, 0.5 * (y1 - y0) + t  # exact: half the inside and a wall
    return [
        Obstacle("the bin's -x wall", np.array([x0 - ht, cy, zc]), np.array([ht, hy, hh])),
        Obstacle("the bin's +x wall", np.array([x1 + ht, cy, zc]), np.array([ht, hy, hh])),
        Obstacle("the bin's -y wall", np.array([cx, y0 - ht, zc]), np.array([hx, ht, hh])),
        Obstacle("the bin's +y wall", np.array([cx, y1 + ht, zc]), np.array([hx, ht, hh])),
    ]


def lying_part(
    what: str, center_xy: Sequence[float], yaw: float, length: float, outer: float, floor_z: float
) -> Obstacle:
    """A neighbour lying on the floor, as the cell saw it: its footprint up to its diameter."""
    radius, half_length = 0.5 * outer, 0.5 * length  # exact: halves of the diameter, length
    return Obstacle(
        what,
        np.array([float(center_xy[0]), float(center_xy[1]), floor_z + radius]),
        np.array([half_length, radius, radius]),
        yaw,
    )


def standing_part(
    what: str, center_xy: Sequence[float], outer: float, length: float, floor_z: float
) -> Obstacle:
    """A neighbour standing on an end, as the cell saw it: its outer size across, its length
    high."""
    half_size, half_length = 0.5 * outer, 0.5 * length  # exact: halves of the size, length
    return Obstacle(
        what,
        np.array([float(center_xy[0]), float(center_xy[1]), floor_z + half_length]),
        np.array([half_size, half_size, half_length]),
        0.0,
    )


def seen_part(what: str, d: Any, floor_z: float) -> Obstacle:
    """A detection (:class:`skills.perception.bin_parts.Detection`) as an obstacle: lying or
    standing as it was seen."""
    if getattr(d, "standing", False):
        return standing_part(what, d.center, d.outer, d.length, floor_z)
    return lying_part(what, d.center, d.yaw, d.length, d.outer, floor_z)


def _box_points(center: Sequence[float], size: Sequence[float], step: float) -> NDArray:
    """Points on the surface of an axis-aligned box (tool frame), ``step`` apart at most."""
    c, s = np.asarray(center, float), np.asarray(size, float)
    half = 0.5 * s  # exact: the faces lie half the size from the centre
    counts = [max(2, int(math.ceil(n / step)) + 1) for n in s]  # exact: both faces at least
    axes = [np.linspace(-h, h, k) for h, k in zip(half, counts, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    on_face = np.any(np.isclose(np.abs(grid), half, atol=FACE_TOL), axis=1)
    return grid[on_face] + c


def tool_points(
    width: float, tip_offset: float, thickness: float, finger_width: float
) -> dict[str, NDArray]:
    """The tool's model as point sets in the TCP frame, by name, at jaw opening ``width``."""
    tip = tip_offset
    top = tip + _FINGER_TOP
    fz = 0.5 * (tip + top)  # exact: the fingers' middle
    # A pad's face lies half the opening from the TCP, its box's centre half its thickness on.
    x_outer = 0.5 * width + 0.5 * thickness  # exact: half the opening, half the pad
    x_inner = -0.5 * width - 0.5 * thickness  # exact: the same, on the other side
    finger = (thickness, finger_width, tip - top)
    fingers = {
        "the outer finger": _box_points((x_outer, 0.0, fz), finger, FINGER_STEP),
        "the inner finger": _box_points((x_inner, 0.0, fz), finger, FINGER_STEP),
    }
    # Each box sits on the one below it: its centre half its height above their contact.
    body_z = top - 0.5 * _BODY[Z]  # exact: a box's centre is half its height in
    puck_z = top - _BODY[Z] - 0.5 * _PUCK[Z]  # exact: a box's centre is half its height in
    wrist_z = top - _BODY[Z] - _PUCK[Z] - 0.5 * _WRIST[Z]  # exact: the same
    fingers["the gripper body"] = _box_points((0.0, 0.0, body_z), _BODY, BODY_STEP)
    fingers["the wrist"] = np.vstack(
        [
            _box_points((0.0, 0.0, puck_z), _PUCK, WRIST_STEP),
            _box_points((0.0, 0.0, wrist_z), _WRIST, WRIST_STEP),
        ]
    )
    return fingers


@dataclass(frozen=True)
class Clearance:
    """The closest the swept tool comes to an obstacle (m, negative: into it), and what."""

    distance: float
    tool_part: str = ""
    obstacle: str = ""
    phase: str = ""

    @property
    def clear(self) -> bool:
        return self.distance >= 0.0

    def reason(self) -> str:
        if self.clear:
            return f"clear by {self.distance * 1e3:.0f} mm"
        if self.obstacle == "the edge of the UR5's reach":
            return f"{self.tool_part} would be beyond {self.obstacle} {self.phase}"
        return (
            f"{self.tool_part} would hit {self.obstacle} {self.phase} "
            f"({-self.distance * 1e3:.0f} mm into it)"
        )


def pivot_sweep(
    frame: PivotFrame, params: PivotParams, finger_width: float
) -> list[tuple[str, Pose, float]]:
    """The tool's poses the pivot passes through, with the jaw opening at each: the last leg of
    the approach (from ``approach_height`` above the pre-approach pose down to it and on to the
    grasp), then the Tilt's arc to upright."""
    p = params
    assert p.l_a is not None and p.alpha is not None
    target = frame.grasp_pose(p.l_a, p.alpha, p.tip_offset)
    opening = frame.opening(p.l_a, p.alpha)
    z = target.rotation[:, Z]
    pre = target.position - p.approach_distance * z
    above = pre + p.approach_height * frame.up
    poses: list[tuple[str, Pose, float]] = []
    wide = opening + p.approach_clearance
    for k in np.linspace(0.0, 1.0, DESCENT_POSES):
        poses.append(
            (
                "coming down over the open end",
                Pose(above + k * (pre - above), target.rotation),
                wide,
            )
        )
    for k in np.linspace(0.0, 1.0, APPROACH_POSES)[1:]:
        poses.append(
            (
                AT_ALPHA,
                Pose(pre + k * (target.position - pre), target.rotation),
                wide,
            )
        )
    # As far as the Tilt goes: past the tip-over angle by ``tilt_past_tip`` (or the configured
    # angle); the part's weight stands it up the rest of the way.
    end = (
        p.tilt_angle
        if p.tilt_angle is not None
        else min(HALF_PI, frame.section.tip_angle + p.tilt_past_tip)
    )
    for theta in np.linspace(0.0, end, ARC_POSES)[1:]:
        poses.append(("on the Tilt's arc", frame.tilt_pose(target, float(theta)), opening))
    return poses


#: m: clearances beyond this are not worked out exactly (reported as at least this)
FAR = 0.05


def nearest(points: NDArray[np.float64], obstacles: Sequence[Obstacle]) -> tuple[float, int, int]:
    """The smallest signed distance (m) from ``points`` to ``obstacles`` and where it is:
    ``(distance, obstacle index, point index)``; ``(FAR, -1, -1)`` when nothing is nearer.

    Only the points inside an obstacle's bounding box grown by :data:`FAR` are measured, so a
    sweep high over the bin or far from a neighbour costs little."""
    best, where = FAR, (-1, -1)
    for k, ob in enumerate(obstacles):
        c, s = math.cos(ob.yaw), math.sin(ob.yaw)
        hx, hy, hz = ob.half
        reach = np.array([abs(c) * hx + abs(s) * hy, abs(s) * hx + abs(c) * hy, hz]) + FAR
        near = np.all(np.abs(points - ob.center) <= reach, axis=1)
        if not near.any():
            continue
        idx = np.flatnonzero(near)
        d = ob.distance(points[idx])
        i = int(np.argmin(d))
        if d[i] < best:
            best, where = float(d[i]), (k, int(idx[i]))
    return best, where[0], where[1]


def standing_sweep(frame: PivotFrame) -> NDArray[np.float64]:
    """The part's own box (its length along ``u``, its height and width ``2b``) as it turns
    about G to upright, the points that leave its lying footprint: the base end swings back
    beyond G by up to its height, where a wall or a neighbour there stops it standing (the
    Tilt's guard then stops the arm)."""
    a, b = frame.section.a, frame.section.b
    g = frame.pivot
    u, n, up = frame.u, frame.normal, frame.up
    grid = [(ds, h, w)
            for ds in np.linspace(0.0, 2.0 * a, STAND_ALONG)  # exact: the length is 2a
            for h in np.linspace(0.0, 2.0 * b, STAND_ACROSS)  # exact: the height is 2b
            for w in np.linspace(-b, b, STAND_ACROSS)]
    along, height, across = (np.array(col) for col in zip(*grid, strict=True))
    points = []
    for beta in np.linspace(0.0, HALF_PI, STAND_POSES)[1:]:
        c, s = math.cos(beta), math.sin(beta)
        ds = along * c - height * s
        h = along * s + height * c
        behind = ds < 0.0  # beyond the end the part lies at: where it was not already
        points.append(g + np.outer(ds[behind], u) + np.outer(across[behind], n)
                      + np.outer(h[behind], up))
    return np.vstack(points)


def pivot_clearance(
    frame: PivotFrame,
    params: PivotParams,
    obstacles: Sequence[Obstacle],
    finger_width: float,
    margin: float | None = None,
) -> Clearance:
    """The sweep's closest approach to ``obstacles``, less ``margin`` (m; default: the
    pivot's ``clearance_margin``)."""
    if margin is None:
        margin = params.clearance_margin
    if not obstacles:
        return Clearance(math.inf)
    models: dict[float, dict[str, NDArray]] = {}
    chunks, labels = [], []  #: world points; (phase, tool part) of each chunk
    for phase, pose, width in pivot_sweep(frame, params, finger_width):
        model = models.get(width)
        if model is None:
            model = models[width] = tool_points(
                width, params.tip_offset, params.finger_thickness, finger_width
            )
        for name, pts in model.items():
            chunks.append(pts @ pose.rotation.T + pose.position)
            labels.append((phase, name))
    chunks.append(standing_sweep(frame))
    labels.append((STANDING_UP, "the part"))
    points = np.vstack(chunks)
    d, o, n = nearest(points, obstacles)
    if o < 0:
        return Clearance(FAR - margin)
    chunk = int(np.searchsorted(np.cumsum([len(c) for c in chunks]), n, side="right"))
    phase, name = labels[chunk]
    return Clearance(d - margin, name, obstacles[o].what, phase)


def reach_problem(
    frame: PivotFrame, params: PivotParams, finger_width: float, reach: Reach
) -> Clearance | None:
    """Where the sweep leaves the arm's ``reach`` (checked above the part, at the grasp and at
    the arc's end), or None when it stays inside."""
    sweep = pivot_sweep(frame, params, finger_width)
    at_grasp = max(i for i, (phase, _, _) in enumerate(sweep) if phase == AT_ALPHA)
    checked = (sweep[0], sweep[at_grasp], sweep[-1])  # above, at the grasp, arc's end
    out = reach([pose for _, pose, _ in checked])
    if out is None:
        return None
    return Clearance(-1.0, "the TCP", "the edge of the UR5's reach", checked[out][0])


@dataclass(frozen=True)
class EndChoice:
    """The frame to pivot (its ``u`` towards the open end used), its clearance, and the
    clearance of every end tried (for the record)."""

    frame: PivotFrame
    clearance: Clearance
    tried: tuple[Clearance, ...]


def points_outward(frame: PivotFrame, base_xy: Sequence[float] = (0.0, 0.0)) -> bool:
    """Whether the frame's open end points away from the robot's base: the end
    :func:`choose_end` prefers among those that clear."""
    radial = np.asarray(frame.center[XY], float) - np.asarray(base_xy, float)
    return float(frame.u[XY] @ radial) > 0.0


def likely_grasp_rotation(
    frame: PivotFrame, alpha: float, open_ends: int, base_xy: Sequence[float] = (0.0, 0.0)
) -> NDArray[np.float64]:
    """The Grasp's tool rotation at the end :func:`choose_end` prefers when both clear (a
    tube's outward end; the one open end otherwise), without the clearance sweeps: cheap
    enough for a tick, for the look to turn its last view to (the sweeps may still pick the
    other end; then the Grasp turns the wrist itself)."""
    if open_ends >= 2 and not points_outward(frame, base_xy):  # exact: a tube
        frame = replace(frame, yaw=frame.yaw + math.pi)
    return frame.grasp_rotation(alpha)


def choose_end(
    frame: PivotFrame,
    params: PivotParams,
    obstacles: Sequence[Obstacle],
    finger_width: float,
    open_ends: int,
    margin: float | None = None,
    base_xy: Sequence[float] = (0.0, 0.0),
    *,
    reach: Reach,
) -> EndChoice:
    """The end to pivot from: for a tube (``open_ends`` 2) either; otherwise the one open end.

    Among the ends whose sweep clears, the one whose open end points away from the robot's base
    (``base_xy``) -- the pose the pivot was tuned in, the wrist over the part's far side from
    the base -- else the one with the larger clearance; with none clear, the larger clearance
    (``clearance.clear`` False: not pickable where it lies). An end whose sweep leaves the
    arm's ``reach`` does not clear."""
    frames = [frame]
    if open_ends >= 2:  # exact: a tube, open at both ends
        frames.append(replace(frame, yaw=frame.yaw + math.pi))
    tried = [
        reach_problem(f, params, finger_width, reach)
        or pivot_clearance(f, params, obstacles, finger_width, margin)
        for f in frames
    ]

    def rank(i: int) -> tuple[bool, bool, float]:
        return (tried[i].clear, points_outward(frames[i], base_xy), tried[i].distance)

    best = max(range(len(frames)), key=rank)
    return EndChoice(frames[best], tried[best], tuple(tried))
