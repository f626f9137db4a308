"""Force balance as linear programs: Eq. 7 (first-order form closure) and Eq. 8 (gravity).

Both are solved with ``scipy.optimize.linprog`` (HiGHS). They are the reference the vectorized
test in :mod:`skills.mechanics.cone` must agree with point by point.

* Eq. 7: ``min sum k  s.t.  sum k_i F_i = 0,  k_i >= 1`` -- the contacts alone hold the part.
* Eq. 8: ``min sum k  s.t.  F_ext + sum k_i F_i = 0,  k_i >= 0`` with ``F_ext = [0, 0, -m g]``.

Feasibility of Eq. 8 does not depend on ``m g`` (the constraint is a cone membership), so the
solver uses ``m g = 1`` and the returned ``k`` are contact forces per unit weight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linprog

from drivers.parts import Section
from skills.mechanics.contact import WRENCH_NAMES, Frictions, contact_wrenches, gravity_wrench

# The ``status`` codes of ``scipy.optimize.linprog`` (as its documentation lists them) read here:
#: an optimum was found
LP_OPTIMAL = 0
#: the constraints cannot all hold: no force balance exists
LP_INFEASIBLE = 2
#: the objective has no lower bound
LP_UNBOUNDED = 3


@dataclass(frozen=True)
class BalanceResult:
    """Outcome of one LP: ``feasible`` and, when feasible, the coefficients ``k`` by name."""

    feasible: bool
    k: dict[str, float] | None
    objective: float | None


def _solve(wrenches: NDArray[np.float64], rhs: NDArray[np.float64], lower: float) -> BalanceResult:
    n = wrenches.shape[1]
    res = linprog(
        c=np.ones(n),
        A_eq=wrenches,
        b_eq=rhs,
        bounds=[(lower, None)] * n,
        method="highs",
    )
    if res.status == LP_OPTIMAL:
        return BalanceResult(True, dict(zip(WRENCH_NAMES, map(float, res.x), strict=True)), res.fun)
    if res.status == LP_INFEASIBLE:
        return BalanceResult(False, None, None)
    if res.status == LP_UNBOUNDED:  # cannot happen with a positive cost and k >= lower >= 0
        raise RuntimeError(f"linprog reported an unbounded problem: {res.message}")
    raise RuntimeError(f"linprog failed: {res.message}")


def form_closure_lp(wrenches: NDArray[np.float64]) -> BalanceResult:
    """Eq. 7 on a 3x6 wrench matrix."""
    return _solve(np.asarray(wrenches, float), np.zeros(3), 1.0)


def gravity_balance_lp(wrenches: NDArray[np.float64]) -> BalanceResult:
    """Eq. 8 on a 3x6 wrench matrix with unit weight."""
    return _solve(np.asarray(wrenches, float), -gravity_wrench(1.0), 0.0)


def solve_point(
    section: Section,
    l_a: float,
    alpha: float,
    beta: float,
    frictions: Frictions,
    equation: str = "auto",
) -> BalanceResult:
    """Solve Eq. 7 or Eq. 8 at one configuration.

    ``equation="auto"`` follows the paper: Eq. 7 when every contact is frictionless, else Eq. 8.
    """
    eq = resolve_equation(equation, frictions)
    w = contact_wrenches(section, l_a, alpha, beta, frictions, normalized=True)
    return form_closure_lp(w) if eq == "eq7" else gravity_balance_lp(w)


def resolve_equation(equation: str, frictions: Frictions) -> str:
    """Map ``auto``/``eq7``/``eq8`` to the equation actually solved."""
    if equation == "auto":
        return "eq7" if frictions.frictionless else "eq8"
    if equation not in ("eq7", "eq8"):
        raise ValueError(f"equation must be one of auto, eq7, eq8; got {equation!r}")
    return equation
