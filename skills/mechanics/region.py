"""Stable-grasp regions in the (alpha, beta) plane (Fig. 5) and the quantities derived from them.

"Stable" means the force balance of :mod:`skills.mechanics.balance` is feasible: Eq. 7 when every
contact is frictionless (as the paper states), Eq. 8 otherwise; ``equation`` overrides that.
Everything here is evaluated with the exact cone test, so a map costs milliseconds.

Continuous questions (how far a tilt stays stable, the smallest usable alpha) are answered on a
fine grid and then refined by bisection with the same exact test. The grid spacing is the
resolution of the answer: a stable interval shorter than one grid step could be missed, which is
why the defaults use 0.25 degree steps in beta.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.parts import Section
from skills.mechanics.balance import resolve_equation
from skills.mechanics.cone import eq7_feasible, eq8_feasible
from skills.mechanics.contact import (
    HALF_PI,
    Frictions,
    check_alpha,
    check_beta,
    check_la,
    contact_wrenches,
)

#: Default number of beta samples on [0, pi/2] for path questions (0.25 degree steps).
BETA_SAMPLES = 361
#: Default number of alpha samples inside (0, pi/2) for the smallest usable alpha (0.25 degree
#: steps: 360 intervals, the two end points excluded)
ALPHA_SAMPLES = 359
#: Default number of halvings of a bisection: 30 halvings of a 0.25 deg step leave an error
#: below 1e-11 rad, far below any angle the arm can set
BISECTIONS = 30
#: rad, angles this close count as equal: above the bisection's error, far below any angle the
#: arm can set, so an edge found by bisection still counts as reaching its target
ANGLE_TOL = 1e-9


def alpha_axis(n: int) -> NDArray[np.float64]:
    """``n`` evenly spaced alphas strictly inside (0, pi/2) (the end points are excluded, Eq. 4)."""
    if n < 1:
        raise ValueError(f"grid must have at least 1 point, got {n}")
    return np.linspace(0.0, HALF_PI, n + 2)[1:-1]  # exact: n inside, both ends dropped


def beta_axis(n: int) -> NDArray[np.float64]:
    """``n`` evenly spaced betas from 0 to pi/2 inclusive (Eq. 5)."""
    if n < 2:  # exact: both end points
        raise ValueError(f"grid must have at least 2 points, got {n}")
    return np.linspace(0.0, HALF_PI, n)


def stable(
    section: Section,
    l_a: ArrayLike,
    alpha: ArrayLike,
    beta: ArrayLike,
    frictions: Frictions,
    equation: str = "auto",
) -> NDArray[np.bool_]:
    """Exact stability at every broadcast point of ``(l_a, alpha, beta)``."""
    eq = resolve_equation(equation, frictions)
    w = contact_wrenches(section, l_a, alpha, beta, frictions, normalized=True)
    return eq7_feasible(w) if eq == "eq7" else eq8_feasible(w)


def region_map(
    section: Section,
    l_as: ArrayLike,
    alphas: ArrayLike,
    betas: ArrayLike,
    frictions: Frictions,
    equation: str = "auto",
) -> NDArray[np.bool_]:
    """The stable set indexed ``[l_a][alpha][beta]`` (the layout of ``cell analyze --json``)."""
    la = check_la(np.atleast_1d(l_as))
    al = check_alpha(np.atleast_1d(alphas))
    be = check_beta(np.atleast_1d(betas))
    return stable(
        section, la[:, None, None], al[None, :, None], be[None, None, :], frictions, equation
    )


def bisect_edge(
    holds: Callable[[float], bool], inside: float, outside: float, iterations: int = BISECTIONS
) -> float:
    """The point nearest ``outside`` where ``holds`` is still True, by bisection.

    ``holds(inside)`` must be True and ``holds(outside)`` False; either may be the larger.
    30 halvings of a 0.25 deg step leave an error below 1e-11 rad.
    """
    for _ in range(iterations):
        mid = 0.5 * (inside + outside)  # exact: the midpoint
        if holds(mid):
            inside = mid
        else:
            outside = mid
    return inside


@dataclass(frozen=True)
class TiltCheck:
    """How far a Tilt at fixed ``(l_a, alpha)`` stays in force balance, starting from beta = 0.

    ``beta_stable_max`` is the end of the stable interval ``[0, beta_stable_max]`` (rad), or None
    when the grasp is not even stable lying flat. ``ok`` says whether it reaches ``beta_required``.
    """

    l_a: float
    alpha: float
    beta_required: float
    beta_stable_max: float | None

    @property
    def ok(self) -> bool:
        end = self.beta_stable_max
        return end is not None and end >= self.beta_required - ANGLE_TOL


def stable_beta_max(
    section: Section,
    l_a: float,
    alpha: float,
    frictions: Frictions,
    equation: str = "auto",
    samples: int = BETA_SAMPLES,
) -> float | None:
    """End of the stable interval that starts at beta = 0 for a fixed grasp (rad), or None.

    Returns pi/2 when the whole tilt is stable; otherwise this is the paper's ``beta_ub``.
    """
    be = beta_axis(samples)
    ok = stable(section, l_a, alpha, be, frictions, equation)
    if not ok[0]:
        return None
    if ok.all():
        return HALF_PI
    first_bad = int(np.argmin(ok))
    return bisect_edge(
        lambda b: bool(stable(section, l_a, alpha, b, frictions, equation)),
        float(be[first_bad - 1]),
        float(be[first_bad]),
    )


def beta_upper_bound(
    section: Section, l_a: float, alpha: float, frictions: Frictions, equation: str = "auto"
) -> float | None:
    """The paper's ``beta_ub``: where balance is lost during the tilt; None if it never is.

    Also None when the grasp is not stable at beta = 0 (there is no tilt to bound).
    """
    end = stable_beta_max(section, l_a, alpha, frictions, equation)
    return None if end is None or end >= HALF_PI else end


def check_tilt(
    section: Section,
    l_a: float,
    alpha: float,
    frictions: Frictions,
    beta_required: float = HALF_PI,
    equation: str = "auto",
) -> TiltCheck:
    """Path check of a planned ``(l_a, alpha)`` along the Tilt, beta = 0 to ``beta_required``."""
    check_la(l_a)
    check_alpha(alpha)
    check_beta(beta_required)
    end = stable_beta_max(section, l_a, alpha, frictions, equation)
    return TiltCheck(float(l_a), float(alpha), float(beta_required), end)


def tilt_ok_mask(
    section: Section,
    l_a: float,
    alphas: NDArray[np.float64],
    frictions: Frictions,
    beta_required: float,
    equation: str = "auto",
    samples: int = BETA_SAMPLES,
) -> NDArray[np.bool_]:
    """For each alpha, whether every sampled beta in [0, beta_required] is stable."""
    be = beta_axis(samples)
    be = np.append(be[be < beta_required], beta_required)
    ok = stable(section, l_a, alphas[:, None], be[None, :], frictions, equation)
    return ok.all(axis=1)


def min_alpha_for_tilt(
    section: Section,
    l_a: float,
    frictions: Frictions,
    beta_required: float = HALF_PI,
    equation: str = "auto",
    alpha_samples: int = ALPHA_SAMPLES,
) -> float | None:
    """Smallest alpha (rad) whose Tilt stays stable from beta = 0 to ``beta_required``, or None.

    Scans alpha in 0.25 degree steps, then bisects between the last failing and the first
    passing sample.
    """
    check_la(l_a)
    check_beta(beta_required)
    al = alpha_axis(alpha_samples)
    ok = tilt_ok_mask(section, l_a, al, frictions, beta_required, equation)
    if not ok.any():
        return None
    first = int(np.argmax(ok))
    if first == 0:
        return float(al[0])

    def passes(alpha: float) -> bool:
        return bool(
            tilt_ok_mask(section, l_a, np.array([alpha]), frictions, beta_required, equation)[0]
        )

    return bisect_edge(passes, float(al[first]), float(al[first - 1]))


def min_alpha_full_tilt(
    section: Section, l_as: ArrayLike, frictions: Frictions, equation: str = "auto"
) -> list[float | None]:
    """Per ``l_a``: the smallest alpha that keeps the whole tilt, beta = 0 to pi/2, stable."""
    return [
        min_alpha_for_tilt(section, float(la), frictions, HALF_PI, equation)
        for la in np.atleast_1d(l_as)
    ]
