"""The cell's uncertainty in `cell pivot`, `cell compare` and `cell sweep`: on by default, every
trial's draws in its JSON entry, ``--ideal`` to turn it off (sim/uncertainty.py)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from cell.cli import main
from sim.uncertainty import Uncertainty

#: the draws that are errors of a real cell; --ideal makes every one of them 0
ERRORS = (
    "hand_eye_x_mm", "hand_eye_y_mm", "hand_eye_z_mm", "hand_eye_rx_deg", "hand_eye_ry_deg",
    "hand_eye_rz_deg", "floor_dz_mm", "outer_dmm", "hole_dmm", "length_dmm", "lag_steps",
)


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> dict:
    code = main(argv)
    _, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(Path(argv[argv.index("--json") + 1]).read_text())


@pytest.mark.parametrize("ideal", [False, True])
def test_pivot_records_each_trials_draws(tmp_path: Path, capsys, ideal: bool) -> None:
    argv = ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--nominal",
            "--json", str(tmp_path / "p.json")] + (["--ideal"] if ideal else [])
    data = _run(argv, capsys)
    assert data["ideal"] is ideal
    draws = data["per_trial"][0]["draws"]
    assert all(isinstance(v, float) for v in draws.values())
    errors = [draws[k] for k in ERRORS]
    if ideal:
        assert errors == [0.0] * len(ERRORS) and draws["ft_rate_hz"] == 0.0
    else:
        assert all(e != 0.0 for e in errors) and draws["ft_rate_hz"] == 100.0
    trial = data["per_trial"][0]
    assert trial["frictions"] == {"S": draws["mu_s"], "H": draws["mu_h"], "G": draws["mu_g"]}


def test_mu_ground_still_forces_the_floor_friction(tmp_path: Path, capsys) -> None:
    argv = ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--nominal",
            "--mu-ground", "0.33", "--json", str(tmp_path / "p.json")]
    data = _run(argv, capsys)
    trial = data["per_trial"][0]
    assert trial["frictions"]["G"] == trial["draws"]["mu_g"] == 0.33
    assert trial["draws"]["floor_dz_mm"] != 0.0  # the rest is still drawn


def test_compare_meets_the_same_draws_with_both_methods(tmp_path: Path, capsys) -> None:
    """Seed 100 under the cell's uncertainty: both methods meet the same draws (what each
    made of them is the measurement: the regrasp's set-down trips its 25 N guard here)."""
    argv = ["compare", "--part", "bushing", "--trials", "1", "--seed", "100", "--nominal",
            "--json", str(tmp_path / "c.json")]
    data = _run(argv, capsys)
    assert data["ideal"] is False
    p, r = (data["methods"][m]["per_trial"][0] for m in ("pivot", "regrasp"))
    assert p["draws"] == r["draws"] and p["draws"]["floor_dz_mm"] != 0.0
    assert p["true_pose"] == r["true_pose"]


def test_sweep_passes_ideal_to_every_part() -> None:
    from lab.sweep_cmd import prepare

    def rows(ideal: bool) -> list:
        args = argparse.Namespace(
            part=["bushing", "mounting_rail"], trials=1, workers=None, address=None, seed=0,
            nominal=True, out=Path("unused"), cell=None, catalogue=None, config=None, set=[],
            ideal=ideal,
        )
        return [row for row in prepare(args) if not row.refused]

    assert [row.setup.uncertainty for row in rows(False)] == [Uncertainty()]
    assert all(row.setup.uncertainty.is_ideal for row in rows(True))
