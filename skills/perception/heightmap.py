"""The bin seen as heights above its floor: the input every bin-picking segmenter starts from.

The floor plane is found by RANSAC on the back-projected depth (it is the largest plane in view),
so a tilted camera, a camera pose a little off or a bin that is not level do not matter; heights
are distances above that plane, per pixel, NaN where the depth is invalid or outside the region
of interest (the bin's inside in the base frame, shrunk by a margin so the walls drop out).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from drivers.camera import Frame, Intrinsics
from drivers.pose import Pose
from skills.axes import DIM
from skills.status import SkillInputError

_UP = np.array([0.0, 0.0, 1.0])
#: mm per m, and back: OpenCV's rectangle fits and clusters take float32 points, so the
#: perception's geometry on the floor runs in millimetres, units of the order of a pixel
MM_PER_M, M_PER_MM = 1e3, 1e-3
#: Random three-point planes RANSAC tries. The floor is the largest plane in view, so a try
#: whose three points all lie on it is common; the least-squares refit on the best one's inliers
#: then makes the result insensitive to which of those tries won.
FLOOR_ITERATIONS = 60
#: m: a point this close to a candidate plane counts as its inlier: above the depth noise on the
#: floor, well under the thinnest part lying on it (the 7.6 mm rail), whose top must not count.
FLOOR_TOLERANCE = 0.003
#: points drawn for counting the inliers: enough to rank the candidate planes, few enough that
#: the tries stay a small part of a frame's time.
FLOOR_SAMPLE = 20000
#: m^2: three points whose two differences have a cross product shorter than this lie (nearly)
#: on a line and define no plane.
DEGENERATE_AREA = 1e-9
#: deg: the floor's normal lies within this of the up hint; steeper planes are walls or faces of
#: parts, and a camera or bin tilted by less still finds its floor.
FLOOR_MAX_TILT_DEG = 25.0
#: m: the bin's inside is shrunk by this before the floor fit, so that the walls drop out.
ROI_MARGIN = 0.008
#: valid depth pixels inside the bin below which no floor is looked for: a frame this empty is
#: no view of the bin.
MIN_FLOOR_PIXELS = 100
#: points the floor fit is given at most (every k-th valid pixel): the bin is about half of a
#: 640 x 480 frame, and the fit needs far fewer points than that.
FLOOR_FIT_POINTS = 40000
#: points that define a plane
PLANE_POINTS = 3


def dot_last(a: NDArray[np.floating], w: NDArray[np.floating] | tuple[float, ...]) -> NDArray:
    """``a @ w`` over the last axis, written out as multiply-adds.

    ``@`` on these tall arrays goes to OpenBLAS, whose worker threads spin-wait between calls:
    on this 2-core machine they doubled the CPU time for no gain, and when another process
    held a core they doubled the wall time too (102 vs 46 ms per frame). Element-wise
    arithmetic runs on the calling thread only.
    """
    out = a[..., 0] * a.dtype.type(w[0])
    for i in range(1, a.shape[-1]):
        out += a[..., i] * a.dtype.type(w[i])
    return out


class PerceptionInputError(SkillInputError):
    """A frame, intrinsics or model that perception cannot work with (named in the message)."""


@dataclass(frozen=True)
class Plane:
    normal: NDArray[np.float64]  #: unit, pointing up (towards the camera side)
    offset: float  #: n . p = offset for points p on the plane (m)

    def height(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        return dot_last(points, self.normal) - self.offset


@dataclass(frozen=True)
class HeightMap:
    height: NDArray[np.float32]  #: (H, W) m above the floor plane; NaN = no data / outside
    points: NDArray[np.float32]  #: (H, W, 3) base-frame points (m); NaN where invalid
    plane: Plane
    pixel_size: float  #: m per pixel on the floor at the image centre (for window sizes)


def check_frame(frame: Frame, intr: Intrinsics | None) -> None:
    """Raise :class:`PerceptionInputError` naming what is wrong with the inputs."""
    if intr is None:
        raise PerceptionInputError("missing camera intrinsics")
    depth = frame.depth
    if not isinstance(depth, np.ndarray) or depth.ndim != 2:  # exact: an image: rows, columns
        raise PerceptionInputError(
            f"depth must be an (H, W) array, got {getattr(depth, 'shape', type(depth).__name__)}"
        )
    if depth.dtype.kind != "f":
        raise PerceptionInputError(f"depth must be floating point metres, got dtype {depth.dtype}")
    if depth.shape != (intr.height, intr.width):
        raise PerceptionInputError(
            f"depth is {depth.shape[1]} x {depth.shape[0]} but the intrinsics say "
            f"{intr.width} x {intr.height}"
        )
    if not np.any(depth > 0):
        raise PerceptionInputError("the depth frame holds no valid pixel")


_RAYS: dict[tuple[int, int, float, float, float, float], NDArray[np.float32]] = {}


def _rays(intr: Intrinsics, shape: tuple[int, int]) -> NDArray[np.float32]:
    """Per-pixel ray ``((u - cx)/fx, (v - cy)/fy, 1)``, cached per camera (the 640 x 480 grid is
    most of the back-projection's cost)."""
    key = (shape[0], shape[1], intr.fx, intr.fy, intr.cx, intr.cy)
    rays = _RAYS.get(key)
    if rays is None:
        v, u = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float32)
        rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1)
        _RAYS.clear()
        _RAYS[key] = rays
    return rays


