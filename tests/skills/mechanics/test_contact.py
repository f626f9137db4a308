"""Table 2 and Eq. 2-3: the contact model."""

import math
import re

import numpy as np
import pytest

from drivers.parts import Section, delta_rectangular, delta_round, hole_offset
from skills.mechanics.contact import Frictions, contact_wrenches

from .conftest import PAPER


def _wrench_at(point, force):
    """Moment about the centre of a force given in the part frame at ``point`` (part frame)."""
    return point[0] * force[1] - point[1] * force[0]


def test_table2_matches_forces_applied_at_the_contact_points(bushing: Section) -> None:
    # Independent construction: apply each cone edge at S, H, G in the part frame, rotate the
    # force into the world by beta, and compare with the closed forms of Table 2.
    a, b, d = bushing.a, bushing.b, bushing.delta
    la, alpha, beta = 0.7, 0.4, 0.6
    g_s, g_h, g_g = PAPER.gammas
    l = 2 * a * la
    rot = np.array([[math.cos(beta), -math.sin(beta)], [math.sin(beta), math.cos(beta)]])
    edges = {
        "S1": ((a - l, b), (math.sin(g_s), -math.cos(g_s))),
        "S2": ((a - l, b), (-math.sin(g_s), -math.cos(g_s))),
        "H1": ((a, b - d), (-math.cos(alpha - g_h), math.sin(alpha - g_h))),
        "H2": ((a, b - d), (-math.cos(alpha + g_h), math.sin(alpha + g_h))),
        # ground edges are fixed in the world: rotate them back into the part frame
        "G1": ((-a, -b), tuple(rot.T @ (-math.sin(g_g), math.cos(g_g)))),
        "G2": ((-a, -b), tuple(rot.T @ (math.sin(g_g), math.cos(g_g)))),
    }
    w = contact_wrenches(bushing, la, alpha, beta, PAPER)
    for col, (point, force) in enumerate(edges.values()):
        world = rot @ np.array(force)
        assert w[0, col] == pytest.approx(_wrench_at(point, force), abs=1e-12)
        assert w[1:, col] == pytest.approx(world, abs=1e-12)


def test_wrenches_are_unit_forces_and_broadcast(bushing: Section) -> None:
    al = np.linspace(0.1, 1.4, 5)[:, None]
    be = np.linspace(0.0, 1.5, 7)[None, :]
    w = contact_wrenches(bushing, 0.5, al, be, PAPER)
    assert w.shape == (5, 7, 3, 6)
    assert np.allclose(np.hypot(w[..., 1, :], w[..., 2, :]), 1.0)
    wn = contact_wrenches(bushing, 0.5, al, be, PAPER, normalized=True)
    assert np.allclose(wn[..., 0, :] * bushing.a, w[..., 0, :])


def test_eq2_eq3_bushing_delta() -> None:
    assert hole_offset(0.028, 0.020) == pytest.approx(0.014 * math.sqrt(1 - (20 / 28) ** 2))
    assert delta_round(0.034, 0.028, 0.020) * 1e3 == pytest.approx(7.2, abs=0.05)


# Table 3: (D, d, paper's delta) in mm.
TABLE3_ROUND = {
    "bushing": (34, 28, 7.2),
    "medicine_bottle": (35, 28, 13.2),
    "plastic_cup": (48, 44, 5.9),
    "cookie_can": (66, 60, 4.7),
    "water_bottle": (30, 25, 20.5),
}


def implied_finger_width(outer: float, hole: float, delta: float) -> float | None:
    """Invert Eq. 2-3: the finger width w (mm) that gives the paper's delta, if any."""
    x = outer / 2 - delta
    if not 0 < x < hole / 2:
        return None
    return hole * math.sqrt(1 - (2 * x / hole) ** 2)


def test_table3_delta_consistent_with_one_finger_width_for_bushing_and_can() -> None:
    widths = {k: implied_finger_width(*v) for k, v in TABLE3_ROUND.items()}
    # Bushing and cookie can agree on one 20 mm finger ...
    assert widths["bushing"] == pytest.approx(20.0, abs=0.1)
    assert widths["cookie_can"] == pytest.approx(20.0, abs=0.2)
    for name in ("bushing", "cookie_can"):
        d_outer, d_hole, paper = TABLE3_ROUND[name]
        assert delta_round(d_outer / 1e3, d_hole / 1e3, 0.020) * 1e3 == pytest.approx(
            paper, abs=0.05
        )
    # ... the bottle and the cup would need wider fingers (25 and 26.6 mm) ...
    assert widths["plastic_cup"] == pytest.approx(25.0, abs=0.2)
    assert widths["medicine_bottle"] == pytest.approx(26.6, abs=0.2)
    # ... and the water bottle's 20.5 mm exceeds D/2 = 15 mm: no finger width gives it.
    assert widths["water_bottle"] is None


def test_table3_prisms_list_twice_the_wall() -> None:
    # Wiring duct 60 x 57 and mounting rail 7.6 x 6.4: the paper's delta equals D - d,
    # while a flat finger on the inner wall of a rectangular hole sits one wall, (D - d)/2, deep.
    assert delta_rectangular(0.060, 0.057, 0.020) == pytest.approx(0.0015)
    assert (60 - 57) == pytest.approx(3.0) and (7.6 - 6.4) == pytest.approx(1.2)


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda: hole_offset(0.028, 0.030), "not narrower than the hole"),
        (lambda: hole_offset(0.028, 0.028), "not narrower than the hole"),
        (lambda: Frictions(mu_g=-0.1), "mu_g must be >= 0"),
        (lambda: Frictions(mu_s=float("nan")), "mu_s must be a finite number"),
        (lambda: Section(0.034, 0.017, 0.05), "delta must lie in"),
        (
            lambda: contact_wrenches(Section(0.03, 0.01, 0.0), 1.5, 0.3, 0.1, PAPER),
            "l_a must lie in (0, 1]",
        ),
        (
            lambda: contact_wrenches(Section(0.03, 0.01, 0.0), 0.0, 0.3, 0.1, PAPER),
            "l_a must lie in (0, 1]",
        ),
        (
            lambda: contact_wrenches(Section(0.03, 0.01, 0.0), 0.5, 0.0, 0.1, PAPER),
            "alpha must lie in (0, pi/2)",
        ),
        (
            lambda: contact_wrenches(Section(0.03, 0.01, 0.0), 0.5, math.pi / 2, 0.1, PAPER),
            "alpha must lie",
        ),
        (
            lambda: contact_wrenches(Section(0.03, 0.01, 0.0), 0.5, 0.3, -0.1, PAPER),
            "beta must lie in [0, pi/2]",
        ),
    ],
)
def test_bad_values_raise_valueerror_naming_them(call, needle: str) -> None:
    with pytest.raises(ValueError, match=re.escape(needle)):
        call()
