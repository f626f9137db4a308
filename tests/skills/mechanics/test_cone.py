"""The vectorized cone test gives the LP's answer at every grid point (Eq. 7 and Eq. 8)."""

import math

import numpy as np
import pytest

from drivers.parts import Section
from skills.mechanics.balance import form_closure_lp, gravity_balance_lp
from skills.mechanics.cone import eq7_feasible, eq8_feasible, in_cone
from skills.mechanics.contact import Frictions, contact_wrenches
from skills.mechanics.region import alpha_axis, beta_axis

from .conftest import FRICTIONLESS, GROUND_ONLY, PAPER


def _lp_map(w: np.ndarray, lp) -> np.ndarray:
    out = np.zeros(w.shape[:-2], dtype=bool)
    for idx in np.ndindex(out.shape):
        out[idx] = lp(w[idx]).feasible
    return out


def _grid(section: Section, la: float, fr: Frictions, n: int) -> np.ndarray:
    al, be = alpha_axis(n), beta_axis(n)
    return contact_wrenches(section, la, al[:, None], be[None, :], fr, normalized=True)


def test_full_91x91_grid_agrees_with_lp(bushing: Section) -> None:
    w = _grid(bushing, 0.9, PAPER, 91)
    fast = eq8_feasible(w)
    assert 0 < fast.sum() < fast.size  # a real boundary runs through this map
    assert np.array_equal(fast, _lp_map(w, gravity_balance_lp))


@pytest.mark.parametrize("fr", [FRICTIONLESS, GROUND_ONLY, PAPER, Frictions(1.0, 0.0, 0.2)])
@pytest.mark.parametrize("la", [0.3, 0.5, 0.7, 1.0])
def test_grids_agree_with_lp_for_both_equations(bushing: Section, fr: Frictions, la: float) -> None:
    w = _grid(bushing, la, fr, 25)
    assert np.array_equal(eq8_feasible(w), _lp_map(w, gravity_balance_lp))
    assert np.array_equal(eq7_feasible(w), _lp_map(w, form_closure_lp))


def test_other_geometry_agrees_with_lp() -> None:
    # A long thin can with a shallow lip, far from the bushing's proportions.
    section = Section(a=0.08, b=0.033, delta=0.0047)
    for fr in (GROUND_ONLY, PAPER):
        w = _grid(section, 0.6, fr, 25)
        assert np.array_equal(eq8_feasible(w), _lp_map(w, gravity_balance_lp))


def test_frictionless_eq7_curve_is_feasible_exactly_on_it(bushing: Section) -> None:
    # Without friction Eq. 7 holds only where the three normals meet (det[S H G] = 0): find such
    # a beta by bisection and check both solvers accept it while a nearby beta fails.
    alpha, la = 0.5, 0.5

    def det(beta: float) -> float:
        w = contact_wrenches(bushing, la, alpha, beta, FRICTIONLESS, normalized=True)
        return float(np.linalg.det(w[:, [0, 2, 4]]))

    lo, hi = 0.2, 0.9
    assert det(lo) * det(hi) < 0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if det(lo) * det(mid) <= 0:
            hi = mid
        else:
            lo = mid
    on = contact_wrenches(bushing, la, alpha, lo, FRICTIONLESS, normalized=True)
    off = contact_wrenches(bushing, la, alpha, lo + 0.01, FRICTIONLESS, normalized=True)
    assert form_closure_lp(on).feasible and bool(eq7_feasible(on))
    assert not form_closure_lp(off).feasible and not bool(eq7_feasible(off))


def test_in_cone_simple_cases() -> None:
    e = np.eye(3)
    assert in_cone(e, np.array([1.0, 2.0, 3.0]))
    assert not in_cone(e, np.array([1.0, -2.0, 3.0]))
    # planar generators: inside the 2-D cone, outside it in the plane, and off the plane
    plane = np.array([[1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])
    assert in_cone(plane, np.array([2.0, 1.0, 0.0]))
    assert not in_cone(plane, np.array([-1.0, 1.0, 0.0]))
    assert not in_cone(plane, np.array([1.0, 0.5, 0.1]))
    # a line
    line = np.array([[1.0], [1.0], [0.0]])
    assert in_cone(line, np.array([2.0, 2.0, 0.0]))
    assert not in_cone(line, np.array([-2.0, -2.0, 0.0]))
    # the whole space (force closure): everything is inside
    both = np.hstack([e, -e])
    assert in_cone(both, np.array([-math.pi, 1.0, -2.0]))