def back_project_image(
    depth: NDArray[np.floating], intr: Intrinsics, world_T_camera: Pose
) -> NDArray[np.float32]:
    """(H, W, 3) base-frame points; NaN where the depth is 0 (invalid)."""
    z = depth.astype(np.float32)
    cam = _rays(intr, depth.shape) * z[..., None]
    rot = world_T_camera.rotation
    pos = world_T_camera.position
    pts = np.stack([dot_last(cam, rot[i]) + np.float32(pos[i]) for i in range(DIM)], axis=-1)
    pts[z <= 0] = np.nan
    return pts


def fit_floor(
    points: NDArray[np.floating],
    rng: np.random.Generator,
    iterations: int = FLOOR_ITERATIONS,
    tolerance: float = FLOOR_TOLERANCE,
    up_hint: NDArray[np.float64] | None = None,
) -> Plane:
    """RANSAC plane with the most inliers among planes within 25 deg of ``up_hint``, refined by
    least squares on its inliers. ``points`` (N, 3) finite."""
    up_hint = _UP if up_hint is None else up_hint
    n = len(points)
    if n < PLANE_POINTS:
        raise PerceptionInputError("too few valid depth pixels to find the floor")
    sample = points[rng.choice(n, size=min(n, FLOOR_SAMPLE), replace=False)]
    best, best_count = None, -1
    idx = rng.integers(0, len(sample), size=(iterations, PLANE_POINTS))
    for i, j, k in idx:
        a, b, c = sample[i], sample[j], sample[k]
        nrm = np.cross(b - a, c - a)
        norm = float(np.linalg.norm(nrm))
        if norm < DEGENERATE_AREA:
            continue
        nrm = nrm / norm
        if nrm @ up_hint < 0:
            nrm = -nrm
        if nrm @ up_hint < np.cos(np.radians(FLOOR_MAX_TILT_DEG)):
            continue
        count = int(np.count_nonzero(np.abs(dot_last(sample, nrm) - nrm @ a) < tolerance))
        if count > best_count:
            best, best_count = (nrm, float(nrm @ a)), count
    if best is None:
        raise PerceptionInputError("no floor plane found in the depth frame")
    nrm, off = best
    inl = sample[np.abs(dot_last(sample, nrm) - off) < tolerance]
    centroid = inl.mean(axis=0)
    d = inl - centroid
    cov = np.array([[float(np.sum(d[:, i] * d[:, j])) for j in range(DIM)] for i in range(DIM)])
    nrm = np.linalg.eigh(cov)[1][:, 0]  # the least-spread direction (3 x 3: no BLAS threads)
    if nrm @ up_hint < 0:
        nrm = -nrm
    return Plane(normal=nrm, offset=float(nrm @ centroid))


def height_map(
    frame: Frame,
    intr: Intrinsics,
    world_T_camera: Pose,
    roi: tuple[float, float, float, float] | None = None,
    roi_margin: float = ROI_MARGIN,
    rng: np.random.Generator | None = None,
) -> HeightMap:
    """Heights above the floor for every pixel. ``roi`` = (xmin, xmax, ymin, ymax) in the base
    frame (the bin's inside); pixels outside it, shrunk by ``roi_margin``, are NaN."""
    check_frame(frame, intr)
    rng = rng if rng is not None else np.random.default_rng(0)
    pts = back_project_image(frame.depth, intr, world_T_camera)
    valid = np.isfinite(pts[..., 0])
    if roi is not None:
        x0, x1, y0, y1 = roi
        m = roi_margin
        with np.errstate(invalid="ignore"):
            valid &= (
                (pts[..., 0] > x0 + m)
                & (pts[..., 0] < x1 - m)
                & (pts[..., 1] > y0 + m)
                & (pts[..., 1] < y1 - m)
            )
    flat = pts[valid]
    if len(flat) < MIN_FLOOR_PIXELS:
        raise PerceptionInputError(
            f"fewer than {MIN_FLOOR_PIXELS} valid depth pixels inside the bin"
        )
    every = max(1, len(flat) // FLOOR_FIT_POINTS)
    plane = fit_floor(flat.astype(np.float64, copy=False)[::every], rng)
    height = np.full(valid.shape, np.nan, np.float32)
    height[valid] = dot_last(flat, plane.normal) - np.float32(plane.offset)
    z_mid = float(np.median(frame.depth[frame.depth > 0]))
    return HeightMap(height=height, points=pts, plane=plane, pixel_size=z_mid / intr.fx)
