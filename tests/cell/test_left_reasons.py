"""What `cell sim` says of the parts it left in the bin."""

from __future__ import annotations

from cell.cell_cmds import left_reasons


def _e(kind: str, **data: object) -> dict[str, object]:
    return {"kind": kind, **data}


def test_a_run_that_found_nothing_to_pick_names_what_it_passed_over_and_what_it_never_saw() -> None:
    passed = {"part": "bushing at (0.400, 0.100) m", "reason": "2 picks failed"}
    events = [_e("packed"), _e("cycle_done"), _e("bin_empty", left=[passed]), _e("cycle_failed")]
    assert left_reasons(events, 3) == [
        passed,
        {"part": "a part", "reason": "not found by perception"},
        {"part": "a part", "reason": "not found by perception"},
    ]


def test_a_run_that_ended_on_its_cycles_left_the_rest_untried() -> None:
    events = [
        _e("bin_empty", left=[]), _e("cycle_failed"), _e("picked"), _e("packed"), _e("cycle_done")
    ]
    untried = {"part": "a part", "reason": "not tried: the run ended first"}
    assert left_reasons(events, 2) == [untried, untried]
    assert left_reasons(events, 0) == []


def test_a_cell_that_stopped_says_so_for_each_part_left() -> None:
    out = left_reasons([_e("cycle_failed")], 1, "3 cycles in a row failed")
    why = "left when the cell stopped: 3 cycles in a row failed"
    assert out == [{"part": "a part", "reason": why}]


def test_the_twin_names_the_parts_perception_never_saw_not_those_the_cell_passed_over() -> None:
    passed = {"part": "bushing at (0.400, 0.100) m", "reason": "2 picks failed", "at": [0.4, 0.1]}
    twin = [
        {"part": "bushing at (0.401, 0.101) m", "at": [0.401, 0.101], "lies": "touching"},
        {"part": "bushing at (0.300, -0.100) m", "at": [0.3, -0.1], "lies": "leaning"},
    ]
    events = [_e("bin_empty", left=[passed]), _e("cycle_failed")]
    out = left_reasons(events, 2, twin=twin)
    assert out[0] == passed
    assert out[1]["part"] == "bushing at (0.300, -0.100) m"
    assert out[1]["lies"] == "leaning"
    assert out[1]["reason"] == "not found by perception"


def test_a_stopped_cell_names_each_part_the_twin_holds_in_the_bin() -> None:
    twin = [{"part": "bushing at (0.300, -0.100) m", "at": [0.3, -0.1], "lies": "free"}]
    out = left_reasons([_e("cycle_failed")], 1, "3 cycles in a row failed", twin)
    assert out == [{**twin[0], "reason": "left when the cell stopped: 3 cycles in a row failed"}]


def test_a_bin_found_empty_by_the_look_while_the_machine_ran_ends_the_run_on_it() -> None:
    """The look taken while the machine runs finds nothing to pick; the part in the slot is
    then picked from it and packed, and the run ends: the bin was empty, not the run short."""
    passed = {"part": "bushing at (0.400, 0.100) m", "reason": "2 picks failed"}
    events = [
        _e("picked"), _e("fed"), _e("bin_empty", left=[passed]), _e("machined"),
        _e("picked_from_slot"), _e("packed"), _e("cycle_done"),
    ]
    assert left_reasons(events, 2) == [
        passed, {"part": "a part", "reason": "not found by perception"}
    ]
