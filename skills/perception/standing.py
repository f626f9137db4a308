"""Find the parts standing on an end in the wide view of the bin.

A part tipped into a bin sometimes lands on an end. Lying-part fits take no notice of it (its top
is a ring or a disc, not a crest), so it was never seen, never picked and never named. From
above, a standing part shows its top at the height of its length, round (or square) and as wide
as the part: the pixels within a narrow band around that height form one blob per standing
part. A blob whose enclosing circle (or rectangle) has the part's outer size is that part; a
lying part's crest in the same band is a strip as long as the part, far wider than its section,
and fails the size test. The top tells the open end: through a ring the camera sees down into
the hole (heights well below the rim), a closed end shows a disc at rim height.

Heights are above the floor plane the height map fitted; nothing here reads the twin.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from drivers.parts import Part
from skills.axes import XY, Z
from skills.perception.bin_parts import Detection
from skills.perception.heightmap import MM_PER_M, HeightMap

#: m: half the height of the band around a part's length that holds its top's pixels: three
#: sigma of the D435's depth noise at the look's distance, under the 5 mm between the
#: catalogue's two nearest lengths (bushing 68 mm, cup 73 mm).
BAND = 0.004
#: pixels: a blob smaller than this is noise or a sliver of a neighbour's flank crossing the band
MIN_PIXELS = 60
#: m: the enclosing circle's radius may differ from half the outer size by this much (the band
#: catches a rim's outer edge a pixel wide or short; a lying crest is tens of mm off)
SIZE_TOLERANCE = 0.004
#: a square top's enclosing circle is the half-diagonal: sqrt(2) times the half side
SQUARE_DIAGONAL = math.sqrt(2.0)
#: share of the hole's radius, around the centre, whose heights tell a ring from a disc
INSIDE_SHARE = 0.6
#: m: the inside reads this far below the rim (the hole's depth seen through the opening) for
#: the end on top to count as open; a closed end's face reads at the rim within the noise
OPEN_DEPTH = 0.010
#: pixels touching at a corner join a blob: a rim a pixel wide runs on diagonals
CONNECTIVITY = 8
#: m: parts thinner than this (the 7.6 mm rail) are not looked for standing: their top is a
#: few pixels, like any edge crossing the band (DetectorSettings.thin_part)
THIN = 0.015
#: inside pixels needed to judge the end on top at all
MIN_INSIDE = 10
#: sectors around the fitted centre; a rim seen from above (the highest thing there) shows in
#: at least MIN_SECTORS of them, out past half its radius; a leaning part's end cut by the
#: band is a strip or a crescent and fills a few
SECTORS, MIN_SECTORS = 12, 10
#: m: the ring just outside the rim, from a pad's width of noise out to a finger's thickness:
#: round a standing part the heights drop off its wall there; round a leaning part's raised
#: end its own body goes on, sloping just under the band
CLEAR_FROM, CLEAR_TO = 0.003, 0.010
#: m below the rim that counts as "dropped" in that ring, and the share of the ring's pixels
#: that may stay higher (a neighbour leaning on it, the noise on the wall's edge)
DROP, MAX_HIGH_AROUND = 0.015, 0.35


def find_standing(hm: HeightMap, catalogue: list[Part]) -> list[Detection]:
    """Every catalogue part standing on an end in ``hm``, as a :class:`Detection` with
    ``standing`` set: ``center`` on the axis at half height, ``open_end`` the top's centre,
    ``open_end_seen`` when the top is open (the hole grasp from above can take it)."""
    height = hm.height
    valid = np.isfinite(height)
    h = np.where(valid, height, -1.0).astype(np.float32)
    found: list[Detection] = []
    taken = np.zeros(height.shape, bool)
    # Tallest first: a tall part's rim never sits in a shorter part's band.
    for part in sorted(catalogue, key=lambda p: -p.length):
        if part.hole <= 0.0 or part.outer < THIN:
            continue  # a rail on end is a stick: no hole to grasp from above, no ring to see
        band = (np.abs(h - part.length) < BAND) & ~taken
        if int(band.sum()) < MIN_PIXELS:
            continue
        n, labels, stats, _ = cv2.connectedComponentsWithStats(band.astype(np.uint8), CONNECTIVITY)
        for k in range(1, n):
            if stats[k, cv2.CC_STAT_AREA] < MIN_PIXELS:
                continue
            mask = labels == k
            det = _standing(hm, part, mask)
            if det is not None:
                found.append(det)
                taken |= mask
    return found


def _standing(hm: HeightMap, part: Part, mask: NDArray[np.bool_]) -> Detection | None:
    """The blob ``mask`` as ``part`` standing, or None when its size is not the part's."""
    xy = hm.points[mask][:, XY].astype(np.float64)
    xy = xy[np.isfinite(xy[:, 0])]
    if len(xy) < MIN_PIXELS:
        return None
    (cx, cy), r_mm = cv2.minEnclosingCircle((xy * MM_PER_M).astype(np.float32))
    radius = r_mm / MM_PER_M
    corner = SQUARE_DIAGONAL if part.hole_shape == "rectangle" else 1.0
    expected = 0.5 * part.outer * corner  # exact: half the outer size, to a side or a corner
    if abs(radius - expected) > SIZE_TOLERANCE:
        return None
    center = np.array([cx, cy]) / MM_PER_M
    rel = xy - center
    out = np.hypot(rel[:, 0], rel[:, 1]) > 0.5 * radius  # exact: past half the radius
    turn = np.arctan2(rel[out, 1], rel[out, 0]) + math.pi  # 0 .. 2 pi
    sectors = np.floor(turn / math.tau * SECTORS)
    if len(np.unique(sectors)) < MIN_SECTORS:
        return None  # not a whole rim round its centre
    # The inside: pixels whose points lie within INSIDE_SHARE of the hole's radius of the axis.
    pts = hm.points.reshape(-1, 3)
    hgt = hm.height.reshape(-1)
    near = np.abs(pts[:, 0] - center[0]) < 0.5 * part.hole  # exact: a cheap box before the disc
    near &= np.abs(pts[:, 1] - center[1]) < 0.5 * part.hole  # exact: the same along y
    idx = np.flatnonzero(near)
    d = np.hypot(pts[idx, 0] - center[0], pts[idx, 1] - center[1])
    inside = hgt[idx[d < INSIDE_SHARE * 0.5 * part.hole]]  # exact: the hole's radius
    far = radius + CLEAR_TO
    box = (np.abs(pts[:, 0] - center[0]) < far) & (np.abs(pts[:, 1] - center[1]) < far)
    ring_idx = np.flatnonzero(box)
    r = np.hypot(pts[ring_idx, 0] - center[0], pts[ring_idx, 1] - center[1])
    around = hgt[ring_idx[(r > radius + CLEAR_FROM) & (r < far)]]
    around = around[np.isfinite(around)]
    if len(around) and float(np.mean(around > part.length - DROP)) > MAX_HIGH_AROUND:
        return None  # its own body goes on beside the blob: a raised end, not a rim
    # No depth inside (the hole too deep and narrow for the sensor) reads as an opening too.
    seen = inside[np.isfinite(inside)]
    open_top = len(seen) < MIN_INSIDE or float(np.median(seen)) < part.length - OPEN_DEPTH
    if part.open_ends == 2:  # exact: a tube is open at both ends
        open_top = True
    floor = hm.plane
    up = floor.normal
    # the axis' foot on the floor plane: up . p = offset
    foot_z = (floor.offset - float(up[XY] @ center)) / float(up[Z])
    base = np.array([center[0], center[1], foot_z])
    top = base + part.length * up
    return Detection(
        center=base + 0.5 * part.length * up,  # exact: the axis' middle
        yaw=0.0,
        length=part.length,
        outer=2.0 * radius / corner,  # exact: the diameter is twice the radius
        part=part.name,
        open_end=top,
        open_end_seen=bool(open_top),
        confidence=float(max(0.0, 1.0 - abs(radius - expected) / SIZE_TOLERANCE)),
        pixels=int(mask.sum()),
        standing=True,
    )
