"""The tact-time breakdown: each leaf's runs and time from its status changes."""

from __future__ import annotations

import pytest

from cell.phases import PhaseTimes


def test_a_leaf_run_lasts_from_running_to_its_end() -> None:
    p = PhaseTimes()
    p.change("tilt", "RUNNING", 1.0)
    p.change("tilt", "SUCCESS", 7.0)
    p.change("tilt", "RUNNING", 10.0)
    p.change("tilt", "FAILURE", 12.0)
    p.change("holding part", "SUCCESS", 12.0)  # a condition never RUNNING: no time, no row
    rows = p.table(parts=2)
    assert [r["phase"] for r in rows] == ["tilt"]
    assert rows[0]["runs"] == 2 and rows[0]["failed"] == 1
    assert rows[0]["total_s"] == pytest.approx(8.0) and rows[0]["mean_s"] == pytest.approx(4.0)
    assert rows[0]["per_part_s"] == pytest.approx(4.0)


def test_a_halted_leaf_counts_up_to_its_halt_and_a_running_one_not_yet() -> None:
    p = PhaseTimes()
    p.change("feed slot", "RUNNING", 0.0)
    p.change("feed slot", "INVALID", 3.0)
    p.change("pack in box", "RUNNING", 3.0)
    rows = {r["phase"]: r for r in p.table()}
    assert rows["feed slot"]["total_s"] == pytest.approx(3.0)
    assert "per_part_s" not in rows["feed slot"]
    assert "pack in box" not in rows
