"""The planar contact model of the asymmetric pivot (paper Sec. III, Fig. 3-4, Tables 1-2).

The lying hollow part is modelled in its side section as a rectangle of half length ``a`` and
half height ``b`` (b = D/2). Three contacts hold it: S (the outer finger's tip on the top
surface), H (the inner finger caught on the hole's upper lip at the open end) and G (the far
bottom corner on the ground). Each contact contributes the two edges of its Coulomb friction
cone as unit contact wrenches ``[m, F_x, F_y]`` (Eq. 6), which is Table 2.

Readings of the paper (the paper is terse here; each choice below reproduces Table 2 exactly):

* **Frames.** ``F_x, F_y`` are in the *world* frame: x horizontal, pointing from the pivot end
  (G) towards the open end (H) while the part lies flat; y vertically up. The part is rotated
  counter-clockwise by ``beta`` about G, so the open end rises.
* **Contact points**, in the part frame (origin at the section centre, x along the axis towards
  the open end, y towards the finger S): ``S = (a - l, b)``, ``H = (a, b - delta)``,
  ``G = (-a, -b)``. So ``l`` is measured from the top corner *at the open end* and ``delta``
  from the same corner down the end face. With these points every moment of Table 2 follows.
* **Moments** are taken about the section centre (the centre of mass of a uniform part),
  counter-clockwise positive. Hence gravity has no moment and ``F_ext = [0, 0, -m g]`` (Eq. 8).
* **Directions.** A positive coefficient ``k_i`` means the contact *pushes* on the part: S
  pushes along the top surface's inward normal, G pushes up, H pushes along the inner finger's
  closing direction ``(-cos alpha, sin alpha)`` in the part frame, i.e. ``alpha`` is the angle
  between the part's axis and the jaw's closing line (``alpha = 0`` is an end-to-end pinch,
  ``alpha = pi/2`` a finger pushed straight down the hole, as in Sec. III-A).
* **Friction edges.** Index 1 and 2 are the two cone edges, rotated by ``-gamma`` / ``+gamma``
  as written in Table 2 (S1 and G2 lean towards +x, H1 leans by ``-gamma_H``).
* **Units.** Lengths in metres; the wrenches are unit forces with moments in metres. Only
  ratios matter for feasibility, so mass and scale drop out of the stability question.

The section constants ``a``, ``b``, ``delta`` (:class:`drivers.parts.Section`) and Eq. 2-3 that
give ``delta`` are part geometry and live with :class:`drivers.parts.Part`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.parts import Frictions, Section

#: Column order of the 3x6 wrench matrix, as in Table 2.
WRENCH_NAMES: tuple[str, ...] = ("S1", "S2", "H1", "H2", "G1", "G2")
#: Columns of the wrench matrix by name: the two friction-cone edges of S, of H and of G
#: (Table 2, in :data:`WRENCH_NAMES` order)
S1, S2, H1, H2, G1, G2 = 0, 1, 2, 3, 4, 5
#: Rows of a planar wrench ``[m, F_x, F_y]`` (Eq. 6): the moment about the section centre, then
#: the horizontal and the vertical force
MOMENT, FORCE_X, FORCE_Y = 0, 1, 2
#: the length of a planar wrench: one moment and two force components
PLANAR_DIM = 3
#: rad, a right angle: the open bound of alpha (Eq. 4) and the closed bound of beta (Eq. 5)
HALF_PI = 0.5 * math.pi
#: rad a beta may lie above pi/2 and still count as pi/2: a beta computed by adding angles can
#: miss it by a few ulps
BETA_ROUNDING = 1e-12


def _check_finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return value


def check_la(l_a: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(l_a, dtype=float)
    bad = ~np.isfinite(arr) | (arr <= 0.0) | (arr > 1.0)
    if np.any(bad):
        raise ValueError(f"l_a must lie in (0, 1] (Eq. 1), got {arr[bad].ravel()[0]:g}")
    return arr


def check_alpha(alpha: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(alpha, dtype=float)
    bad = ~np.isfinite(arr) | (arr <= 0.0) | (arr >= HALF_PI)
    if np.any(bad):
        raise ValueError(f"alpha must lie in (0, pi/2) rad (Eq. 4), got {arr[bad].ravel()[0]:g}")
    return arr


def check_beta(beta: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(beta, dtype=float)
    bad = ~np.isfinite(arr) | (arr < 0.0) | (arr > HALF_PI + BETA_ROUNDING)
    if np.any(bad):
        raise ValueError(f"beta must lie in [0, pi/2] rad (Eq. 5), got {arr[bad].ravel()[0]:g}")
    return arr


def contact_wrenches(
    section: Section,
    l_a: ArrayLike,
    alpha: ArrayLike,
    beta: ArrayLike,
    frictions: Frictions,
    *,
    normalized: bool = False,
) -> NDArray[np.float64]:
    """Table 2: the six basis contact wrenches, shape ``broadcast(l_a, alpha, beta) + (3, 6)``.

    Rows are ``(m, F_x, F_y)``, columns :data:`WRENCH_NAMES`. With ``normalized`` the moment row
    is divided by ``a`` so all rows are O(1); that scaling does not change which force balances
    exist (it is an invertible positive map of wrench space) and it keeps tolerances meaningful.
    """
    la = check_la(l_a)
    al = check_alpha(alpha)
    be = check_beta(beta)
    la, al, be = np.broadcast_arrays(la, al, be)
    a, b, delta = section.a, section.b, section.delta
    g_s, g_h, g_g = frictions.gammas
    l = 2.0 * a * la  # exact: l = 2 a l_a, the paper's definition of l_a (Eq. 1)

    out = np.empty(la.shape + (PLANAR_DIM, len(WRENCH_NAMES)))
    # S: finger tip on the top surface at (a - l, b).
    out[..., MOMENT, S1] = (l - a) * math.cos(g_s) - b * math.sin(g_s)
    out[..., FORCE_X, S1] = np.sin(be + g_s)
    out[..., FORCE_Y, S1] = -np.cos(be + g_s)
    out[..., MOMENT, S2] = (l - a) * math.cos(g_s) + b * math.sin(g_s)
    out[..., FORCE_X, S2] = np.sin(be - g_s)
    out[..., FORCE_Y, S2] = -np.cos(be - g_s)
    # H: the hole's upper lip at (a, b - delta) against the inner finger's face.
    out[..., MOMENT, H1] = a * np.sin(al - g_h) + (b - delta) * np.cos(al - g_h)
    out[..., FORCE_X, H1] = -np.cos(al - be - g_h)
    out[..., FORCE_Y, H1] = np.sin(al - be - g_h)
    out[..., MOMENT, H2] = a * np.sin(al + g_h) + (b - delta) * np.cos(al + g_h)
    out[..., FORCE_X, H2] = -np.cos(al - be + g_h)
    out[..., FORCE_Y, H2] = np.sin(al - be + g_h)
    # G: the far bottom corner (-a, -b) on the ground.
    out[..., MOMENT, G1] = -a * np.cos(g_g - be) - b * np.sin(g_g - be)
    out[..., FORCE_X, G1] = -math.sin(g_g)
    out[..., FORCE_Y, G1] = math.cos(g_g)
    out[..., MOMENT, G2] = -a * np.cos(g_g + be) + b * np.sin(g_g + be)
    out[..., FORCE_X, G2] = math.sin(g_g)
    out[..., FORCE_Y, G2] = math.cos(g_g)
    if normalized:
        out[..., MOMENT, :] /= a
    return out


def gravity_wrench(normalized_mass: float = 1.0) -> NDArray[np.float64]:
    """``F_ext = [0, 0, -m g]`` (Eq. 8): no moment about the centre of mass, weight downwards."""
    return np.array([0.0, 0.0, -normalized_mass])
