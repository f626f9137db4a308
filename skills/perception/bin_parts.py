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
from skills.perception.heightmap import HeightMap, PerceptionInputError, dot_last, height_map


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
    hs = cv2.medianBlur(h, 5)  # edge-preserving: a thin part beside a tall one keeps its top
    gx = cv2.Sobel(hs, cv2.CV_32F, 1, 0, ksize=3) / (8.0 * hm.pixel_size)
    gy = cv2.Sobel(hs, cv2.CV_32F, 0, 1, ksize=3) / (8.0 * hm.pixel_size)
    gentle = np.hypot(gx, gy) < settings.max_seed_slope
    crest = fg & gentle & (h > settings.min_crest)
    # A thin part (the 7.6 mm rail, 7 pixels wide) against a tall one: the filtered slope is
    # steep over most of its width, so it may get no seed there and the tall part's watershed
    # takes it. Its top is a band of its own height, as wide as the part; a tall part's flank
    # crosses that band in a line one or two pixels wide, which the opening removes.
    for size in thin:
        band = (np.abs(hs - size) < max(0.002, 0.25 * size)) & fg
        band = cv2.morphologyEx(band.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        crest |= band > 0
    crest = cv2.morphologyEx(crest.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, comp, stats, _ = cv2.connectedComponentsWithStats(crest, connectivity=4)
    keep = stats[:, cv2.CC_STAT_AREA] >= settings.min_seed
    keep[0] = False
    lut = np.zeros(n, np.int32)
    lut[keep] = np.arange(2, 2 + int(np.count_nonzero(keep)), dtype=np.int32)
    markers = lut[comp]
    markers[~fg] = 1
    if not keep.any():
        return np.zeros(h.shape, np.int32)
    top = float(h.max())
    grey = (255.0 * np.clip(1.0 - h / max(top, 1e-6), 0.0, 1.0)).astype(np.uint8)
    labels = cv2.watershed(cv2.merge([grey, grey, grey]), markers.copy())
    out = np.where(fg & (labels >= 2), labels - 1, 0).astype(np.int32)
    _drop_climbed(out, markers - 1, hs)
    return _merge_pieces(out, hs, hm.points[..., :2], settings.thin_part)


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
        limit = top + max(0.003, 0.1 * top)
        rise = _seed_slope(seed, hflat[seed], hs.shape[1])
        if rise is not None:
            # A part leaning on a neighbour or a wall: its top rises along it, and so does
            # the seed; the limit follows the seed's plane (its high end is its own).
            a, b, c = rise
            v, u = np.divmod(idx, hs.shape[1])
            plane = a + b * u + c * v
            keep = np.zeros(len(idx), bool)
            keep[np.isin(idx, seed)] = True
            high = idx[(hflat[idx] > plane + max(0.003, 0.1 * top)) & ~keep]
        else:
            high = idx[hflat[idx] > limit]
        flat[high] = 0


def _seed_slope(
    seed: NDArray[np.int64], h: NDArray[np.float32], cols: int
) -> tuple[float, float, float] | None:
    """The plane ``h = a + b u + c v`` (pixels) through a seed's heights when they rise by
    more than 10 mm across it (a leaning part's top), else None (a level part: its median)."""
    if len(seed) < 30:
        return None
    v, u = np.divmod(seed, cols)
    u = u.astype(np.float64)
    v = v.astype(np.float64)
    hh = h.astype(np.float64)
    um, vm, hm_ = u.mean(), v.mean(), hh.mean()
    du, dv, dh = u - um, v - vm, hh - hm_
    m = np.array([[np.sum(du * du), np.sum(du * dv)], [np.sum(du * dv), np.sum(dv * dv)]])
    r = np.array([np.sum(du * dh), np.sum(dv * dh)])
    if abs(float(np.linalg.det(m))) < 1e-9:
        return None
    b, c = np.linalg.solve(m, r)
    fit = dh - (b * du + c * dv)
    span = float(np.percentile(b * du + c * dv, 98) - np.percentile(b * du + c * dv, 2))
    if span < 0.010 or float(np.std(fit)) > 0.25 * span:
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
    if k_max < 2:
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
        if len(p) < 10:
            continue
        x, y = p[:, 0], p[:, 1]
        mom[k] = np.array([len(p), x.sum(), y.sum(), (x * x).sum(), (y * y).sum(), (x * y).sum()])
        top[k] = float(np.percentile(hh[idx[ok]], 80))
    # The watershed leaves a one-pixel line (-1) between the regions it grows, so neighbours
    # are looked for up to two pixels apart.
    pairs = set()
    rows, cols = labels.shape
    for dv, du in ((0, 2), (2, 0), (2, 2), (2, -2), (1, 2), (2, 1), (2, -1), (1, -2)):
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
        if max(ha, hb) > max_height or abs(ha - hb) > max(0.002, 0.1 * max(ha, hb)):
            continue
        union = mom[ra] + mom[rb]
        if _minor_std(union) > 1.25 * max(_minor_std(mom[ra]), _minor_std(mom[rb])) + 0.0005:
            continue  # side by side: two parts
        parent[ra] = rb
        mom[rb] = union
        top[rb] = (ha * mom[ra][0] + hb * (union[0] - mom[ra][0])) / union[0]
    remap = np.array([find(k) for k in range(k_max + 1)], np.int32)
    return remap[labels]


def _minor_std(m: NDArray[np.float64]) -> float:
    """Spread (m, one standard deviation) across the major axis, from the moments."""
    n = m[0]
    cx, cy = m[1] / n, m[2] / n
    sxx, syy, sxy = m[3] / n - cx * cx, m[4] / n - cy * cy, m[5] / n - cx * cy
    tr, det = sxx + syy, sxx * syy - sxy * sxy
    return float(math.sqrt(max(0.5 * tr - math.sqrt(max(0.25 * tr * tr - det, 0.0)), 0.0)))


def _plane_basis(normal: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    e1 = np.cross(normal, [0.0, 1.0, 0.0])
    if np.linalg.norm(e1) < 1e-6:
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
    """Every part lying in view. ``segmenter``: an object with ``segment(hm, rgb)`` (the learned
    option) used instead of the classical segmentation."""
    hm = height_map(frame, intr, world_T_camera, roi)
    if segmenter is not None:
        labels = segmenter.segment(hm, frame.rgb)  # type: ignore[attr-defined]
    else:
        thin = tuple(p.outer for p in catalogue if p.outer < settings.thin_part)
        labels = segment(hm, settings, thin)
    return fit_segments(hm, labels, catalogue, robot_xy, settings, world_T_camera.position)


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
    smooth = cv2.medianBlur(np.nan_to_num(hm.height, nan=0.0).astype(np.float32), 5).reshape(-1)
    uv_all = np.column_stack([dot_last(pts, e1), dot_last(pts, e2)])
    inputs = _FitInputs(uv_all, hgt, smooth, hm, e1, e2, catalogue, robot_xy, settings, cam)
    out: list[Detection] = []
    for _, idx in sorted(_groups(labels).items()):
        if len(idx) < settings.min_pixels and (
            len(idx) < settings.min_stub
            or float(np.percentile(smooth[idx], 80)) >= settings.thin_part
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
    top = float(np.percentile(h, 80))
    outer = float(np.percentile(inputs.smooth[idx], 80))
    upper = idx[h > 0.5 * top]
    if len(upper) < 20:
        return None
    uv = inputs.uv[upper].astype(np.float64)
    mean, axis = _principal(uv)
    across = np.array([-axis[1], axis[0]])
    s = dot_last(uv - mean, axis)
    c = dot_last(uv - mean, across)
    width = float(np.percentile(c, 99) - np.percentile(c, 1))
    thin = _thin_match(outer, inputs.catalogue, inputs.settings)
    length = float(np.percentile(s, 99) - np.percentile(s, 1))
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
    return seg.width > 1.6 * seg.outer or pair


# ----------------------------------------------------------- a segment of several parts
def _fit_side_by_side(seg: _Segment, inputs: _FitInputs) -> list[Detection]:
    """Each strip across the segment fitted on its own (its own axis and length); compact
    clusters instead when they explain more of it."""
    axis, across, c, width = _rect_aligned(seg)
    strips = max(2, int(round(width / max(seg.outer, 1e-6))))
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
    (_, _), (rw, rh), ang = cv2.minAreaRect((seg.uv * 1e3).astype(np.float32))
    a = math.radians(ang)
    cand = np.array([math.cos(a), math.sin(a)])
    if rh > rw:
        cand = np.array([-cand[1], cand[0]])
    axis = cand if float(cand @ seg.axis) >= 0 else -cand
    across = np.array([-axis[1], axis[0]])
    c = dot_last(seg.uv - seg.mean, across)
    width = float(np.percentile(c, 99) - np.percentile(c, 1))
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
    c_lo, c_hi = float(np.percentile(c, 1)), float(np.percentile(c, 99))
    edges = np.linspace(c_lo, c_hi, strips + 1)
    clipped, c_true = -1, 0.0
    thin = seg.thin
    if thin is not None and width < (strips - 0.25) * thin.outer:
        from_free = _strips_from_free_side(seg, inputs, axis, across, (c_lo, c_hi), strips, thin)
        if from_free is not None:
            edges, clipped, c_true = from_free
    edges[0], edges[-1] = -np.inf, np.inf
    out: list[Detection] = []
    for j in range(strips):
        sub = seg.idx[(c_all >= edges[j]) & (c_all < edges[j + 1])]
        if len(sub) >= inputs.settings.min_pixels // 2:
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
    win = _window(seg.idx, inputs.hm, 0.01)
    s_in = (float(np.percentile(seg.s, 5)), float(np.percentile(seg.s, 95)))
    uv, hgt = inputs.uv[win], inputs.hgt[win]
    free = [
        _side_free(uv, hgt, seg.mean, axis, across, s_in, edge, sign, inputs.settings)
        for edge, sign in ((c_lo, -1.0), (c_hi, 1.0))
    ]
    steps = thin.outer * np.arange(strips + 1)
    if free == [True, False]:
        return c_lo + steps, strips - 1, c_lo + (strips - 0.5) * thin.outer
    if free == [False, True]:
        return (c_hi - steps)[::-1].copy(), 0, c_hi - (strips - 0.5) * thin.outer
    return None


def _fit_clusters(seg: _Segment, inputs: _FitInputs, n: int) -> list[Detection]:
    """The segment split into ``n`` compact clusters, each fitted on its own."""
    centres = _clusters(seg.uv * 1e3, n)
    pts_all = inputs.uv[seg.idx] * 1e3
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
    axis, across, s, c = _crest_axis(seg, crest, settings)
    c_mid = float(np.median(c[crest]))
    s_lo, s_hi = float(np.percentile(s, 1)), float(np.percentile(s, 99))
    s_mid = 0.5 * (s_lo + s_hi)
    center_uv = seg.mean + s_mid * axis + c_mid * across
    length = s_hi - s_lo
    part, err = _match(length, seg.outer, inputs.catalogue, settings.match_tolerance)
    if part is not None:
        return _Placement(part, err, False, axis, across, center_uv, length)
    if seg.thin is None:
        return _raised(seg, inputs)
    # A thin part partly hidden under a taller one: see _hidden_thin_part.
    hidden = _hidden_under_neighbour(seg, inputs, seg.thin, axis, s_lo, s_hi, c_mid)
    if hidden is None:
        return None
    part, axis, across, center_uv = hidden
    return _Placement(part, settings.match_tolerance, True, axis, across, center_uv, length)


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
    c_lo, c_hi = float(np.percentile(c, 2)), float(np.percentile(c, 98))
    outer = c_hi - c_lo
    c_mid = 0.5 * (c_lo + c_hi)
    band = np.abs(c - c_mid) < 0.2 * outer  # the crest's strip along the axis
    if np.count_nonzero(band) < 30:
        return None
    sb, hb = s[band], h[band]
    ds = sb - sb.mean()
    slope = float(np.sum(ds * (hb - hb.mean())) / max(float(np.sum(ds * ds)), 1e-12))
    if abs(slope) < 0.07:
        # Level: on the floor the height fit said what it shows; level on other parts looks
        # like a strip cut off a taller part (a duct's half as a bushing), so it is not taken.
        return None
    s_lo, s_hi = float(np.percentile(s, 1)), float(np.percentile(s, 99))
    length = (s_hi - s_lo) * math.sqrt(1.0 + slope * slope)
    part, err = _match(length, outer, inputs.catalogue, settings.match_tolerance)
    if part is None or part.outer < settings.thin_part:
        return None
    center_uv = mean + 0.5 * (s_lo + s_hi) * axis + c_mid * across
    return _Placement(part, err, False, axis, across, center_uv, length, tilted=True)


def _crest(seg: _Segment, hs: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which of the upper half's points (heights ``hs``) are on the crest, near the top.

    Bounded above too, so that a few pixels of a taller neighbour at the segment's edge do not
    pull the centre towards it. Narrow (3 % of the height): seen obliquely, a cylinder's far
    flank is hidden, so a wide band would be lopsided towards the camera."""
    top = seg.top
    crest = (hs > 0.97 * top) & (hs < top + max(0.1 * top, 0.004))
    if np.count_nonzero(crest) < 5:
        crest = hs > 0.9 * top
    return crest


def _crest_axis(
    seg: _Segment, crest: NDArray[np.bool_], settings: DetectorSettings
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The axis, the direction across and the upper points along and across it: the crest's
    direction where that is the better axis, else the segment's principal one.

    The crest of a lying cylinder is a strip along its axis (a cup's is 4-5 times longer
    than wide; its whole top only 1.5 times): its direction is the better axis, unless
    the whole top is the longer strip. Not for a thin part: its flat top is all crest."""
    axis, across, s, c = seg.axis, seg.across, seg.s, seg.c
    pts = seg.uv[crest]
    if len(pts) >= 30 and seg.outer >= settings.thin_part:
        _, crest_axis = _principal(pts)
        rel = pts - pts.mean(axis=0)
        along = dot_last(rel, crest_axis)
        side = dot_last(rel, np.array([-crest_axis[1], crest_axis[0]]))
        aspect = float(np.std(along)) / max(float(np.std(side)), 1e-9)
        if aspect > 2.5 and aspect > float(np.std(s)) / max(float(np.std(c)), 1e-9):
            axis = crest_axis if float(crest_axis @ axis) >= 0 else -crest_axis
            across = np.array([-axis[1], axis[0]])
            s = dot_last(seg.uv - seg.mean, axis)
            c = dot_last(seg.uv - seg.mean, across)
    return axis, across, s, c


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
    win = _window(seg.idx, inputs.hm, thin.length if stub else 0.02)
    axes = [(axis, s_lo, s_hi, c_mid, seg.width)]
    if stub:
        axes.append(_rect_axis(seg.uv, seg.mean, axis))
    smooth = inputs.smooth[seg.idx]
    relief = float(np.percentile(smooth, 90) - np.percentile(smooth, 10))
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
    center = (
        center_uv[0] * e1
        + center_uv[1] * e2
        + (hm.plane.offset + 0.5 * seg.outer) * (hm.plane.normal)
    )
    direction = axis[0] * e1 + axis[1] * e2
    half = 0.5 * part.length
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
    conf = float(math.exp(-((placed.err / 0.1) ** 2)))
    if placed.partial:  # the centre rests on the catalogue length, not on a seen extent
        conf = 0.2
    return Detection(
        center=center,
        yaw=yaw,
        length=placed.length,
        outer=seg.outer,
        part=part.name,
        open_end=end,
        open_end_seen=seen,
        confidence=conf * (1.0 if seen else 0.5),
        pixels=len(seg.idx),
        tilted=placed.tilted,
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
    near = _window(seg.idx, hm, 0.25 * part.length + part.outer)
    near = near[np.abs(inputs.uv[near] - center_uv).max(axis=1) < 0.5 * part.length + part.outer]
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
    lateral = abs(float((cam_uv - center_uv) @ axis)) - 0.5 * part.length
    ratio = lateral / max(cam_height, 1e-6)
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
    area = (0.8 * part.hole) * (0.7 * part.outer)
    depth = max(cam_height - 0.5 * part.outer, 1e-3)  # over the end's middle
    focal = cam_height / max(pixel_size, 1e-9)  # pixels per metre at the floor, times depth
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
    half = 0.5 * part.length
    crest = (
        (np.abs(c) < 0.35 * part.outer)
        & (hgt > 0.75 * part.outer)
        & (hgt < 1.2 * part.outer)
        & (s > 0.0)
        & (s < half + 0.02)
    )
    if np.count_nonzero(crest) < 10:
        return center_uv
    s_end = float(np.percentile(s[crest], 98))
    if abs(s_end - half) > 0.015:
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
    axis /= max(float(np.linalg.norm(axis)), 1e-12)
    across = np.array([-axis[1], axis[0]])
    center_uv = np.array([float(det.center @ e1), float(det.center @ e2)])
    pts = hm.points
    ok = np.isfinite(pts[..., 0])
    # Only the pixels around the part: a box in the base frame first (cheap), then the plane.
    c = det.center
    reach = 0.5 * part.length + part.outer
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
    half = 0.5 * part.length * direction
    end = det.center + (half if choice == 0 else -half)
    toward = end - det.center
    return replace(
        det,
        yaw=math.atan2(toward[1], toward[0]),
        open_end=end,
        open_end_seen=True,
        confidence=min(1.0, 2.0 * det.confidence),
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
    if all(abs(_wrap(j.yaw - first.yaw)) < 0.5 * math.pi for j in decided):
        return first
    return det


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _thin_match(outer: float, catalogue: list[Part], settings: DetectorSettings) -> Part | None:
    """The thin catalogue part (under ``settings.thin_part``) whose size ``outer`` matches."""
    for part in catalogue:
        if part.outer < settings.thin_part and abs(outer - part.outer) <= max(
            0.002, 0.25 * part.outer
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
    beside = (s > s_in[0]) & (s < s_in[1]) & (c > 0.0015) & (c < 0.006)
    h = hgt[beside]
    h = h[h > -0.5]  # invalid pixels read -1
    return len(h) >= 20 and float(np.median(h)) < settings.min_height


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
        confidence=min(det.confidence, 0.2),
    )


def _clusters(xy: NDArray[np.float64], n: int, iterations: int = 10) -> NDArray[np.float64]:
    """``n`` k-means centres of 2D points, started at quantiles along the major axis
    (deterministic, unlike a random start)."""
    mean, major = _principal(xy)
    along = dot_last(xy - mean, major)
    centres = np.array(
        [mean + float(np.percentile(along, 100.0 * (j + 0.5) / n)) * major for j in range(n)]
    )
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
    grow = int(math.ceil(1.6 * margin / hm.pixel_size))
    r0, r1 = max(int(v.min()) - grow, 0), min(int(v.max()) + grow + 1, rows)
    c0, c1 = max(int(u.min()) - grow, 0), min(int(u.max()) + grow + 1, cols)
    return (np.arange(r0, r1)[:, None] * cols + np.arange(c0, c1)[None, :]).reshape(-1)


def _rect_axis(
    uv: NDArray[np.float64], mean: NDArray[np.float64], axis: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float, float, float, float]:
    """The long side of the smallest rectangle around ``uv`` as the axis, with the extent
    (s_lo, s_hi), the middle across and the width along it (as :func:`_fit_one` measures them)."""
    (_, _), (rw, rh), ang = cv2.minAreaRect((uv * 1e3).astype(np.float32))
    a = math.radians(ang)
    ax = np.array([math.cos(a), math.sin(a)])
    if rh > rw:
        ax = np.array([-ax[1], ax[0]])
    ax = ax if float(ax @ axis) >= 0 else -ax
    s = dot_last(uv - mean, ax)
    c = dot_last(uv - mean, np.array([-ax[1], ax[0]]))
    lo, hi = float(np.percentile(s, 1)), float(np.percentile(s, 99))
    width = float(np.percentile(c, 99) - np.percentile(c, 1))
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
        slack = max(0.002, 0.25 * part.outer)
        if abs(outer - part.outer) > slack or width > part.outer + 2 * slack:
            continue
        if not settings.min_stub_length * part.length <= length < 0.9 * part.length:
            continue
        stub = length < settings.min_hidden * part.length
        if stub and (relief > settings.max_stub_relief or width < 0.85 * part.outer):
            continue
        ends, rest = [], []
        rel = uv_all - (mean + c_mid * across)
        c = dot_last(rel, across)
        on_line = np.abs(c) < 0.5 * part.outer
        for sign, s_end in ((1.0, s_hi), (-1.0, s_lo)):
            # Heights just beyond this end, on the part's line.
            s = dot_last(rel, axis) * sign - sign * s_end
            beyond = (s > 0.002) & (s < 0.010) & on_line
            h = hgt[beyond]
            seen = h > -0.5  # invalid pixels read -1
            if stub and np.count_nonzero(seen) < 10:
                # Hardly any floor seen just beyond a stub's end: hidden under a taller part
                # (beside a taller part the floor is in its shadow for several millimetres).
                ends.append("hidden")
            elif np.count_nonzero(seen) < 10:
                ends.append("unknown")
            elif float(np.median(h[seen])) < settings.min_height:
                ends.append("free")
            else:  # a taller part over it, or a sliver of it seen past that part's flank
                ends.append("hidden")
            # What is seen over the rest of the part's length, were this end the hidden one.
            h = hgt[(s > 0.002) & (s < part.length - length) & on_line]
            h = h[h > -0.5]
            rest.append(float(np.mean(h > 0.8 * part.outer)) if len(h) else 1.0)
        if ends == ["free", "hidden"] and (not stub or rest[1] >= settings.min_cover):
            return part, s_hi - 0.5 * part.length  # the +axis end (s_hi) is the free one
        if ends == ["hidden", "free"] and (not stub or rest[0] >= settings.min_cover):
            return part, s_lo + 0.5 * part.length
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
    within = np.abs(c) < 0.4 * part.hole
    # Kept 6 mm inside the end: the lower part of a closed end's own face, blurred by the depth
    # noise and the centre's error, must not count as a view inside.
    near_end = (s > 0.5 * part.length - 0.6 * part.outer) & (s < 0.5 * part.length - 0.006)
    low = (hgt > -0.002) & (hgt < 0.3 * part.outer)
    at_face = np.abs(s - 0.5 * part.length) < 0.004
    middle = (hgt > 0.15 * part.outer) & (hgt < 0.85 * part.outer)
    return int(np.count_nonzero(near_end & within & low)), int(
        np.count_nonzero(at_face & within & middle)
    )


def timed_detect(*args, **kwargs) -> tuple[list[Detection], float]:  # type: ignore[no-untyped-def]
    """``detect_parts`` and the seconds it took (for the benchmark)."""
    t0 = time.perf_counter()
    out = detect_parts(*args, **kwargs)
    return out, time.perf_counter() - t0
