"""ForcePush's command to the arm's force mode: the push's axis presses, a free axis gives way
with nothing pressed, every other axis is held (fake devices, no physics)."""

from __future__ import annotations

import numpy as np
import pytest

from skills.force import ForcePush
from skills.motion import Guard
from skills.packing import PackInBox
from tests.skills.test_slot_packing_fakes import PART, PLACE, dev, devices, push_back


def test_a_free_axis_is_compliant_with_only_the_starting_reading_commanded() -> None:
    d = devices()
    push_back(d, (0.3, -0.4, -1.5))  # the held part's weight and the sensor's offset
    push = ForcePush("push +x", dev(d), Guard(), (1, 0, 0), 6.0, 0.01, 0.01, free=(1,))
    push.motion.tick()
    selection, wrench, limits = d["arm"].force
    assert selection.tolist() == [True, True, False, False, False, False]
    # the tool applies minus the force on it: the reference, plus the push along +x only
    assert wrench[0] == pytest.approx(-0.3 + 6.0) and wrench[1] == pytest.approx(0.4)
    assert limits[0] == limits[1] == 0.01 and not limits[2:].any()


def test_without_free_axes_the_push_holds_every_other_axis() -> None:
    d = devices()
    push = ForcePush("push +y", dev(d), Guard(), (0, 1, 0), 6.0, 0.01, 0.01)
    push.motion.tick()
    selection, _, _ = d["arm"].force
    assert selection.tolist() == [False, True, False, False, False, False]


@pytest.mark.parametrize("free", [(0,), (3,)])
def test_a_free_axis_must_be_another_base_axis(free: tuple[int, ...]) -> None:
    with pytest.raises(ValueError, match="free axes"):
        ForcePush("push +x", dev(devices()), Guard(), (1, 0, 0), 6.0, 0.01, 0.01, free=free)


def test_packing_pushes_along_x_give_way_along_y_and_the_y_push_holds_x() -> None:
    pack = PackInBox(PLACE, PART, dev(devices()), floor_press=0.0)
    assert pack.push_x.free == (1,) and pack.push_x_again.free == (1,)
    assert pack.push_y.free == () and pack.floor.free == ()
    assert np.allclose(pack.place_xy, PLACE[:2])


def test_packing_sideways_pushes_press_the_part_onto_the_floor_the_floor_push_does_not() -> None:
    """Each sideways push gives way along z and presses ``floor_press`` down, so the held
    part stands on the floor instead of rubbing its neighbour upwards."""
    pack = PackInBox(PLACE, PART, dev(devices()), floor_press=1.5)
    for push in (pack.push_x, pack.push_y, pack.push_x_again):
        assert 2 in push.free and push.lean[2] == pytest.approx(-1.5)
    assert pack.push_x.free == (1, 2) and pack.push_y.free == (2,)
    assert pack.floor.free == () and not pack.floor.lean.any()


def test_packing_sideways_pushes_measure_from_the_hanging_part_not_from_their_start() -> None:
    """A push starting with the part already pressed onto the floor by the push before must
    not take that press as nothing pressed (it would press twice as hard, then three times)."""
    d = devices()
    pack = PackInBox(PLACE, PART, dev(d), floor_press=1.0)
    pack.reference.force = np.array([0.0, 0.0, -2.0])  # the hanging part, read over the place
    push_back(d, (0.0, 0.0, 1.0))  # now pressed onto the floor: the wrist reads the floor's push
    pack.push_y.motion.tick()
    _, wrench, _ = d["arm"].force
    # the arm carries the hanging part's weight less the press (from the reading at the start
    # it would command -1 - 1 = -2 N: pressing 3 N into the floor)
    assert wrench[2] == pytest.approx(2.0 - 1.0)


def test_a_lean_presses_along_its_free_axis_on_top_of_the_reference() -> None:
    d = devices()
    push_back(d, (0.3, -0.4, -1.5))
    push = ForcePush(
        "push +x", dev(d), Guard(), (1, 0, 0), 6.0, 0.01, 0.01, free=(1,), lean=(0, 2.0, 0)
    )
    push.motion.tick()
    _, wrench, _ = d["arm"].force
    assert wrench[0] == pytest.approx(-0.3 + 6.0) and wrench[1] == pytest.approx(0.4 + 2.0)


@pytest.mark.parametrize(("free", "lean"), [((1,), (0, 0, 2.0)), ((), (0, 2.0, 0)), ((1,), (1, 2))])
def test_a_lean_off_the_free_axes_is_refused(free: tuple[int, ...], lean: tuple) -> None:
    with pytest.raises(ValueError, match="leans only"):
        ForcePush("push +x", dev(devices()), Guard(), (1, 0, 0), 6.0, 0.01, 0.01, free=free,
                  lean=lean)


def test_packing_x_pushes_lean_towards_the_y_wall_and_the_others_do_not() -> None:
    pack = PackInBox(PLACE, PART, dev(devices()), floor_press=0.0)
    assert pack.push_x.lean.tolist() == [0.0, pack.params.lean_force, 0.0]
    assert pack.push_x_again.lean.tolist() == [0.0, pack.params.lean_force, 0.0]
    assert not pack.push_y.lean.any() and not pack.floor.lean.any()


def test_a_given_reference_is_what_the_free_axes_hold_not_the_reading_at_the_start() -> None:
    """A push that begins pressing something (a finger caught on a hole's wall) and is given
    the reading from before that contact commands nothing sideways: the contact moves it."""
    d = devices()
    push_back(d, (5.0, -3.0, -1.5))  # a finger pressed sideways as the push begins

    def commanded(reference: np.ndarray | None) -> np.ndarray:
        push = ForcePush(
            "withdraw up", dev(d), Guard(), (0, 0, 1), 6.0, 0.05, 0.04, free=(0, 1),
            reference=lambda: reference,
        )
        push.motion.tick()
        return d["arm"].force[1]

    before = np.array([0.1, -0.2, -1.5])  # read with the part hanging, nothing touching
    wrench = commanded(before)
    assert wrench[0] == pytest.approx(-0.1) and wrench[1] == pytest.approx(0.2)
    assert wrench[2] == pytest.approx(1.5 + 6.0)
    wrench = commanded(None)  # no reading given: the one at the start
    assert wrench[0] == pytest.approx(-5.0) and wrench[1] == pytest.approx(3.0)


def test_packing_withdraws_the_open_hand_giving_way_in_the_plane() -> None:
    pack = PackInBox(PLACE, PART, dev(devices()))
    assert pack.withdraw.axis == 2 and pack.withdraw.sign == 1.0
    assert pack.withdraw.free == (0, 1) and not pack.withdraw.lean.any()
