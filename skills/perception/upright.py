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
from skills.perception.heightmap import back_project_image


@dataclass(frozen=True)
class UprightPart:
    center: NDArray[np.float64]  #: x, y (m) of the part's axis, world
    yaw: float  #: rad, for a square section the direction of one side (mod 90 deg); else 0
    points: int  #: rim points used
    fit_rms: float  #: m, rms distance of the points from the fitted rim


def _circle_fit(xy: NDArray[np.float64]) -> tuple[NDArray[np.float64], float, float]:
    """Kasa fit: centre, radius, rms residual (m)."""
    a = np.column_stack([2.0 * xy, np.ones(len(xy))])
    b = np.sum(xy**2, axis=1)
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    center = sol[:2]
    radius = math.sqrt(max(0.0, sol[2] + float(center @ center)))
    rms = float(np.sqrt(np.mean((np.linalg.norm(xy - center, axis=1) - radius) ** 2)))
    return center, radius, rms


def locate_upright_part(
    frame: Frame,
    intr: Intrinsics,
    world_T_camera: Pose,
    part: Part,
    expected_xy: NDArray[np.float64],
    floor_z: float = 0.0,
    search: float = 0.08,
    band: float = 0.004,
    min_points: int = 40,
) -> UprightPart | None:
    """The standing ``part`` near ``expected_xy`` (m), or None when no rim is seen there.

    ``search``: how far (m) beyond its outer radius the part may stand from ``expected_xy``;
    ``band``: half-height (m) of the slab around the rim height that holds the rim's points.
    """
    pts = back_project_image(frame.depth, intr, world_T_camera).reshape(-1, 3)
    pts = pts[np.isfinite(pts[:, 0])].astype(np.float64)
    rim_z = floor_z + part.length
    higher = pts[pts[:, 2] > rim_z + 1.5 * band, :2]
    pts = pts[np.abs(pts[:, 2] - rim_z) < band]
    if len(higher) and len(pts):
        # Nothing stands higher than the rim of a free-standing part: band points beside
        # something taller are the face of a wall (the bin's, or a fixture's), not a rim.
        from scipy.spatial import cKDTree

        near_tall = cKDTree(higher).query(pts[:, :2], distance_upper_bound=0.006)[0]
        pts = pts[~np.isfinite(near_tall)]
    reach = 0.5 * part.outer * (math.sqrt(2.0) if part.hole_shape == "rectangle" else 1.0)
    center = np.asarray(expected_xy, float)[:2]
    radius = reach + search
    xy = pts[:0, :2]
    for _ in range(3):  # select around the guess, fit, reselect tightly around the fit
        d = np.linalg.norm(pts[:, :2] - center, axis=1)
        xy = pts[d < radius, :2]
        if len(xy) < min_points:
            return None
        center = _center(xy, part)
        radius = reach + 0.004
    if part.hole_shape == "circle":
        c, r, rms = _circle_fit(xy)
        if not 0.35 * part.hole < r < 0.65 * part.outer:
            return None
        return UprightPart(center=c, yaw=0.0, points=len(xy), fit_rms=rms)
    (cx, cy), (w, h), angle = cv2.minAreaRect((xy * 1e3).astype(np.float32))
    if max(w, h) > part.outer * 1e3 * 1.3:
        return None
    yaw = math.radians(angle) % (0.5 * math.pi)
    return UprightPart(center=np.array([cx, cy]) * 1e-3, yaw=yaw, points=len(xy), fit_rms=0.0)


def _center(xy: NDArray[np.float64], part: Part) -> NDArray[np.float64]:
    if part.hole_shape == "circle":
        return _circle_fit(xy)[0]
    (cx, cy), _, _ = cv2.minAreaRect((xy * 1e3).astype(np.float32))
    return np.array([cx, cy]) * 1e-3
