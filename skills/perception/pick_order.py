"""Which part to pick first from a bin tipped full: the freest. A part with room around it
leaves the fingers, the wrist and the Tilt's arc clear of its neighbours and the walls, and
taking it first frees the others. Judged from the detections -- the cell's own depth data,
never the simulator's truth."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from skills.axes import XY
from skills.perception.bin_parts import Detection

#: points sampled along each part's axis, end to end: the axis is a 9-point polyline, so a gap
#: is measured to within an eighth of a part's length -- the spacing of the neighbours matters,
#: not a millimetre of it
_SAMPLES = 9
#: decimals of a metre the clearance is rounded to before ordering (3: a millimetre), so parts
#: whose clearances differ by less than the depth data resolves tie and the nearer goes first
_CLEARANCE_DECIMALS = 3


def _axis_points(d: Detection) -> NDArray[np.float64]:
    if d.standing:  # its axis is a point on the floor
        return np.asarray(d.center[XY], float)[None, :]
    u = np.array([math.cos(d.yaw), math.sin(d.yaw)])
    half = 0.5  # exact: the axis runs half the length either side of the centre
    s = np.linspace(-half, half, _SAMPLES)[:, None] * d.length
    return np.asarray(d.center[XY], float) + s * u


def clearance(
    d: Detection, others: list[Detection], roi: tuple[float, float, float, float]
) -> float:
    """The smallest gap (m) between the part's outline and a neighbour's or a bin wall,
    each part taken as its axis thickened by half its outer size."""
    pts = _axis_points(d)
    x0, x1, y0, y1 = roi
    walls = np.minimum.reduce([pts[:, 0] - x0, x1 - pts[:, 0], pts[:, 1] - y0, y1 - pts[:, 1]])
    gap = float(walls.min()) - 0.5 * d.outer  # exact: the outline lies half the outer size out
    for o in others:
        if o is d:
            continue
        q = _axis_points(o)
        dist = np.linalg.norm(pts[:, None, :] - q[None, :, :], axis=-1).min()
        gap = min(gap, float(dist) - 0.5 * (d.outer + o.outer))  # exact: two half outer sizes
    return gap


def freest_first(
    usable: list[Detection], all_seen: list[Detection], roi: tuple[float, float, float, float]
) -> list[Detection]:
    """``usable`` ordered by clearance, the freest first (ties: nearer the robot first)."""
    return sorted(
        usable,
        key=lambda d: (
            -round(clearance(d, all_seen, roi), _CLEARANCE_DECIMALS), math.hypot(*d.center[XY])
        ),
    )


__all__ = ["clearance", "freest_first"]
