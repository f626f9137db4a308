"""Eq. 9 reproduces Table 3's interval columns (two rows of the paper are off Eq. 9)."""

import pytest

from lab.stats import wilson_interval


@pytest.mark.parametrize(
    ("k", "n", "lo", "hi"),
    [
        (10, 10, 72.25, 100.0),  # bushing, cookie can, wiring duct
        (9, 10, 59.58, 98.21),  # medicine bottle
        (8, 10, 49.02, 94.33),  # plastic cup
        (3, 10, 10.78, 60.32),  # mounting rail: the paper prints 10.74 / 60.27
        (0, 10, 0.0, 27.75),  # water bottle: the paper prints 26.46
    ],
)
def test_table3_intervals(k: int, n: int, lo: float, hi: float) -> None:
    got = wilson_interval(k, n)
    assert got[0] * 100 == pytest.approx(lo, abs=0.01)
    assert got[1] * 100 == pytest.approx(hi, abs=0.01)


def test_bad_counts() -> None:
    with pytest.raises(ValueError):
        wilson_interval(3, 0)
    with pytest.raises(ValueError):
        wilson_interval(11, 10)
