"""Find a hollow part standing on its end: the ring of its rim seen from above.

Used by Align after the Tilt has stood a part up: it lands a few millimetres from where the
mechanics put it, and the hole grasp needs its wall to a millimetre or two. From above, a
standing hollow part shows its rim as a ring at the height of its length; nothing else in a bin
lies at that height within a few centimetres, so the ring's points are picked by height and
distance from the expected place and fitted: a circle (algebraic least squares, which a partial
ring does not bias) for round parts, the smallest enclosing rectangle for square ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from drivers.camera import Frame, Intrinsics
from drivers.parts import Part
from drivers.pose import Pose
from skills.axes import XY, Z
from skills.perception.heightmap import M_PER_MM, MM_PER_M, back_project_image

#: m: how far beyond its outer radius a standing part may be from where it is expected, by
#: default: centimetres, so a prediction off by more than the usual few millimetres still finds
#: it (Align and the slot pass their own, their ``view_search``).
SEARCH = 0.08
#: m: half the height of the slab around the rim's height that holds the rim's points: a few
#: times the depth noise, under the height step to anything else in the bin.
BAND = 0.004
#: rim points below which no rim is said to be seen: too few to fit a ring or a rectangle to.
MIN_POINTS = 40
#: bands (1): points higher than the rim by this many band half-heights are something taller
#: than the part (a wall): clear of the rim's own slab with a margin for its noise.
TALLER_BANDS = 1.5
#: m: rim-height points within this of something taller are the face of a wall beside it, not a
#: rim: a few pixels at the camera's distance (about a millimetre a pixel at 0.5 m).
WALL_FACE = 0.006
#: passes of select-and-fit: around the guess, then twice around the fit, tighter.
FIT_PASSES = 3
#: m: beyond its outer radius, what the later passes keep around the fitted centre: the rim's
#: thickness of noise, not the neighbours.
REFIT_MARGIN = 0.004
#: a fitted circle's radius must lie between these fractions of the hole's and of the outer
#: diameter: a rim's radius lies between half of each, with a margin for a partial ring.
MIN_OF_HOLE, MAX_OF_OUTER = 0.35, 0.65
#: a fitted rectangle's longer side may be this much of the outer size at most (a square's
#: rim seen whole, with noise); larger, it holds more than the rim.
MAX_RECT_OF_OUTER = 1.3


@dataclass(frozen=True)
class UprightPart:
    center: NDArray[np.float64]  #: x, y (m) of the part's axis, world
    yaw: float  #: rad, for a square section the direction of one side (mod 90 deg); else 0
    points: int  #: rim points used
    fit_rms: float  #: m, rms distance of the points from the fitted rim


def _circle_fit(xy: NDArray[np.float64]) -> tuple[NDArray[np.float64], float, float]:
    """Kasa fit: centre, radius, rms residual (m)."""
    a = np.column_stack([2.0 * xy, np.ones(len(xy))])  # exact: x^2 + y^2 = 2 a.x + c
    b = np.sum(xy**2, axis=1)
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    center, c = sol[:-1], sol[-1]
    radius = math.sqrt(max(0.0, c + float(center @ center)))
    rms = float(np.sqrt(np.mean((np.linalg.norm(xy - center, axis=1) - radius) ** 2)))
    return center, radius, rms


def locate_upright_part(
    frame: Frame,
    intr: Intrinsics,
    world_T_camera: Pose,
    part: Part,
    expected_xy: NDArray[np.float64],
    floor_z: float = 0.0,
    search: float = SEARCH,
    band: float = BAND,
    min_points: int = MIN_POINTS,
) -> UprightPart | None:
    """The standing ``part`` near ``expected_xy`` (m), or None when no rim is seen there.

    ``search``: how far (m) beyond its outer radius the part may stand from ``expected_xy``;
    ``band``: half-height (m) of the slab around the rim height that holds the rim's points.
    """
    pts = back_project_image(frame.depth, intr, world_T_camera).reshape(-1, 3)
    pts = pts[np.isfinite(pts[:, 0])].astype(np.float64)
    rim_z = floor_z + part.length
    higher = pts[pts[:, Z] > rim_z + TALLER_BANDS * band, XY]
    pts = pts[np.abs(pts[:, Z] - rim_z) < band]
    if len(higher) and len(pts):
        # Nothing stands higher than the rim of a free-standing part: band points beside
        # something taller are the face of a wall (the bin's, or a fixture's), not a rim.
        from scipy.spatial import cKDTree

        near_tall = cKDTree(higher).query(pts[:, XY], distance_upper_bound=WALL_FACE)[0]
        pts = pts[~np.isfinite(near_tall)]
    corner = math.sqrt(2.0) if part.hole_shape == "rectangle" else 1.0  # exact: a diagonal
    reach = 0.5 * part.outer * corner  # exact: half the outer size, to a side or a corner
    center = np.asarray(expected_xy, float)[XY]
    radius = reach + search
    xy = pts[:0, XY]
    for _ in range(FIT_PASSES):  # select around the guess, fit, reselect tightly around the fit
        d = np.linalg.norm(pts[:, XY] - center, axis=1)
        xy = pts[d < radius, XY]
        if len(xy) < min_points:
            return None
        center = _center(xy, part)
        radius = reach + REFIT_MARGIN
    if part.hole_shape == "circle":
        c, r, rms = _circle_fit(xy)
        if not MIN_OF_HOLE * part.hole < r < MAX_OF_OUTER * part.outer:
            return None
        return UprightPart(center=c, yaw=0.0, points=len(xy), fit_rms=rms)
    (cx, cy), (w, h), angle = cv2.minAreaRect((xy * MM_PER_M).astype(np.float32))
    if max(w, h) > part.outer * MM_PER_M * MAX_RECT_OF_OUTER:
        return None
    yaw = math.radians(angle) % (0.5 * math.pi)  # exact: a square repeats every right angle
    return UprightPart(center=np.array([cx, cy]) * M_PER_MM, yaw=yaw, points=len(xy), fit_rms=0.0)


def _center(xy: NDArray[np.float64], part: Part) -> NDArray[np.float64]:
    if part.hole_shape == "circle":
        return _circle_fit(xy)[0]
    (cx, cy), _, _ = cv2.minAreaRect((xy * MM_PER_M).astype(np.float32))
    return np.array([cx, cy]) * M_PER_MM
