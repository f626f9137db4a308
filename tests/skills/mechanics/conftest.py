"""Shared fixtures: the bushing of Table 3 with the 20 mm finger, and the paper's friction sets."""

import pytest

from drivers.parts import Section, delta_round
from skills.mechanics.contact import Frictions

FRICTIONLESS = Frictions(0.0, 0.0, 0.0)
GROUND_ONLY = Frictions(0.0, 0.0, 0.4)  # Fig. 5(b), Fig. 7
PAPER = Frictions(0.2, 0.4, 0.4)  # Fig. 5(c), Fig. 11


@pytest.fixture
def bushing() -> Section:
    return Section(a=0.034, b=0.017, delta=delta_round(0.034, 0.028, 0.020))
