"""Region maps, beta_ub, the smallest alpha per l_a and the Tilt path check."""

import math

import numpy as np
import pytest

from drivers.parts import Section
from skills.mechanics.region import (
    HALF_PI,
    alpha_axis,
    beta_axis,
    beta_upper_bound,
    check_tilt,
    min_alpha_for_tilt,
    min_alpha_full_tilt,
    region_map,
    stable,
)

from .conftest import GROUND_ONLY, PAPER


def test_axes_follow_the_contract() -> None:
    al, be = alpha_axis(91), beta_axis(91)
    assert al.size == be.size == 91
    assert 0 < al[0] and al[-1] < HALF_PI
    assert np.allclose(np.diff(al), al[0])  # evenly spaced, as far from 0 as from pi/2
    assert be[0] == 0.0 and be[-1] == pytest.approx(HALF_PI)
    assert np.allclose(np.diff(be), be[1])


def test_region_map_layout_is_la_alpha_beta(bushing: Section) -> None:
    las, al, be = np.array([0.3, 0.9]), alpha_axis(11), beta_axis(13)
    m = region_map(bushing, las, al, be, PAPER)
    assert m.shape == (2, 11, 13)
    assert m[1, 4, 7] == stable(bushing, 0.9, al[4], be[7], PAPER)


def test_min_alpha_is_the_boundary_of_the_path_set(bushing: Section) -> None:
    tip = bushing.tip_angle
    alpha = min_alpha_for_tilt(bushing, 0.7, GROUND_ONLY, tip)
    assert alpha is not None
    assert check_tilt(bushing, 0.7, alpha + 1e-4, GROUND_ONLY, tip).ok
    assert not check_tilt(bushing, 0.7, alpha - 1e-3, GROUND_ONLY, tip).ok


def test_min_alpha_full_tilt_per_la(bushing: Section) -> None:
    small, large = min_alpha_full_tilt(bushing, [0.3, 0.9], GROUND_ONLY)
    assert small is not None and math.radians(55) < small < math.radians(65)
    assert large is None  # beta_ub cuts every tilt short at l_a = 0.9 without S/H friction


def test_beta_upper_bound_and_path_check(bushing: Section) -> None:
    ub = beta_upper_bound(bushing, 0.9, math.pi / 10, GROUND_ONLY)
    assert ub is not None and bushing.tip_angle < ub < HALF_PI
    assert stable(bushing, 0.9, math.pi / 10, ub - 1e-6, GROUND_ONLY)
    assert not stable(bushing, 0.9, math.pi / 10, ub + 1e-3, GROUND_ONLY)
    path = check_tilt(bushing, 0.9, math.pi / 10, GROUND_ONLY, HALF_PI)
    assert not path.ok and path.beta_stable_max == pytest.approx(ub)
    assert check_tilt(bushing, 0.9, math.pi / 10, GROUND_ONLY, bushing.tip_angle).ok
    # not stable lying flat at all: no bound, path fails
    assert beta_upper_bound(bushing, 0.3, 0.2, GROUND_ONLY) is None
    assert not check_tilt(bushing, 0.3, 0.2, GROUND_ONLY).ok


@pytest.mark.parametrize("alpha", [0.0, HALF_PI, -0.1, 2.0])
def test_check_tilt_rejects_alpha_outside_the_open_interval(bushing: Section, alpha: float) -> None:
    with pytest.raises(ValueError, match="alpha must lie in"):
        check_tilt(bushing, 0.5, alpha, PAPER)
