"""``cell pivot``: the contract form, its JSON, and bad input (exit 2, one line, no motion)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

import cell.experiments.pivot_run
from cell.cli import main


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def no_simulation(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Fail the test if a trial is started: bad input must be refused before any motion."""
    started: list[int] = []

    def trap(*args, **kwargs):
        started.append(1)
        raise AssertionError("a trial was simulated")

    monkeypatch.setattr(cell.experiments.pivot_run, "run_trial", trap)
    return started


def test_contract_form_writes_the_summary(tmp_path: Path, capsys) -> None:
    out_json = tmp_path / "r.json"
    code, out, err = run_cli(
        ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--json", str(out_json)],
        capsys,
    )
    assert code == 0, err
    data = json.loads(out_json.read_text())
    assert data["part"] == "bushing" and data["trials"] == 1
    assert data["successes"] == 1
    lo, hi = data["wilson95"]
    assert 0.0 < lo < hi == pytest.approx(1.0)
    trial = data["per_trial"][0]
    assert trial["success"] is True and trial["failure"] is None
    assert {"seed", "tilt_deg", "height_m", "true_pose", "frictions", "mass"} <= set(trial)
    assert data["plan"]["l_a"] == pytest.approx(0.9)
    assert "1/1" in out and "Wilson" in out
    assert "1/1" in err  # the progress bar


def test_mu_ground_is_used_exactly(tmp_path: Path, capsys, monkeypatch) -> None:
    seen = []
    real = cell.experiments.pivot_run.run_trial

    def spy(setup, seed, **kw):
        seen.append(setup.mu_ground)
        return real(setup, seed, **kw)

    monkeypatch.setattr(cell.experiments.pivot_run, "run_trial", spy)
    out_json = tmp_path / "r.json"
    args = ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--mu-ground", "0.7"]
    code, _, err = run_cli([*args, "--json", str(out_json)], capsys)
    assert code == 0, err
    assert seen == [0.7]
    assert json.loads(out_json.read_text())["per_trial"][0]["frictions"]["G"] == 0.7


@pytest.mark.parametrize(
    ("part", "words"),
    [
        ("no_such_part", ["unknown part 'no_such_part'", "parts.yaml"]),
        ("mounting_rail", ["parts.mounting_rail", "hole narrower than the finger"]),
        ("water_bottle", ["parts.water_bottle", "deformable"]),
    ],
)
def test_parts_that_cannot_be_pivoted_are_refused(
    part: str, words: list[str], tmp_path: Path, capsys, no_simulation
) -> None:
    code, out, err = run_cli(
        ["pivot", "--part", part, "--trials", "2", "--seed", "0", "--json", str(tmp_path / "r")],
        capsys,
    )
    assert code == 2
    assert all(w in err for w in words), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()


def test_forcing_the_rail_is_still_refused_its_finger_cannot_enter(
    tmp_path: Path, capsys, no_simulation
) -> None:
    code, _, err = run_cli(
        ["pivot", "--part", "mounting_rail", "--force", "--json", str(tmp_path / "r")], capsys
    )
    assert code == 2 and "hole_mm" in err and "not even with --force" in err


def _cell(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("layout", "words"),
    [
        ({"bin_center": [0.10, 0.40]}, ["bin_center", "overlaps machine"]),
        (
            {"floor_size": [3.0, 3.0], "bin_center": [1.2, 0.0]},
            ["bin_center", "out of the UR5's reach"],
        ),
        ({"bin_inner_size": [0.12, 0.3]}, ["bin_center", "outside the bin"]),
        ({"bin_wall_height": "high"}, ["bin_wall_height", "expected a finite number"]),
        ({"no_such_key": 1}, ["no_such_key", "unknown key"]),
    ],
)
def test_bad_cell_yaml_is_refused_naming_file_and_key(
    layout: dict, words: list[str], tmp_path: Path, capsys, no_simulation
) -> None:
    path = _cell(tmp_path, layout)
    code, _, err = run_cli(
        ["pivot", "--part", "bushing", "--cell", str(path), "--json", str(tmp_path / "r")], capsys
    )
    assert code == 2, err
    assert str(path) in err and all(w in err for w in words), err


@pytest.mark.parametrize(
    ("extra", "word"),
    [
        (["--trials", "0"], "--trials"),
        (["--mu-ground", "-1"], "--mu-ground"),
        (["--record", "x.mp4"], "--record"),
        (["--la", "0.5"], "--la/--alpha"),
    ],
)
def test_bad_options_are_refused(extra, word, tmp_path: Path, capsys, no_simulation) -> None:
    code, _, err = run_cli(
        ["pivot", "--part", "bushing", *extra, "--json", str(tmp_path / "r")], capsys
    )
    assert code == 2 and word in err, err
