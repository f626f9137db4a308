"""Find every hollow part lying in the bin from one RGB-D frame (the classical pipeline).

1. Heights above the floor (:mod:`skills.perception.heightmap`: RANSAC floor, bin ROI).
2. Segmentation: foreground above ``min_height``; one seed per part from its gently sloped top
   (the foreground cut at steep slopes: between touching parts, or a low part and a tall one,
   the surfaces are steep), plus the band of its own height for a thin catalogue part; then a
   watershed on the heights grows the seeds over the flanks, and each segment drops what it
   took well above its own top. Two boxes touching side by side leave no valley; a segment as
   wide as ``n`` catalogue parts of its height is cut into ``n`` strips along its axis (or
   ``n`` compact clusters); two thin parts side by side, the second partly under a taller
   neighbour, are cut at the catalogue width from the free side.
3. A fit per segment on its 3D points: the axis from the principal direction of the upper half
   (the crest), the length from its extent, the outer size from the height (a lying part is as
   tall as it is wide), the centre on the crest line at half height; the nearest catalogue part
   by length and outer size names it. A thin part seen only in part, one end free and the
   other running under a neighbour, is placed from its free end and the catalogue length;
   down to a stub of a tenth of its length when that is flat-topped, as wide as the part, and
   the rest of its length lies under taller surfaces.
4. The end for the hole finger: a tube is open at both ends, so the end farther from the robot
   (the gripper then swings back over the pivot, inside the bin). A cup or bottle: the end whose
   inside is seen (floor-level points inside the part's footprint, seen through the opening);
   when neither is seen the detection says so (``open_end_seen`` False).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from drivers.camera import Frame, Intrinsics
from drivers.parts import Part
from drivers.pose import Pose
from skills.axes import XY
from skills.perception.heightmap import (
    MM_PER_M,
    HeightMap,
    PerceptionInputError,
    dot_last,
    height_map,
)

# Algorithm constants. The figures they quote are from the twin's D435 at the 0.5 m look-down
# pose: depth noise 1.25 mm (one sigma), a pixel about 1.1 mm on the floor; the catalogue's
# thin part is the 7.6 mm mounting rail. The tunable thresholds are :class:`DetectorSettings`.

#: pixels, the aperture of the median filters over the heights (5 x 5): wide enough to take out
#: the depth noise's speckle, narrow enough that the rail's top (7 pixels) keeps its height
MEDIAN_APERTURE = 5
#: pixels, the Sobel aperture for the slope that cuts the seeds (3 x 3, the finest)
SOBEL_APERTURE = 3
#: a 3 x 3 Sobel's response to a slope of one (height unit per pixel): its weights 1, 2, 1
#: over a two-pixel difference; dividing by it and the pixel size gives rise over run
SOBEL_GAIN = 8.0
#: the seeds' connectivity (4: pixels sharing a side): two seeds touching at a corner only
#: (two parts' tops across a diagonal gap) stay two
SEED_CONNECTIVITY = 4
#: the watershed marker of the first seed: 0 is the unknown it floods, 1 the background
FIRST_SEED = 2
#: the 8-bit grey level of the floor in the image the watershed floods (the top is black)
GREY_FULL_SCALE = 255.0  # exact: the full scale of an 8-bit image
#: m, the smallest length or height divided by (a frame or segment of no height, a camera on
#: the floor): a guard against dividing by zero, far below any real size
MIN_LENGTH = 1e-6
#: m, the same guard for the pixel size and the spread of points across a crest
MIN_SPREAD = 1e-9
#: the same guard for a squared spread (m^2) and a direction's norm
MIN_SQUARED = 1e-12
#: pixels^4, the seed's scatter determinant below which its pixels lie on a line (no plane)
MIN_SCATTER_DET = 1e-9
#: m, a thin catalogue part's size tolerance: heights within 2 mm of its size (the depth noise
#: is 1.25 mm) or a quarter of it, whichever is larger, are its band, its match, its stub
THIN_SIZE_TOL = 0.002
#: the same tolerance as a share of the thin part's size
THIN_SIZE_SHARE = 0.25
#: m, what a segment may rise above its seed's top before it is a neighbour's flank (3 mm:
#: over twice the depth noise)
CLIMB_MARGIN = 0.003
#: the same margin as a share of the seed's top (tall parts: 10 %)
CLIMB_SHARE = 0.1
#: pixels, the fewest in a seed whose plane is fitted (a leaning top); fewer: its median
MIN_PLANE_SEED = 30
#: percent, a seed's rise is measured from its 2nd to its 98th percentile (a stray pixel of a
#: neighbour does not make a level top lean)
RISE_PERCENTILES = (2, 98)
#: m, the rise across a seed that makes its top a leaning one (10 mm: eight sigma of noise)
LEAN_RISE = 0.010
#: a seed is a plane only when its heights scatter about the fit by under this share of its rise
PLANE_SCATTER = 0.25
#: percent: a segment's top (or outer size) is this percentile of its heights; that of a lying
#: cylinder's is within 2 % of its diameter, and it keeps the depth noise from inflating a rail
TOP_PERCENTILE = 80
#: percent: a segment's extent along or across its axis runs between these percentiles of its
#: points, so that a few stray pixels do not stretch it
EXTENT_LO, EXTENT_HI = 1, 99
#: points, the fewest of a segment's whose moments count when pieces are joined
MIN_PIECE = 10
#: pixel offsets (rows, columns) at which two segments are neighbours: the watershed leaves a
#: one-pixel line between the regions it grows, so up to two pixels apart, each direction once
NEIGHBOUR_OFFSETS = ((0, 2), (2, 0), (2, 2), (2, -2), (1, 2), (2, 1), (2, -1), (1, -2))
#: m, pieces of one part have the same height to within 2 mm...
JOIN_HEIGHT_TOL = 0.002
#: ... or 10 % of the taller one's, whichever is larger
JOIN_HEIGHT_SHARE = 0.1
#: pieces end to end keep the width of the wider: a union whose spread across grows past this
#: factor (plus :data:`JOIN_WIDTH_MARGIN`) holds two parts side by side
JOIN_WIDTH_GROWTH = 1.25
#: m, the spread across that a union of pieces may gain regardless (half a millimetre of noise)
JOIN_WIDTH_MARGIN = 0.0005
#: a direction this close to the floor's normal (norm of their cross product) is parallel
PARALLEL = 1e-6
#: the points above this share of a segment's top are its upper half, which its axis and extent
#: are measured on (a lying part's top and upper flanks; seen obliquely, a lower flank is hidden)
UPPER_SHARE = 0.5
#: points, the fewest in a segment's upper half for a fit
MIN_UPPER = 20
#: a segment wider than this many times its height (a lying part is as wide as it is tall)
#: holds several parts side by side
SIDE_BY_SIDE_WIDTH = 1.6
#: a thin segment narrower than its count of catalogue widths by this share of one is clipped:
#: its last part partly under a taller neighbour
STRIP_SHORTFALL = 0.25
#: a strip of a split segment is fitted when it holds 1/this of ``min_pixels`` (a part beside
#: others shows less of itself)
STRIP_PIXEL_DIVISOR = 2
#: m, the window around a segment searched for bare floor beside its long sides
FREE_SIDE_WINDOW = 0.01
#: percent, the stretch of a segment along its axis where the floor beside it is looked at
#: (5th to 95th: its rounded ends left out)
FREE_SIDE_PERCENTILES = (5, 95)
#: m, the floor beside a long side is looked at from 1.5 mm out (past the part's edge blurred by
#: the noise) ...
FREE_SIDE_FROM = 0.0015
#: ... to 6 mm out: a few pixels of floor, near enough that a neighbour touching or overhanging
#: the side is met there
FREE_SIDE_TO = 0.006
#: points, the fewest seen beside a side for it to be judged free
MIN_FREE_SIDE = 20
#: m, heights above this are seen: invalid pixels read -1 (NaN replaced), any real height is
#: far above this line
SEEN_ABOVE = -0.5
#: percent, the 2nd to 98th percentiles across a leaning part span its outer size
LEAN_WIDTH_PERCENTILES = (2, 98)
#: a leaning part's crest is the strip of this share of its width either side of its middle
LEAN_CREST_BAND = 0.2
#: points, the fewest on a leaning part's crest for its slope to be fitted
MIN_LEAN_CREST = 30
#: rise over run along the crest below which a part is level (0.07: 4 deg)
LEVEL_SLOPE = 0.07
#: m: a top this much higher than the part's size lies on something, not on the floor (about
#: five sigma of the depth noise, under the thinnest part, 7.6 mm)
MIN_FOOT = 0.006
#: share of a level segment's width either side of its middle that is its crest band
#: (:func:`_lying_profile`)
PROFILE_MIDDLE = 0.15
#: share of a level segment's width off its middle where its outer quarters begin
PROFILE_SIDE = 0.25
#: share of a lying cylinder's diameter by which its top, seen from above, falls at the
#: median of an outer quarter (about 3/8 of the width off the middle: r (1 - sqrt(1 - 0.75^2))
#: = 0.17 d; 4-6 mm seen on 34 mm parts in the twin), and the range of it accepted: down to a
#: quarter, as a part high up and off the view's centre is seen obliquely, its far flank
#: hidden (a cup on a duct: 2.5-3.4 mm on that side against 8.2 mm)
ROUND_FALL = 0.17
#: the shares of :data:`ROUND_FALL` accepted (seen obliquely, a quarter; twice it at the most)
ROUND_FALL_RANGE = (0.25, 2.0)
#: share of the part's size within which a top counts as flat (a box's top; a cylinder's
#: crest band)
PROFILE_FLAT = 0.1
#: the crest is the upper points above this share of the top (3 % under it: seen obliquely, a
#: cylinder's far flank is hidden, so a wider band would be lopsided towards the camera) ...
CREST_SHARE = 0.97
#: ... and over the top by at most this share of it or :data:`CREST_ABOVE`, whichever larger
#: (a few pixels of a taller neighbour at the edge do not pull the centre towards it)
CREST_ABOVE_SHARE = 0.1
#: m, the least a crest point may lie over the top (about three sigma of the depth noise)
CREST_ABOVE = 0.004
#: points, a narrower crest than this is widened to :data:`CREST_WIDE_SHARE` of the top
MIN_CREST = 5
#: the wider crest's share of the top
CREST_WIDE_SHARE = 0.9
#: points, the fewest on a crest whose own direction may be the axis
MIN_CREST_AXIS = 30
#: a crest this many times longer than wide is a strip along the axis (a cup's is 4-5 times)
CREST_ASPECT = 2.5
#: m, the window around a thin part's segment that is not a stub (its hidden rest is near)
HIDDEN_WINDOW = 0.02
#: percent, a stub's relief (see ``max_stub_relief``) is its 10th to 90th percentile spread
RELIEF_PERCENTILES = (10, 90)
#: relative size error at which a detection's confidence falls to 1/e (a tenth of its size)
CONFIDENCE_SCALE = 0.1
#: the confidence of a part whose place rests on the catalogue (its length or width), not on
#: what was seen of it
CATALOGUE_CONFIDENCE = 0.2
#: the confidence is scaled by this while the open end is undecided
UNDECIDED_END = 0.5
#: share of a part's length the window around it grows by past its segment (its ends may lie
#: beyond what was segmented), plus an outer size
END_WINDOW_SHARE = 0.25
#: m, the least depth of an end face below the camera (a guard: the camera is never that low)
MIN_FACE_DEPTH = 1e-3
#: the points within this share of the hole's width either side of the axis are looked at in
#: and on an end (inside the hole's rim, with room for the axis' error)
FACE_HALF_WIDTH = 0.4
#: an end face's middle, where a closed face shows, spans these shares of the outer size in
#: height (clear of the floor and of the crest)
FACE_MIDDLE = (0.15, 0.85)
#: m, the end face is the points this close to the end along the axis
FACE_BAND = 0.004
#: the band looked into behind an end reaches this share of the outer size inside it
INSIDE_DEPTH = 0.6
#: m, and stops this far inside the end (6 mm: the lower part of a closed end's own face,
#: blurred by the depth noise and the centre's error, must not count as a view inside)
INSIDE_INSET = 0.006
#: m, heights from this (a little under the floor: noise) ...
INSIDE_FLOOR = -0.002
#: ... to this share of the outer size are low: the floor or the inner wall seen inside
INSIDE_LOW = 0.3
#: an end's crest: points within this share of the outer size of the axis, across ...
END_CREST_HALF_WIDTH = 0.35
#: ... as high as these shares of the outer size (the crest, not the floor or a neighbour) ...
END_CREST_HEIGHT = (0.75, 1.2)
#: m, ... and at most this far past the expected end along the axis
END_CREST_BEYOND = 0.02
#: points, the fewest on an end's crest for it to move the centre
MIN_END_CREST = 10
#: percent: the crest ends at this percentile of its points along the axis
END_CREST_PERCENTILE = 98
#: m, a crest ending farther than this from the expected end belongs to something else
END_CREST_SHIFT = 0.015
#: k-means rounds when a segment is split into clusters (they settle within a few)
CLUSTER_ITERATIONS = 10
#: the image window around a segment grows by this many times the margin over a pixel's floor
#: width: room for the taller rows (fy over fx 1.34 in the twin) and for raised points
WINDOW_GROWTH = 1.6
#: a thin part seen over this share of its length or more is seen whole, not partly hidden
MAX_HIDDEN_SHARE = 0.9
#: a stub is at least this share of the part's width wide (its whole width shows)
STUB_WIDTH = 0.85
#: m, the heights just beyond an end are looked at from 2 mm past it (its rim blurred) ...
BEYOND_FROM = 0.002
#: ... to 10 mm past it
BEYOND_TO = 0.010
#: points, the fewest seen beyond an end to judge it free or covered
MIN_BEYOND = 10
#: a stub's hidden rest counts as covered where the surface over it is above this share of
#: the part's size (a neighbour over it, not the part itself seen)
COVER_HEIGHT = 0.8


@dataclass(frozen=True)
class Detection:
    """One part lying in the bin, in the robot base frame (m, rad)."""

    center: NDArray[np.float64]  #: the part's centre (on its axis)
    yaw: float  #: direction of the axis towards ``open_end``
    length: float  #: estimated length
    outer: float  #: estimated outer size (diameter or side)
    part: str | None  #: nearest catalogue part, None when nothing is close
    open_end: NDArray[np.float64]  #: centre of the end face the hole finger should use
    open_end_seen: bool  #: True when the end was decided (tube, or its inside was seen)
    confidence: float  #: 0..1, from the fit's agreement with the matched part
    pixels: int
    #: not level on the floor (fitted as leaning): the end tests assume a part level on the
    #: floor, so its open end is never judged (a wrong end is worse than none)
    tilted: bool = False
    #: standing on an end (:mod:`skills.perception.standing`): ``open_end`` is the top's
    #: centre, ``open_end_seen`` says the top is open; the pivot cannot take it as it stands
    standing: bool = False
    #: m its axis lies higher than lying on the floor puts it, above the floor the view fitted
    #: (on another part, leaning on one): what decides a lay down, free of how well the
    #: configured floor height and the camera's calibration agree
    raised: float = 0.0

    def pick(self) -> tuple[tuple[float, float], float]:
        """The grasp target the pivot planner needs: (open end x, y) and the axis yaw."""
        return (float(self.open_end[0]), float(self.open_end[1])), self.yaw


@dataclass(frozen=True)
class DetectorSettings:
    min_height: float = 0.0035  #: m above the floor that counts as a part (3 sigma at 0.5 m)
    min_crest: float = 0.005  #: m, lowest crest that seeds a part (the 7.6 mm rail)
    max_seed_slope: float = 1.0  #: seeds are flatter than this (rise over run)
    min_seed: int = 30  #: pixels of the smallest seed
    thin_part: float = 0.015  #: m, catalogue parts thinner than this seed from a height band
    min_width: float = 0.5  #: a segment narrower than this times the part's size is not it
    min_hidden: float = 0.2  #: shortest visible fraction of a thin part running under another
    thin_pair: float = 1.3  #: a thin segment this many part widths wide holds two side by side
    min_stub: int = 60  #: pixels of the smallest visible end of a thin part (see min_stub_length)
    min_stub_length: float = 0.1  #: shortest visible fraction of a thin part's length
    max_stub_relief: float = 0.002  #: m, p10-p90 height spread of a stub's (flat) top
    min_cover: float = 0.8  #: a stub's hidden rest: this fraction of it under taller surfaces
    min_pixels: int = 150  #: smaller segments are noise
    match_tolerance: float = 0.25  #: relative size error beyond which no catalogue part matches
    min_inside: int = 40  #: points seen through an opening that make an end the open one
    max_closed: int = 5  #: at most this many, and the end facing the camera is the closed one
    min_face: int = 40  #: points on a closed end's face (its middle) to call it closed
    #: a closed end's face shows at least this share of :func:`_face_expected` (a bottle's
    #: neck end seen at a slant showed 0.5-0.7 of it, closed faces mostly over 0.9; 0.7-0.9
    #: all gave the same decisions on the tuning scenes)
    min_face_share: float = 0.8
    #: an open end shows a cavity: its face (the hole's far wall) under this many times the
    #: points seen inside, or under ``max_open_face_share`` of a whole face
    max_face_per_inside: float = 1.5
    max_open_face_share: float = 0.35
    min_end_view: float = 0.1  #: tan of the view angle onto an end face needed to judge it


def segment(
    hm: HeightMap,
    settings: DetectorSettings = DetectorSettings(),
    thin: tuple[float, ...] = (),
) -> NDArray[np.int32]:
    """(H, W) labels: 0 background, 1..K part instances. ``thin``: the outer sizes (m) of the
    catalogue's thin parts, whose flat tops also seed (see below)."""
    h = np.nan_to_num(hm.height, nan=0.0).astype(np.float32)
    fg = h > settings.min_height
    fg = cv2.morphologyEx(fg.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)) > 0
    # Seeds: the gently sloped top of each part. Where parts touch, or a low part lies against
    # a tall one, the surfaces between them are steep (a cylinder's flank, a box's wall), so
    # cutting the foreground at steep slopes leaves one seed per part.
    # Median: edge-preserving, so a thin part beside a tall one keeps its top.
    hs = cv2.medianBlur(h, MEDIAN_APERTURE)
    gx = cv2.Sobel(hs, cv2.CV_32F, 1, 0, ksize=SOBEL_APERTURE) / (SOBEL_GAIN * hm.pixel_size)
    gy = cv2.Sobel(hs, cv2.CV_32F, 0, 1, ksize=SOBEL_APERTURE) / (SOBEL_GAIN * hm.pixel_size)
    gentle = np.hypot(gx, gy) < settings.max_seed_slope
    crest = fg & gentle & (h > settings.min_crest)
    # A thin part (the 7.6 mm rail, 7 pixels wide) against a tall one: the filtered slope is
    # steep over most of its width, so it may get no seed there and the tall part's watershed
    # takes it. Its top is a band of its own height, as wide as the part; a tall part's flank
    # crosses that band in a line one or two pixels wide, which the opening removes.
    for size in thin:
        band = (np.abs(hs - size) < max(THIN_SIZE_TOL, THIN_SIZE_SHARE * size)) & fg
        band = cv2.morphologyEx(band.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        crest |= band > 0
    crest = cv2.morphologyEx(crest.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, comp, stats, _ = cv2.connectedComponentsWithStats(crest, connectivity=SEED_CONNECTIVITY)
    keep = stats[:, cv2.CC_STAT_AREA] >= settings.min_seed
    keep[0] = False
    lut = np.zeros(n, np.int32)
    lut[keep] = np.arange(FIRST_SEED, FIRST_SEED + int(np.count_nonzero(keep)), dtype=np.int32)
    markers = lut[comp]
    markers[~fg] = 1
    if not keep.any():
        return np.zeros(h.shape, np.int32)
    top = float(h.max())
    grey = (GREY_FULL_SCALE * np.clip(1.0 - h / max(top, MIN_LENGTH), 0.0, 1.0)).astype(np.uint8)
    labels = cv2.watershed(cv2.merge([grey, grey, grey]), markers.copy())
    out = np.where(fg & (labels >= FIRST_SEED), labels - 1, 0).astype(np.int32)
    _drop_climbed(out, markers - 1, hs)
    return _merge_pieces(out, hs, hm.points[..., XY], settings.thin_part)


def _groups(labels: NDArray[np.int32]) -> dict[int, NDArray[np.int64]]:
    """Flat pixel indices of each label > 0 (one sort of the labelled pixels only)."""
    flat = labels.reshape(-1)
    idx = np.flatnonzero(flat > 0)
    if len(idx) == 0:
        return {}
    lab = flat[idx]
    order = np.argsort(lab, kind="stable")
    idx, lab = idx[order], lab[order]
    cuts = np.flatnonzero(np.diff(lab)) + 1
    return {int(g[0]): i for g, i in zip(np.split(lab, cuts), np.split(idx, cuts), strict=True)}


def _drop_climbed(
    labels: NDArray[np.int32], seeds: NDArray[np.int32], hs: NDArray[np.float32]
) -> None:
    """Unlabel (in place) the pixels a segment took well above its own top.

    The watershed floods each pixel at its own height, so a low part's region climbs the
    steep flank or wall of a tall neighbour up to that neighbour's seed: a rail against a duct
    would take the duct's side wall and read 10-20 mm tall. A part's top is its seed's height
    (the gentle top); pixels more than 3 mm (or 10 %) above that belong to something else.
    """
    flat, hflat = labels.reshape(-1), hs.reshape(-1)
    seed_groups = _groups(seeds)
    for k, idx in _groups(labels).items():
        seed = seed_groups.get(k)
        if seed is None or len(seed) == 0:
            continue
        top = float(np.median(hflat[seed]))
        limit = top + max(CLIMB_MARGIN, CLIMB_SHARE * top)
        rise = _seed_slope(seed, hflat[seed], hs.shape[1])
        if rise is not None:
            # A part leaning on a neighbour or a wall: its top rises along it, and so does
            # the seed; the limit follows the seed's plane (its high end is its own).
            a, b, c = rise
            v, u = np.divmod(idx, hs.shape[1])
            plane = a + b * u + c * v
            keep = np.zeros(len(idx), bool)
            keep[np.isin(idx, seed)] = True
            high = idx[(hflat[idx] > plane + max(CLIMB_MARGIN, CLIMB_SHARE * top)) & ~keep]
        else:
            high = idx[hflat[idx] > limit]
        flat[high] = 0


def _seed_slope(
    seed: NDArray[np.int64], h: NDArray[np.float32], cols: int
) -> tuple[float, float, float] | None:
    """The plane ``h = a + b u + c v`` (pixels) through a seed's heights when they rise by
    more than 10 mm across it (a leaning part's top), else None (a level part: its median)."""
    if len(seed) < MIN_PLANE_SEED:
        return None
    v, u = np.divmod(seed, cols)
    u = u.astype(np.float64)
    v = v.astype(np.float64)
    hh = h.astype(np.float64)
    um, vm, hm_ = u.mean(), v.mean(), hh.mean()
    du, dv, dh = u - um, v - vm, hh - hm_
    m = np.array([[np.sum(du * du), np.sum(du * dv)], [np.sum(du * dv), np.sum(dv * dv)]])
    r = np.array([np.sum(du * dh), np.sum(dv * dh)])
    if abs(float(np.linalg.det(m))) < MIN_SCATTER_DET:
        return None
    b, c = np.linalg.solve(m, r)
    fit = dh - (b * du + c * dv)
    lo, hi = RISE_PERCENTILES
    span = float(np.percentile(b * du + c * dv, hi) - np.percentile(b * du + c * dv, lo))
    if span < LEAN_RISE or float(np.std(fit)) > PLANE_SCATTER * span:
        return None
    return float(hm_ - b * um - c * vm), float(b), float(c)


def _principal(xy: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean and major axis of 2D points, from the 2 x 2 scatter (no BLAS call: its threads
    spin-wait, see :func:`heightmap.dot_last`)."""
    mean = xy.mean(axis=0)
    d = xy - mean
    sxx, syy, sxy = (
        float(np.sum(d[:, 0] ** 2)),
        float(np.sum(d[:, 1] ** 2)),
        float(np.sum(d[:, 0] * d[:, 1])),
    )
    axis = np.linalg.eigh(np.array([[sxx, sxy], [sxy, syy]]))[1][:, 1]
    return mean, axis


def _merge_pieces(
    labels: NDArray[np.int32],
    h: NDArray[np.float32],
    xy: NDArray[np.float32],
    max_height: float,
) -> NDArray[np.int32]:
    """Join neighbouring segments of one part that the seeds split (a thin, noisy top: a lone
    rail can come out in three pieces): the same height (to 2 mm or 10 %) and together no wider
    than the wider of them, as pieces end to end are; two parts side by side make a union
    twice as wide. ``xy``: (H, W, 2) base-frame coordinates (m), so widths are metric. Only
    pieces lower than ``max_height`` (a thin part) are joined: two tall parts end to end or in
    a T would pass the same tests."""
    k_max = int(labels.max(initial=0))
    if k_max < 2:  # exact: a join takes two segments
        return labels
    # Moments per segment (count, sums of x, y, xx, yy, xy): a union's spread is their sum.
    mom: dict[int, NDArray[np.float64]] = {}
    top: dict[int, float] = {}
    px = xy.reshape(-1, 2)
    hh = h.reshape(-1)
    for k, idx in _groups(labels).items():
        p = px[idx].astype(np.float64)
        ok = np.isfinite(p[:, 0])
        p = p[ok]
        if len(p) < MIN_PIECE:
            continue
        x, y = p[:, 0], p[:, 1]
        mom[k] = np.array([len(p), x.sum(), y.sum(), (x * x).sum(), (y * y).sum(), (x * y).sum()])
        top[k] = float(np.percentile(hh[idx[ok]], TOP_PERCENTILE))
    # The watershed leaves a one-pixel line (-1) between the regions it grows, so neighbours
    # are looked for up to two pixels apart.
    pairs = set()
    rows, cols = labels.shape
    for dv, du in NEIGHBOUR_OFFSETS:
        a = labels[: rows - dv, max(0, -du) : cols - max(0, du)]
        b = labels[dv:, max(0, du) : cols - max(0, -du)]
        m = (a > 0) & (b > 0) & (a != b)
        pairs.update(zip(a[m].tolist(), b[m].tolist(), strict=True))
    parent = {k: k for k in range(k_max + 1)}

    def find(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    # Most alike heights first; each test is on the groups merged so far.
    ranked = sorted(
        (abs(top[a] - top[b]), a, b) for a, b in pairs if a < b and a in mom and b in mom
    )
    for _, a, b in ranked:
        ra, rb = find(a), find(b)
        if ra == rb:
            continue
        ha, hb = top[ra], top[rb]
        if max(ha, hb) > max_height or abs(ha - hb) > max(
            JOIN_HEIGHT_TOL, JOIN_HEIGHT_SHARE * max(ha, hb)
        ):
            continue
        union = mom[ra] + mom[rb]
        wider = max(_minor_std(mom[ra]), _minor_std(mom[rb]))
        if _minor_std(union) > JOIN_WIDTH_GROWTH * wider + JOIN_WIDTH_MARGIN:
            continue  # side by side: two parts
        parent[ra] = rb
        mom[rb] = union
        top[rb] = (ha * mom[ra][0] + hb * (union[0] - mom[ra][0])) / union[0]
    remap = np.array([find(k) for k in range(k_max + 1)], np.int32)
    return remap[labels]


def _minor_std(m: NDArray[np.float64]) -> float:
    """Spread (m, one standard deviation) across the major axis, from the moments."""
    n, mx, my, mxx, myy, mxy = m
    cx, cy = mx / n, my / n
    sxx, syy, sxy = mxx / n - cx * cx, myy / n - cy * cy, mxy / n - cx * cy
    tr, det = sxx + syy, sxx * syy - sxy * sxy
    # The smaller eigenvalue of the 2 x 2 scatter: tr/2 - sqrt(tr^2/4 - det).
    minor = 0.5 * tr - math.sqrt(max(0.25 * tr * tr - det, 0.0))  # exact: that eigenvalue
    return float(math.sqrt(max(minor, 0.0)))


def _plane_basis(normal: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    e1 = np.cross(normal, [0.0, 1.0, 0.0])
    if np.linalg.norm(e1) < PARALLEL:
        e1 = np.cross(normal, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


def _match(
    length: float, outer: float, catalogue: list[Part], tol: float
) -> tuple[Part | None, float]:
    best, best_err = None, math.inf
    for part in catalogue:
        err = math.hypot((length - part.length) / part.length, (outer - part.outer) / part.outer)
        if err < best_err:
            best, best_err = part, err
    if best is None or best_err > tol:
        return None, best_err
    return best, best_err


def detect_parts(
    frame: Frame,
    intr: Intrinsics,
    world_T_camera: Pose,
    catalogue: list[Part],
    roi: tuple[float, float, float, float] | None = None,
    robot_xy: tuple[float, float] = (0.0, 0.0),
    settings: DetectorSettings = DetectorSettings(),
    segmenter: object | None = None,
) -> list[Detection]:
    """Every part lying in view, and every part standing on an end (``standing``).
    ``segmenter``: an object with ``segment(hm, rgb)`` (the learned option) used instead of the
    classical segmentation."""
    hm = height_map(frame, intr, world_T_camera, roi)
    if segmenter is not None:
        labels = segmenter.segment(hm, frame.rgb)  # type: ignore[attr-defined]
    else:
        thin = tuple(p.outer for p in catalogue if p.outer < settings.thin_part)
        labels = segment(hm, settings, thin)
    lying = fit_segments(hm, labels, catalogue, robot_xy, settings, world_T_camera.position)
    from skills.perception.standing import find_standing  # it builds on Detection

    standing = find_standing(hm, catalogue)
    # A standing part's flank can pass for a short lying part there: the top decides. A part
    # lying against it (its centre a radius and more away) stays.
    lying = [
        d
        for d in lying
        if all(
            math.dist(d.center[:2], s.center[:2]) > 0.5 * s.outer  # exact: its radius
            for s in standing
        )
    ]
    return lying + standing


def fit_segments(
    hm: HeightMap,
    labels: NDArray[np.int32],
    catalogue: list[Part],
    robot_xy: tuple[float, float] = (0.0, 0.0),
    settings: DetectorSettings = DetectorSettings(),
    camera_position: NDArray[np.float64] | None = None,
) -> list[Detection]:
    """Fit every labelled segment; ``camera_position`` (base frame) tells which end faces the
    camera, the one end whose face (or inside) a single view can show."""
    cam = np.zeros(3) if camera_position is None else np.asarray(camera_position, float)
    n = hm.plane.normal
    e1, e2 = _plane_basis(n)
    pts = hm.points.reshape(-1, 3)  # float32: twice as fast as float64, sub-0.1 mm here
    hgt = np.nan_to_num(hm.height.reshape(-1), nan=-1.0)
    # Heights median-filtered (5 x 5) for the outer size: on a flat top the depth noise
    # (1.25 mm at 0.5 m) would otherwise push the 80th percentile 1 mm up, 13 % of a rail.
    h0 = np.nan_to_num(hm.height, nan=0.0).astype(np.float32)
    smooth = cv2.medianBlur(h0, MEDIAN_APERTURE).reshape(-1)
    uv_all = np.column_stack([dot_last(pts, e1), dot_last(pts, e2)])
    inputs = _FitInputs(uv_all, hgt, smooth, hm, e1, e2, catalogue, robot_xy, settings, cam)
    out: list[Detection] = []
    for _, idx in sorted(_groups(labels).items()):
        if len(idx) < settings.min_pixels and (
            len(idx) < settings.min_stub
            or float(np.percentile(smooth[idx], TOP_PERCENTILE)) >= settings.thin_part
        ):
            continue  # too small for a part, and not the end of a thin one (_hidden_thin_part)
        out.extend(_fit_one(idx, inputs))
    return out


@dataclass(frozen=True)
class _FitInputs:
    """What every segment's fit reads besides its own pixels, computed once per frame: each
    pixel's point in the floor plane's basis (``uv``, m), its height (``hgt``, -1 where
    invalid) and its 5 x 5 median-filtered height (``smooth``); the basis ``e1``, ``e2``; the
    catalogue, the robot's place (a tube's hole end is the far one) and the camera's (``cam``,
    which end a cup shows)."""

    uv: NDArray[np.float64]
    hgt: NDArray[np.float64]
    smooth: NDArray[np.float32]
    hm: HeightMap
    e1: NDArray[np.float64]
    e2: NDArray[np.float64]
    catalogue: list[Part]
    robot_xy: tuple[float, float]
    settings: DetectorSettings
    cam: NDArray[np.float64]


@dataclass(frozen=True)
class _Segment:
    """One segment measured on its upper half (the points above half its top): the principal
    axis through their ``mean``, where they lie along (``s``) and across (``c``) it, the
    width and length they span, the outer size from the heights, and the thin catalogue part
    of that size (if any)."""

    idx: NDArray[np.int64]  #: flat pixel indices of the whole segment
    upper: NDArray[np.int64]  #: those of its upper half
    uv: NDArray[np.float64]  #: the upper half's points (m, plane basis)
    top: float
    outer: float
    mean: NDArray[np.float64]
    axis: NDArray[np.float64]
    across: NDArray[np.float64]
    s: NDArray[np.float64]
    c: NDArray[np.float64]
    width: float
    length: float
    thin: Part | None


@dataclass(frozen=True)
class _Placement:
    """A part found in a segment, before its hole end is chosen: the catalogue part, the fit's
    error, whether it rests on the catalogue length (``partial``: mostly hidden), its axis and
    the direction across it, its centre (plane basis) and the length seen."""

    part: Part
    err: float
    partial: bool
    axis: NDArray[np.float64]
    across: NDArray[np.float64]
    center_uv: NDArray[np.float64]
    length: float
    tilted: bool = False  #: not level on the floor (:func:`_raised`): its ends are not judged
    #: m above the floor, its axis at its middle, where that is not half its seen height (a
    #: part raised at one end or both: its crest's height there less half the catalogue size)
    axis_height: float | None = None


def _fit_one(idx: NDArray[np.int64], inputs: _FitInputs, split: bool = True) -> list[Detection]:
    """The parts in one segment: one fit, or, when it is as wide as several parts side by side
    and ``split`` allows, one per strip (or cluster), each fitted on its own."""
    seg = _measure(idx, inputs)
    if seg is None:
        return []
    if split and _side_by_side(seg, inputs.settings):
        return _fit_side_by_side(seg, inputs)
    placed = _place(seg, inputs)
    if placed is None or not _reported(seg, placed, inputs.settings):
        return []
    return [_detection(seg, placed, inputs)]


def _measure(idx: NDArray[np.int64], inputs: _FitInputs) -> _Segment | None:
    """The segment's upper half along its principal axis (None: too few points for a fit)."""
    h = inputs.hgt[idx]
    # The 80th percentile of a lying cylinder's heights is within 2 % of its diameter, and it
    # keeps the depth noise (1.25 mm at 0.5 m) from inflating thin parts like the rail.
    top = float(np.percentile(h, TOP_PERCENTILE))
    outer = float(np.percentile(inputs.smooth[idx], TOP_PERCENTILE))
    upper = idx[h > UPPER_SHARE * top]
    if len(upper) < MIN_UPPER:
        return None
    uv = inputs.uv[upper].astype(np.float64)
    mean, axis = _principal(uv)
    across = np.array([-axis[1], axis[0]])
    s = dot_last(uv - mean, axis)
    c = dot_last(uv - mean, across)
    width = float(np.percentile(c, EXTENT_HI) - np.percentile(c, EXTENT_LO))
    thin = _thin_match(outer, inputs.catalogue, inputs.settings)
    length = float(np.percentile(s, EXTENT_HI) - np.percentile(s, EXTENT_LO))
    return _Segment(idx, upper, uv, top, outer, mean, axis, across, s, c, width, length, thin)


def _side_by_side(seg: _Segment, settings: DetectorSettings) -> bool:
    """Touching boxes leave no valley: a segment ``n`` parts wide is ``n`` parts side by side.

    Two thin parts side by side, the second partly under a taller neighbour's overhang: a
    segment as long as the part but wider by a good part of its width (one alone was at most
    1.2 times as wide in 600 scenes: its top and a little of a side face)."""
    thin = seg.thin
    pair = (
        thin is not None
        and seg.width > settings.thin_pair * thin.outer
        and abs(seg.length - thin.length) < settings.match_tolerance * thin.length
    )
    return seg.width > SIDE_BY_SIDE_WIDTH * seg.outer or pair


# ----------------------------------------------------------- a segment of several parts
def _fit_side_by_side(seg: _Segment, inputs: _FitInputs) -> list[Detection]:
    """Each strip across the segment fitted on its own (its own axis and length); compact
    clusters instead when they explain more of it."""
    axis, across, c, width = _rect_aligned(seg)
    strips = max(2, int(round(width / max(seg.outer, MIN_LENGTH))))  # exact: at least a pair
    out = _fit_strips(seg, inputs, axis, across, c, width, strips)
    if len(out) < strips:
        # Parts touching end to side (a Z of two ducts) are not strips: split the segment
        # into as many compact clusters instead, and keep that if it explains more of it.
        alt = _fit_clusters(seg, inputs, strips)
        if len(alt) > len(out):
            out = alt
    return out


def _rect_aligned(
    seg: _Segment,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]:
    """Side by side and offset along their axes, two parts make a blob whose principal axis
    is diagonal; the smallest enclosing rectangle stays aligned with them. Its axis (turned
    like the principal one), the direction across, the points across it and the width."""
    (_, _), (rw, rh), ang = cv2.minAreaRect((seg.uv * MM_PER_M).astype(np.float32))
    a = math.radians(ang)
    cand = np.array([math.cos(a), math.sin(a)])
    if rh > rw:
        cand = np.array([-cand[1], cand[0]])
    axis = cand if float(cand @ seg.axis) >= 0 else -cand
    across = np.array([-axis[1], axis[0]])
    c = dot_last(seg.uv - seg.mean, across)
    width = float(np.percentile(c, EXTENT_HI) - np.percentile(c, EXTENT_LO))
    return axis, across, c, width


def _fit_strips(
    seg: _Segment,
    inputs: _FitInputs,
    axis: NDArray[np.float64],
    across: NDArray[np.float64],
    c: NDArray[np.float64],
    width: float,
    strips: int,
) -> list[Detection]:
    """The segment cut into ``strips`` equal strips across ``axis`` (or, for thin parts, strips
    of the catalogue width from the free side), each fitted on its own."""
    c_all = dot_last(inputs.uv[seg.idx] - seg.mean, across)
    c_lo, c_hi = float(np.percentile(c, EXTENT_LO)), float(np.percentile(c, EXTENT_HI))
    edges = np.linspace(c_lo, c_hi, strips + 1)
    clipped, c_true = -1, 0.0
    thin = seg.thin
    if thin is not None and width < (strips - STRIP_SHORTFALL) * thin.outer:
        from_free = _strips_from_free_side(seg, inputs, axis, across, (c_lo, c_hi), strips, thin)
        if from_free is not None:
            edges, clipped, c_true = from_free
    edges[0], edges[-1] = -np.inf, np.inf
    out: list[Detection] = []
    for j in range(strips):
        sub = seg.idx[(c_all >= edges[j]) & (c_all < edges[j + 1])]
        if len(sub) >= inputs.settings.min_pixels // STRIP_PIXEL_DIVISOR:
            found = _fit_one(sub, inputs, False)
            if j == clipped:
                e1, e2 = inputs.e1, inputs.e2
                found = [_moved_across(d, seg.mean, across, c_true, e1, e2) for d in found]
            out += found
    return out


def _strips_from_free_side(
    seg: _Segment,
    inputs: _FitInputs,
    axis: NDArray[np.float64],
    across: NDArray[np.float64],
    c_range: tuple[float, float],
    strips: int,
    thin: Part,
) -> tuple[NDArray[np.float64], int, float] | None:
    """Thin parts narrower together than the catalogue says: the one beside the taller
    neighbour is partly under it. The strips are the catalogue's width from the free side;
    the last, clipped one's centre is placed a whole width further on. Returns the strips'
    edges across, the clipped strip and its centre across; None when no side is the free one.
    """
    c_lo, c_hi = c_range
    win = _window(seg.idx, inputs.hm, FREE_SIDE_WINDOW)
    lo, hi = FREE_SIDE_PERCENTILES
    s_in = (float(np.percentile(seg.s, lo)), float(np.percentile(seg.s, hi)))
    uv, hgt = inputs.uv[win], inputs.hgt[win]
    free = [
        _side_free(uv, hgt, seg.mean, axis, across, s_in, edge, sign, inputs.settings)
        for edge, sign in ((c_lo, -1.0), (c_hi, 1.0))
    ]
    steps = thin.outer * np.arange(strips + 1)
    if free == [True, False]:
        last = c_lo + (strips - 0.5) * thin.outer  # exact: the last strip's middle
        return c_lo + steps, strips - 1, last
    if free == [False, True]:
        last = c_hi - (strips - 0.5) * thin.outer  # exact: the last strip's middle
        return (c_hi - steps)[::-1].copy(), 0, last
    return None


def _fit_clusters(seg: _Segment, inputs: _FitInputs, n: int) -> list[Detection]:
    """The segment split into ``n`` compact clusters, each fitted on its own."""
    centres = _clusters(seg.uv * MM_PER_M, n)
    pts_all = inputs.uv[seg.idx] * MM_PER_M
    dist = np.stack([np.hypot(*(pts_all - c).T) for c in centres])
    nearest = np.argmin(dist, axis=0)
    alt: list[Detection] = []
    for j in range(n):
        sub = seg.idx[nearest == j]
        if len(sub) >= inputs.settings.min_pixels:
            alt += _fit_one(sub, inputs, False)
    return alt


# ------------------------------------------------------------------ a segment of one part
def _place(seg: _Segment, inputs: _FitInputs) -> _Placement | None:
    """The part the segment shows, from its crest's axis and its extent along it; a thin part
    mostly hidden under a taller one from its free end (None: it matches no catalogue part)."""
    settings = inputs.settings
    crest = _crest(seg, inputs.hgt[seg.upper])
    #: per candidate axis: (axis, across, s_lo, s_hi, c_mid), the first the default
    fits: list[tuple[NDArray[np.float64], NDArray[np.float64], float, float, float]] = []
    placed: _Placement | None = None
    for axis, across, s, c in _crest_axis_candidates(seg, crest, settings):
        c_mid = float(np.median(c[crest]))
        s_lo, s_hi = float(np.percentile(s, EXTENT_LO)), float(np.percentile(s, EXTENT_HI))
        fits.append((axis, across, s_lo, s_hi, c_mid))
        s_mid = 0.5 * (s_lo + s_hi)  # exact: the middle
        center_uv = seg.mean + s_mid * axis + c_mid * across
        length = s_hi - s_lo
        part, err = _match(length, seg.outer, inputs.catalogue, settings.match_tolerance)
        if part is not None and (placed is None or err < placed.err):
            placed = _Placement(part, err, False, axis, across, center_uv, length)
    if placed is not None:
        return placed
    axis, across, s_lo, s_hi, c_mid = fits[0]
    length = s_hi - s_lo
    if seg.thin is None:
        return _raised(seg, inputs)
    # A thin part partly hidden under a taller one: see _hidden_thin_part.
    hidden = _hidden_under_neighbour(seg, inputs, seg.thin, axis, s_lo, s_hi, c_mid)
    if hidden is None:
        return None
    part, axis, across, center_uv = hidden
    return _Placement(part, settings.match_tolerance, True, axis, across, center_uv, length)


def _on_something(
    seg: _Segment,
    inputs: _FitInputs,
    h: NDArray[np.float64],
    mean: NDArray[np.float64],
    axis: NDArray[np.float64],
    s: NDArray[np.float64],
    c: NDArray[np.float64],
    outer: float,
    c_mid: float,
) -> _Placement | None:
    """A part lying level on something (another part, a wall's foot): seen from above, its
    width is its outer size, and its top is higher than that size (what it lies on is mostly
    hidden under it, so its height above that is not measured). Its top must show the part's
    profile across it (:func:`_lying_profile`): for a round part, a strip cut off a taller
    part's flat top (a duct's half) or a piece between two parts does not; a box part is taken
    on any flat top of its sizes. None on the floor or where nothing matches. Fitted as
    ``tilted`` (not on the floor: its ends are not judged), its axis half its size under its
    top."""
    settings = inputs.settings
    s_lo, s_hi = float(np.percentile(s, EXTENT_LO)), float(np.percentile(s, EXTENT_HI))
    length = s_hi - s_lo
    part, err = _match(length, outer, inputs.catalogue, settings.match_tolerance)
    if part is None or part.outer < settings.thin_part:
        return None
    if seg.outer - part.outer < MIN_FOOT:
        return None  # as high as its size: on the floor, and the height fit found nothing
    if not _lying_profile(c - c_mid, h, seg.outer, outer, part):
        return None
    across = np.array([-axis[1], axis[0]])  # as the caller measured ``c`` along
    center_uv = mean + 0.5 * (s_lo + s_hi) * axis + c_mid * across  # exact: the middle
    axis_height = seg.outer - 0.5 * part.outer  # exact: the axis is half the size under the top
    return _Placement(part, err, False, axis, across, center_uv, length, tilted=True,
                      axis_height=axis_height)


def _lying_profile(
    c: NDArray[np.float64], h: NDArray[np.float64], top: float, width: float, part: Part
) -> bool:
    """Whether the heights ``h`` across a level segment (``c`` each point's distance across
    from its middle, ``width`` wide, ``top`` high) are ``part`` lying: a round
    part's crest in the middle at the top and both flanks falling away from it by what a
    cylinder's do (the median of each outer quarter and a half: :data:`ROUND_FALL` of the size),
    a box's top flat across."""
    middle = h[np.abs(c) < PROFILE_MIDDLE * width]
    sides = [h[c < -PROFILE_SIDE * width], h[c > PROFILE_SIDE * width]]
    if middle.size == 0 or any(x.size == 0 for x in sides):
        return False
    dip = top - float(np.median(middle))
    falls = [top - float(np.median(x)) for x in sides]
    if part.hole_shape == "circle":
        lo, hi = ROUND_FALL_RANGE
        expected = ROUND_FALL * part.outer
        return dip < PROFILE_FLAT * part.outer and all(
            lo * expected <= f <= hi * expected for f in falls
        )
    return max(abs(dip), *map(abs, falls)) < PROFILE_FLAT * part.outer


def _raised(seg: _Segment, inputs: _FitInputs) -> _Placement | None:
    """A part leaning (one end on a neighbour or a wall): its height above the floor is then
    no measure of its size, nor is its upper half all of it; seen from above, its width still
    is its outer size, and its length is the extent along it stretched by the slope of its
    crest (over 4 deg). None when the segment is level or this matches no part either."""
    settings = inputs.settings
    uv = inputs.uv[seg.idx].astype(np.float64)
    h = inputs.smooth[seg.idx].astype(np.float64)
    mean, axis = _principal(uv)
    across = np.array([-axis[1], axis[0]])
    s = dot_last(uv - mean, axis)
    c = dot_last(uv - mean, across)
    lo, hi = LEAN_WIDTH_PERCENTILES
    c_lo, c_hi = float(np.percentile(c, lo)), float(np.percentile(c, hi))
    outer = c_hi - c_lo
    c_mid = 0.5 * (c_lo + c_hi)  # exact: the middle
    band = np.abs(c - c_mid) < LEAN_CREST_BAND * outer  # the crest's strip along the axis
    if np.count_nonzero(band) < MIN_LEAN_CREST:
        return None
    sb, hb = s[band], h[band]
    ds = sb - sb.mean()
    slope = float(np.sum(ds * (hb - hb.mean())) / max(float(np.sum(ds * ds)), MIN_SQUARED))
    if abs(slope) < LEVEL_SLOPE:
        # Level: on the floor the height fit said what it shows. Level on something (a part
        # lying on a duct): its width and length are its sizes, its top higher than its size,
        # its profile across a lying part's; a piece of a flat top or between parts is not.
        return _on_something(seg, inputs, h, mean, axis, s, c, outer, c_mid)
    s_lo, s_hi = float(np.percentile(s, EXTENT_LO)), float(np.percentile(s, EXTENT_HI))
    length = (s_hi - s_lo) * math.sqrt(1.0 + slope * slope)
    part, err = _match(length, outer, inputs.catalogue, settings.match_tolerance)
    if part is None or part.outer < settings.thin_part:
        return None
    s_mid = 0.5 * (s_lo + s_hi)  # exact: the middle
    center_uv = mean + s_mid * axis + c_mid * across
    crest = float(hb.mean()) + slope * (s_mid - float(sb.mean()))  # the crest's line there
    axis_height = crest - 0.5 * part.outer  # exact: the axis is half the size under the crest
    return _Placement(part, err, False, axis, across, center_uv, length, tilted=True,
                      axis_height=axis_height)


def _crest(seg: _Segment, hs: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which of the upper half's points (heights ``hs``) are on the crest, near the top.

    Bounded above too, so that a few pixels of a taller neighbour at the segment's edge do not
    pull the centre towards it. Narrow (3 % of the height): seen obliquely, a cylinder's far
    flank is hidden, so a wide band would be lopsided towards the camera."""
    top = seg.top
    crest = (hs > CREST_SHARE * top) & (hs < top + max(CREST_ABOVE_SHARE * top, CREST_ABOVE))
    if np.count_nonzero(crest) < MIN_CREST:
        crest = hs > CREST_WIDE_SHARE * top
    return crest


def _crest_axis_candidates(
    seg: _Segment, crest: NDArray[np.bool_], settings: DetectorSettings
) -> list[
    tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
]:
    """The axes to fit along, each with the direction across and the upper points along and
    across it; the first is the default.

    The crest of a lying cylinder is a strip along its axis (a cup's is 4-5 times longer
    than wide; its whole top only 1.5 times): where it is the longer strip of the two and
    longer than ``CREST_ASPECT`` times its width, its direction is the axis; short of that,
    both the segment's principal direction and the crest's are given, for the catalogue to
    decide between them (:func:`_place`). A short, wide part lying (a sleeve 50 mm long and
    60 mm across) shows a top wider than long, so the top's principal direction runs across
    it, while its crest (about 2.4 times longer than wide) still runs along the axis: taken
    from the top alone, the pivot's Grasp came down 64-90 deg off the part's axis. Not for a
    thin part: its flat top is all crest."""
    axis, across, s, c = seg.axis, seg.across, seg.s, seg.c
    pts = seg.uv[crest]
    if len(pts) < MIN_CREST_AXIS or seg.outer < settings.thin_part:
        return [(axis, across, s, c)]
    _, crest_axis = _principal(pts)
    rel = pts - pts.mean(axis=0)
    along = dot_last(rel, crest_axis)
    side = dot_last(rel, np.array([-crest_axis[1], crest_axis[0]]))
    aspect = float(np.std(along)) / max(float(np.std(side)), MIN_SPREAD)
    whole = float(np.std(s)) / max(float(np.std(c)), MIN_SPREAD)
    if aspect <= whole:
        return [(axis, across, s, c)]
    crest_axis = crest_axis if float(crest_axis @ axis) >= 0 else -crest_axis
    crest_across = np.array([-crest_axis[1], crest_axis[0]])
    along_crest = (
        crest_axis,
        crest_across,
        dot_last(seg.uv - seg.mean, crest_axis),
        dot_last(seg.uv - seg.mean, crest_across),
    )
    if aspect > CREST_ASPECT:
        return [along_crest]
    return [(axis, across, s, c), along_crest]


def _hidden_under_neighbour(
    seg: _Segment,
    inputs: _FitInputs,
    thin: Part,
    axis: NDArray[np.float64],
    s_lo: float,
    s_hi: float,
    c_mid: float,
) -> tuple[Part, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None:
    """A thin part mostly under a taller neighbour (:func:`_hidden_thin_part`): the part, its
    axis, the direction across and its centre (plane basis); None if the segment is not one.

    A stub's rest is looked for under its neighbour, and its axis is uncertain (11 by 8 mm):
    the enclosing rectangle's long side is tried after the principal axis."""
    settings = inputs.settings
    stub = s_hi - s_lo < settings.min_hidden * thin.length
    win = _window(seg.idx, inputs.hm, thin.length if stub else HIDDEN_WINDOW)
    axes = [(axis, s_lo, s_hi, c_mid, seg.width)]
    if stub:
        axes.append(_rect_axis(seg.uv, seg.mean, axis))
    smooth = inputs.smooth[seg.idx]
    lo, hi = RELIEF_PERCENTILES
    relief = float(np.percentile(smooth, hi) - np.percentile(smooth, lo))
    uv, hgt = inputs.uv[win], inputs.hgt[win]
    for ax, lo, hi, mid, wide in axes:
        ac = np.array([-ax[1], ax[0]])
        found = _hidden_thin_part(
            uv,
            hgt,
            seg.mean,
            ax,
            ac,
            lo,
            hi,
            mid,
            seg.outer,
            wide,
            relief,
            inputs.catalogue,
            settings,
        )
        if found is not None:
            part, s_mid = found
            return part, ax, ac, seg.mean + s_mid * ax + mid * ac
    return None


def _reported(seg: _Segment, placed: _Placement, settings: DetectorSettings) -> bool:
    """Whether a placed part is reported: a small segment only as a thin part's stub, and not
    a strip of a bigger part's flank."""
    if len(seg.idx) < settings.min_pixels and not placed.partial:
        return False  # small segments are only reported as thin parts' stubs
    part = placed.part
    # As tall and as long as the part but much narrower: a strip of a bigger part's flank cut
    # off by the watershed (one of a can's gave a cup), not a part.
    return not (part.outer >= settings.thin_part and seg.width < settings.min_width * part.outer)


def _detection(seg: _Segment, placed: _Placement, inputs: _FitInputs) -> Detection:
    """The placed part in the base frame, with the end for the hole finger."""
    hm, e1, e2, part = inputs.hm, inputs.e1, inputs.e2, placed.part
    center_uv, axis = placed.center_uv, placed.axis
    # Level, its axis is half its size under its top: half the top's height on the floor,
    # higher on something (the raised part the cell lays down before the pivot)
    up = placed.axis_height
    if up is None:
        up = max(0.5 * seg.outer, seg.outer - 0.5 * part.outer)  # exact: halves
    center = center_uv[0] * e1 + center_uv[1] * e2 + (hm.plane.offset + up) * hm.plane.normal
    direction = axis[0] * e1 + axis[1] * e2
    half = 0.5 * part.length  # exact: an end is half the length from the centre
    ends = [center + half * direction, center - half * direction]
    if part.open_ends == 1 and placed.tilted:
        choice, seen = 0, False  # the end tests assume a part level on the floor
    elif part.open_ends == 1:
        choice, seen = _open_end_in_view(seg, placed, inputs)
    else:  # a tube: the end farther from the robot
        d = [math.hypot(e[0] - inputs.robot_xy[0], e[1] - inputs.robot_xy[1]) for e in ends]
        choice, seen = (0 if d[0] >= d[1] else 1), True
    end = ends[choice]
    toward = end - center
    yaw = math.atan2(toward[1], toward[0])
    conf = float(math.exp(-((placed.err / CONFIDENCE_SCALE) ** 2)))
    if placed.partial:  # the centre rests on the catalogue length, not on a seen extent
        conf = CATALOGUE_CONFIDENCE
    return Detection(
        center=center,
        yaw=yaw,
        length=placed.length,
        outer=seg.outer,
        part=part.name,
        open_end=end,
        open_end_seen=seen,
        confidence=conf * (1.0 if seen else UNDECIDED_END),
        pixels=len(seg.idx),
        tilted=placed.tilted,
        raised=max(0.0, up - 0.5 * part.outer),  # exact: lying, the axis is half the size up
    )


def _open_end_in_view(seg: _Segment, placed: _Placement, inputs: _FitInputs) -> tuple[int, bool]:
    """A cup's or bottle's open end: 0 the ``+axis`` end, 1 the other; and whether the view
    decided it.

    One view shows one end face: the end turned towards the camera. Its inside seen through
    the opening means it is the open end; its face without an inside means the closed one, so
    the open end is the other. Between a clear view inside and none at all the view is not
    trusted: undecided."""
    cam, e1, e2, hm, settings = inputs.cam, inputs.e1, inputs.e2, inputs.hm, inputs.settings
    part, center_uv, axis, across = placed.part, placed.center_uv, placed.axis, placed.across
    cam_uv = np.array([cam @ e1, cam @ e2])
    # Only the pixels around this part matter: one pass picks them.
    near = _window(seg.idx, hm, END_WINDOW_SHARE * part.length + part.outer)
    reach = 0.5 * part.length + part.outer  # exact: an outer size past either end
    near = near[np.abs(inputs.uv[near] - center_uv).max(axis=1) < reach]
    uv, hgt = inputs.uv[near], inputs.hgt[near]
    height = float(cam @ hm.plane.normal - hm.plane.offset)
    return _end_evidence(
        uv, hgt, center_uv, axis, across, part, cam_uv, height, hm.pixel_size, settings
    )


def _end_evidence(
    uv: NDArray[np.float64],
    hgt: NDArray[np.float64],
    center_uv: NDArray[np.float64],
    axis: NDArray[np.float64],
    across: NDArray[np.float64],
    part: Part,
    cam_uv: NDArray[np.float64],
    cam_height: float,
    pixel_size: float,
    settings: DetectorSettings,
) -> tuple[int, bool]:
    """What the end turned towards the camera shows (points ``uv``, heights ``hgt`` around a
    part placed at ``center_uv`` along ``axis``, camera ``cam_height`` over the floor, where
    a pixel covers ``pixel_size``): 0 the ``+axis`` end open, 1 the other, and whether the
    view decided it.

    Open: points seen inside, and few on the end face compared with them (a cavity); a
    neighbour's flank or the floor beside a closed end also puts points in the band inside,
    but the closed face in front of them stays. Closed: nothing inside and most of the face
    a whole end would show from there (a bottle's neck end shows a ring of its rim only)."""
    facing = 0 if float((cam_uv - center_uv) @ axis) >= 0.0 else 1
    sign = 1.0 if facing == 0 else -1.0
    center_uv = _end_on_crest(uv, hgt, center_uv, sign * axis, across, part)
    inside, face = _end_view(uv, hgt, center_uv, sign * axis, across, part)
    lateral = abs(float((cam_uv - center_uv) @ axis)) - 0.5 * part.length  # exact: from the end
    ratio = lateral / max(cam_height, MIN_LENGTH)
    whole = _face_expected(part, ratio, cam_height, pixel_size)
    cavity = max(settings.max_face_per_inside * inside, settings.max_open_face_share * whole)
    is_open = inside >= settings.min_inside and face <= cavity
    is_closed = (
        inside <= settings.max_closed
        and face >= settings.min_face
        and face >= settings.min_face_share * whole
    )
    seen = ratio > settings.min_end_view and (is_open or is_closed)
    return (facing if is_open else 1 - facing), seen


def _face_expected(part: Part, ratio: float, cam_height: float, pixel_size: float) -> float:
    """The scale of the face count :func:`_end_view` finds on a whole (closed) end face seen at
    ``ratio`` (tan of the angle off the vertical) from ``cam_height`` over the floor: the strip
    it counts (0.8 hole wide, 0.7 outer high) foreshortened by the view's slant, over a
    square pixel's footprint at that distance (``pixel_size`` is a pixel's width on the
    floor). The D435's pixels are not square (fy over fx 1.34 in the twin), so a whole face
    renders about 1.4 times this; the shares in :class:`DetectorSettings` are of this scale."""
    if ratio <= 0.0:
        return 0.0
    low, high = FACE_MIDDLE
    area = (2 * FACE_HALF_WIDTH * part.hole) * ((high - low) * part.outer)  # exact: the strip
    middle = 0.5 * part.outer  # exact: the end's middle, half the outer size up
    depth = max(cam_height - middle, MIN_FACE_DEPTH)
    focal = cam_height / max(pixel_size, MIN_SPREAD)  # pixels per metre at the floor, times depth
    slant = ratio / math.sqrt(1.0 + ratio * ratio)  # cosine of the face's normal to the ray
    return area * slant * focal * focal / (depth * depth * (1.0 + ratio * ratio))


def _end_on_crest(
    uv: NDArray[np.float64],
    hgt: NDArray[np.float64],
    center_uv: NDArray[np.float64],
    axis: NDArray[np.float64],
    across: NDArray[np.float64],
    part: Part,
) -> NDArray[np.float64]:
    """The part's centre moved so that its ``+axis`` end is where its crest ends.

    The inside is looked for just within the end: a centre a few millimetres off along the
    axis (a part touching another, or seen in an earlier view) puts bare floor beyond a closed
    end into that band, which then reads as a view inside. The crest (the top line, at the
    part's height) runs to the end's rim whether the end is open or closed, so its end is the
    end's place; it also gives the axis' place across. Unchanged when no crest is seen there
    (a leaning part, or the top hidden)."""
    s, c = _along_across(uv, center_uv, axis, across)
    half = 0.5 * part.length  # exact: the end is half the length from the centre
    low, high = END_CREST_HEIGHT
    crest = (
        (np.abs(c) < END_CREST_HALF_WIDTH * part.outer)
        & (hgt > low * part.outer)
        & (hgt < high * part.outer)
        & (s > 0.0)
        & (s < half + END_CREST_BEYOND)
    )
    if np.count_nonzero(crest) < MIN_END_CREST:
        return center_uv
    s_end = float(np.percentile(s[crest], END_CREST_PERCENTILE))
    if abs(s_end - half) > END_CREST_SHIFT:
        return center_uv  # not this part's end: something else on its line
    return center_uv + (s_end - half) * axis + float(np.median(c[crest])) * across


def open_end_from_view(
    det: Detection,
    part: Part,
    frame: Frame,
    intr: Intrinsics,
    world_T_camera: Pose,
    roi: tuple[float, float, float, float] | None = None,
    settings: DetectorSettings = DetectorSettings(),
) -> Detection:
    """``det`` (a cup or bottle found in an earlier view) with its open end judged from a view
    taken beyond one of its ends: that end's inside seen through the opening makes it the open
    one, its closed face the other. The part is not looked for again (a close view may hold
    only part of it): its place from ``det`` is where the end is looked at. Unchanged when this
    view does not decide either, or when ``det`` was fitted as leaning (``tilted``): seen
    from beside, a raised end's face and the floor under it read like an end looked into (on
    the tuning scenes half the leaning parts' ends so judged were wrong)."""
    if det.tilted:
        return det
    try:
        hm = height_map(frame, intr, world_T_camera, roi)
    except PerceptionInputError:  # a view mostly outside the bin: it shows nothing of the end
        return det
    e1, e2 = _plane_basis(hm.plane.normal)
    direction = np.array([math.cos(det.yaw), math.sin(det.yaw), 0.0])
    axis = np.array([float(direction @ e1), float(direction @ e2)])
    axis /= max(float(np.linalg.norm(axis)), MIN_SQUARED)
    across = np.array([-axis[1], axis[0]])
    center_uv = np.array([float(det.center @ e1), float(det.center @ e2)])
    pts = hm.points
    ok = np.isfinite(pts[..., 0])
    # Only the pixels around the part: a box in the base frame first (cheap), then the plane.
    c = det.center
    reach = 0.5 * part.length + part.outer  # exact: an outer size past either end
    near = ok & (np.abs(np.nan_to_num(pts[..., 0]) - c[0]) < reach)
    near &= np.abs(np.nan_to_num(pts[..., 1]) - c[1]) < reach
    p = pts[near].astype(np.float64)
    uv = np.column_stack([dot_last(p, e1), dot_last(p, e2)])
    hgt = np.nan_to_num(hm.height[near], nan=-1.0).astype(np.float64)
    cam = np.asarray(world_T_camera.position, float)
    cam_uv = np.array([float(cam @ e1), float(cam @ e2)])
    height = float(cam @ hm.plane.normal - hm.plane.offset)
    choice, seen = _end_evidence(
        uv, hgt, center_uv, axis, across, part, cam_uv, height, hm.pixel_size, settings
    )
    if not seen:
        return det
    half = 0.5 * part.length * direction  # exact: an end is half the length from the centre
    end = det.center + (half if choice == 0 else -half)
    toward = end - det.center
    return replace(
        det,
        yaw=math.atan2(toward[1], toward[0]),
        open_end=end,
        open_end_seen=True,
        confidence=min(1.0, det.confidence / UNDECIDED_END),  # the undecided halving undone
    )


def combine_end_views(det: Detection, judged: list[Detection]) -> Detection:
    """``det`` (undecided) with the open end the views beyond its ends agree on (each
    :func:`open_end_from_view` on ``det``): decided when those that decided agree, undecided
    when they disagree (a neighbour's surface in the band inside an end reads as a view inside;
    a wrong end is worse than none, the planner passes an undecided part over)."""
    decided = [j for j in judged if j.open_end_seen]
    if not decided:
        return det
    first = decided[0]
    if all(abs(_wrap(j.yaw - first.yaw)) < 0.5 * math.pi for j in decided):  # exact: right angle
        return first
    return det


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi  # exact: a full turn


def _thin_match(outer: float, catalogue: list[Part], settings: DetectorSettings) -> Part | None:
    """The thin catalogue part (under ``settings.thin_part``) whose size ``outer`` matches."""
    for part in catalogue:
        if part.outer < settings.thin_part and abs(outer - part.outer) <= max(
            THIN_SIZE_TOL, THIN_SIZE_SHARE * part.outer
        ):
            return part
    return None


def _side_free(
    uv_all: NDArray[np.float64],
    hgt: NDArray[np.float64],
    mean: NDArray[np.float64],
    axis: NDArray[np.float64],
    across: NDArray[np.float64],
    s_in: tuple[float, float],
    edge: float,
    sign: float,
    settings: DetectorSettings,
) -> bool:
    """Bare floor just beyond a segment's long side at ``edge`` (across, from ``mean``), on the
    ``sign`` side, along the segment's extent ``s_in``: False where something stands there or
    nothing is seen (hidden under a taller neighbour)."""
    s, c = _along_across(uv_all, mean, axis, across)
    c = (c - edge) * sign
    beside = (s > s_in[0]) & (s < s_in[1]) & (c > FREE_SIDE_FROM) & (c < FREE_SIDE_TO)
    h = hgt[beside]
    h = h[h > SEEN_ABOVE]
    return len(h) >= MIN_FREE_SIDE and float(np.median(h)) < settings.min_height


def _moved_across(
    det: Detection,
    mean: NDArray[np.float64],
    across: NDArray[np.float64],
    c_true: float,
    e1: NDArray[np.float64],
    e2: NDArray[np.float64],
) -> Detection:
    """``det`` moved across its axis to ``c_true`` (from ``mean``, in the plane basis), with a low
    confidence: its centre rests on the catalogue width, not on what was seen."""
    uv = np.array([float(det.center @ e1), float(det.center @ e2)])
    shift = (c_true - float((uv - mean) @ across)) * (across[0] * e1 + across[1] * e2)
    return replace(
        det,
        center=det.center + shift,
        open_end=det.open_end + shift,
        confidence=min(det.confidence, CATALOGUE_CONFIDENCE),
    )


def _clusters(
    xy: NDArray[np.float64], n: int, iterations: int = CLUSTER_ITERATIONS
) -> NDArray[np.float64]:
    """``n`` k-means centres of 2D points, started at quantiles along the major axis
    (deterministic, unlike a random start)."""
    mean, major = _principal(xy)
    along = dot_last(xy - mean, major)
    # The middles of the n quantiles along the axis, in percent.
    mids = [100.0 * (j + 0.5) / n for j in range(n)]  # exact: the quantiles' middles, in percent
    centres = np.array([mean + float(np.percentile(along, q)) * major for q in mids])
    for _ in range(iterations):
        dist = np.stack([np.hypot(*(xy - c).T) for c in centres])
        nearest = np.argmin(dist, axis=0)
        for j in range(n):
            if np.any(nearest == j):
                centres[j] = xy[nearest == j].mean(axis=0)
    return centres


def _window(idx: NDArray[np.int64], hm: HeightMap, margin: float) -> NDArray[np.int64]:
    """Flat indices of the image window around a segment's pixels ``idx``, grown by
    ``margin`` (m) at the floor, with room for the taller rows (fy > fx) and raised points:
    the neighbourhood tests then read a few thousand pixels instead of the whole frame."""
    rows, cols = hm.height.shape
    v, u = np.divmod(idx, cols)
    grow = int(math.ceil(WINDOW_GROWTH * margin / hm.pixel_size))
    r0, r1 = max(int(v.min()) - grow, 0), min(int(v.max()) + grow + 1, rows)
    c0, c1 = max(int(u.min()) - grow, 0), min(int(u.max()) + grow + 1, cols)
    return (np.arange(r0, r1)[:, None] * cols + np.arange(c0, c1)[None, :]).reshape(-1)


def _rect_axis(
    uv: NDArray[np.float64], mean: NDArray[np.float64], axis: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float, float, float, float]:
    """The long side of the smallest rectangle around ``uv`` as the axis, with the extent
    (s_lo, s_hi), the middle across and the width along it (as :func:`_fit_one` measures them)."""
    (_, _), (rw, rh), ang = cv2.minAreaRect((uv * MM_PER_M).astype(np.float32))
    a = math.radians(ang)
    ax = np.array([math.cos(a), math.sin(a)])
    if rh > rw:
        ax = np.array([-ax[1], ax[0]])
    ax = ax if float(ax @ axis) >= 0 else -ax
    s = dot_last(uv - mean, ax)
    c = dot_last(uv - mean, np.array([-ax[1], ax[0]]))
    lo, hi = float(np.percentile(s, EXTENT_LO)), float(np.percentile(s, EXTENT_HI))
    width = float(np.percentile(c, EXTENT_HI) - np.percentile(c, EXTENT_LO))
    return ax, lo, hi, float(np.median(c)), width


def _hidden_thin_part(
    uv_all: NDArray[np.float64],
    hgt: NDArray[np.float64],
    mean: NDArray[np.float64],
    axis: NDArray[np.float64],
    across: NDArray[np.float64],
    s_lo: float,
    s_hi: float,
    c_mid: float,
    outer: float,
    width: float,
    relief: float,
    catalogue: list[Part],
    settings: DetectorSettings,
) -> tuple[Part, float] | None:
    """A segment too short for any part, with the cross-section of a thin catalogue part (as
    tall and as wide as it), one end on the bare floor and the other running on under something
    (heights above the floor beyond it, or nothing seen there: the floor hidden by a taller
    neighbour): that part, mostly hidden under its neighbour (a rail against a can is overhung
    by it from most views). The free end is a true end, so the centre is half the catalogue
    length from it. Returns (part, centre along ``axis`` from ``mean``) or None.

    A stub shorter than ``min_hidden`` of the part is no longer than a patch of a cup's inside
    or a can's end face at the same height, so it must also show the part's whole width and a
    flat top (``relief``: the spread of its filtered heights), and the rest of the part's length
    must lie under taller surfaces."""
    length = s_hi - s_lo
    for part in catalogue:
        if part.outer >= settings.thin_part:
            continue
        slack = max(THIN_SIZE_TOL, THIN_SIZE_SHARE * part.outer)
        if abs(outer - part.outer) > slack or width > part.outer + 2 * slack:  # exact: both sides
            continue
        if not settings.min_stub_length * part.length <= length < MAX_HIDDEN_SHARE * part.length:
            continue
        stub = length < settings.min_hidden * part.length
        if stub and (relief > settings.max_stub_relief or width < STUB_WIDTH * part.outer):
            continue
        ends, rest = [], []
        rel = uv_all - (mean + c_mid * across)
        c = dot_last(rel, across)
        on_line = np.abs(c) < 0.5 * part.outer  # exact: within its outline, half its size
        for sign, s_end in ((1.0, s_hi), (-1.0, s_lo)):
            # Heights just beyond this end, on the part's line.
            s = dot_last(rel, axis) * sign - sign * s_end
            beyond = (s > BEYOND_FROM) & (s < BEYOND_TO) & on_line
            h = hgt[beyond]
            seen = h > SEEN_ABOVE
            if stub and np.count_nonzero(seen) < MIN_BEYOND:
                # Hardly any floor seen just beyond a stub's end: hidden under a taller part
                # (beside a taller part the floor is in its shadow for several millimetres).
                ends.append("hidden")
            elif np.count_nonzero(seen) < MIN_BEYOND:
                ends.append("unknown")
            elif float(np.median(h[seen])) < settings.min_height:
                ends.append("free")
            else:  # a taller part over it, or a sliver of it seen past that part's flank
                ends.append("hidden")
            # What is seen over the rest of the part's length, were this end the hidden one.
            h = hgt[(s > BEYOND_FROM) & (s < part.length - length) & on_line]
            h = h[h > SEEN_ABOVE]
            rest.append(float(np.mean(h > COVER_HEIGHT * part.outer)) if len(h) else 1.0)
        if ends == ["free", "hidden"] and (not stub or rest[1] >= settings.min_cover):
            # The +axis end (s_hi) is the free one.
            return part, s_hi - 0.5 * part.length  # exact: half the length from the free end
        if ends == ["hidden", "free"] and (not stub or rest[0] >= settings.min_cover):
            return part, s_lo + 0.5 * part.length  # exact: half the length from the free end
    return None


def _along_across(
    uv: NDArray[np.float64],
    origin: NDArray[np.float64],
    axis: NDArray[np.float64],
    across: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Where points ``uv`` lie from ``origin``: along ``axis`` and across it (m)."""
    rel = uv - origin
    return dot_last(rel, axis), dot_last(rel, across)


def _end_view(
    uv_all: NDArray[np.float64],
    hgt: NDArray[np.float64],
    center_uv: NDArray[np.float64],
    axis: NDArray[np.float64],
    across: NDArray[np.float64],
    part: Part,
) -> tuple[int, int]:
    """What a view shows of the ``+axis`` end, as two counts of points within the hole's width
    of the axis: those seen through the opening (low, in the band just inside the end) and
    those on the middle of the end face (a closed end shows a disc there, an open end only the
    hole's inside, which lies further in)."""
    s, c = _along_across(uv_all, center_uv, axis, across)
    within = np.abs(c) < FACE_HALF_WIDTH * part.hole
    end = 0.5 * part.length  # exact: the end is half the length from the centre
    # Kept 6 mm inside the end: the lower part of a closed end's own face, blurred by the depth
    # noise and the centre's error, must not count as a view inside.
    near_end = (s > end - INSIDE_DEPTH * part.outer) & (s < end - INSIDE_INSET)
    low = (hgt > INSIDE_FLOOR) & (hgt < INSIDE_LOW * part.outer)
    at_face = np.abs(s - end) < FACE_BAND
    face_low, face_high = FACE_MIDDLE
    middle = (hgt > face_low * part.outer) & (hgt < face_high * part.outer)
    return int(np.count_nonzero(near_end & within & low)), int(
        np.count_nonzero(at_face & within & middle)
    )


def timed_detect(*args, **kwargs) -> tuple[list[Detection], float]:  # type: ignore[no-untyped-def]
    """``detect_parts`` and the seconds it took (for the benchmark)."""
    t0 = time.perf_counter()
    out = detect_parts(*args, **kwargs)
    return out, time.perf_counter() - t0
