"""``cell perceive``: the contract form and its JSON keys; bad input exits 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cell.cli import main

KEYS = {
    "scenes",
    "recall",
    "false_positives",
    "yaw_err_deg_median",
    "yaw_err_deg_p95",
    "pos_err_mm_median",
    "pos_err_mm_p95",
    "ms_per_frame_median",
}


def test_contract_form(tmp_path: Path, capsys) -> None:
    out = tmp_path / "p.json"
    code = main(["perceive", "--scenes", "2", "--seed", "1", "--json", str(out)])
    assert code == 0
    data = json.loads(out.read_text())
    assert KEYS <= set(data) and data["scenes"] == 2
    assert 0.0 <= data["recall"] <= 1.0 and data["found"] >= 1
    # CPU time beside wall time, so that waiting for a core (another job) shows
    assert data["cpu_ms_per_frame_median"] > 0.0 and data["ms_per_frame_p95"] > 0.0
    assert "recall" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--scenes", "0", "--seed", "1"], ["--scenes"]),
        (["--scenes", "1", "--seed", "1", "--weights", "x.pt"], ["--weights"]),
    ],
)
def test_bad_input_exits_2(argv, words, tmp_path: Path, capsys) -> None:
    code = main(["perceive", *argv, "--json", str(tmp_path / "p.json")])
    err = capsys.readouterr().err
    assert code == 2 and all(w in err for w in words), err


def test_learned_weights_that_do_not_exist_exit_2(tmp_path: Path, capsys) -> None:
    argv = ["--scenes", "1", "--seed", "1", "--pipeline", "learned", "--weights", "nope.onnx"]
    code = main(["perceive", *argv, "--json", str(tmp_path / "p.json")])
    err = capsys.readouterr().err
    assert code == 2 and "nope.onnx" in err, err


def test_random_fill_splits_by_part_and_situation(tmp_path: Path, capsys) -> None:
    """Parts tipped in: every scored part is in one kind's row and one situation's row, and the
    one-ended parts found are counted for the open end."""
    out = tmp_path / "r.json"
    argv = ["perceive", "--scenes", "1", "--seed", "7001", "--fill", "random", "--parts", "6"]
    assert main([*argv, "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["fill"] == "random" and data["second_view"] is True
    left_out = sum(data["not_lying"].values())
    assert data["parts"] + left_out == 6
    for key in ("by_part", "by_situation"):
        assert sum(r["parts"] for r in data[key].values()) == data["parts"]
        assert sum(r["found"] for r in data[key].values()) == data["found"]
    assert set(data["by_situation"]) <= {"free", "touching", "wall", "leaning", "on_top"}
    assert data["open_end_decided_right"] <= data["open_end_decided"]
    assert data["open_end_decided"] <= data["open_end_one_ended_parts"]
    assert "by situation" in capsys.readouterr().out


def test_unknown_part_exits_2(tmp_path: Path, capsys) -> None:
    argv = ["perceive", "--scenes", "1", "--seed", "1", "--part", "teapot"]
    code = main([*argv, "--json", str(tmp_path / "p.json")])
    err = capsys.readouterr().err
    assert code == 2 and "--part" in err and "teapot" in err, err
