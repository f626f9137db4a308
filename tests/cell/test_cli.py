"""Tests of the ``cell`` command line: in-process through :func:`cell.cli.main`, and a few
through a real interpreter to check exit statuses and that users never see a traceback."""

from __future__ import annotations

import contextlib
import io
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from cell.catalogue import load_catalogue
from cell.cli import main
from skills.mechanics.contact import Frictions
from skills.mechanics.region import alpha_axis, beta_axis, region_map

from .conftest import TABLE3_PARTS as PARTS

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
GRID = 21
ANALYZE = ["--la", "0.3", "0.9", "--mu-s", "0.2", "--mu-h", "0.4", "--mu-g", "0.4"]


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``main(argv)`` in-process: (exit status, stdout, stderr). argparse's SystemExit counts."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    out, err = capsys.readouterr()
    return code, out, err


def run_subprocess(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cell.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
    )


def assert_user_error(code: int, out: str, err: str, command: str, *needles: str) -> str:
    """Exit 2, exactly one line on stderr naming the command and every needle, no traceback."""
    assert code == 2, (out, err)
    assert "Traceback" not in err and "Traceback" not in out
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    line = lines[0]
    assert line.startswith(f"cell {command}: error:"), line
    for needle in needles:
        assert needle in line, (needle, line)
    return line


def analyze_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], *extra: str
) -> tuple[dict[str, Any], Path, str]:
    out_dir = tmp_path / "out"
    json_path = tmp_path / "sub" / "map.json"
    argv = ["analyze", *extra, "--grid", str(GRID), "--out", str(out_dir), "--json", str(json_path)]
    code, out, err = run_cli(argv, capsys)
    assert code == 0, err
    assert "Traceback" not in err
    return json.loads(json_path.read_text(encoding="utf-8")), out_dir, out


def assert_one_png(out_dir: Path) -> Path:
    pngs = sorted(out_dir.glob("*.png"))
    assert len(pngs) == 1, pngs
    assert sorted(out_dir.iterdir()) == pngs  # nothing else written there
    data = pngs[0].read_bytes()
    assert len(data) > len(PNG_MAGIC)
    assert data.startswith(PNG_MAGIC)
    return pngs[0]


# --- cell analyze -----------------------------------------------------------------------------
#
# Each analyze run costs about a second per l_a (its summary table bisects for the smallest
# alpha), so the full two-l_a run is shared by the tests that only read its output.


@pytest.fixture(scope="module")
def bushing_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("analyze")
    out_dir, json_path = tmp / "out", tmp / "sub" / "map.json"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(
            [
                "analyze",
                "--part",
                "bushing",
                *ANALYZE,
                "--grid",
                str(GRID),
                "--out",
                str(out_dir),
                "--json",
                str(json_path),
            ]
        )
    return {
        "code": code,
        "out": stdout.getvalue(),
        "err": stderr.getvalue(),
        "out_dir": out_dir,
        "data": json.loads(json_path.read_text(encoding="utf-8")),
    }


def test_analyze_exits_0_and_writes_one_png(bushing_run: dict[str, Any]) -> None:
    assert bushing_run["code"] == 0, bushing_run["err"]
    assert "Traceback" not in bushing_run["err"]
    png = assert_one_png(bushing_run["out_dir"])
    assert "bushing" in png.name
    assert str(png) in bushing_run["out"]


def test_analyze_json_layout(bushing_run: dict[str, Any]) -> None:
    data = bushing_run["data"]
    assert {"part", "l_a", "alpha", "beta", "stable"} <= set(data)
    assert data["part"] == "bushing"
    assert data["l_a"] == pytest.approx([0.3, 0.9])

    alpha = np.asarray(data["alpha"], dtype=float)
    assert alpha.shape == (GRID,)
    assert np.all(alpha > 0.0) and np.all(alpha < math.pi / 2)
    steps = np.diff(alpha)
    assert np.all(steps > 0)
    assert steps == pytest.approx(np.full(GRID - 1, steps[0]), rel=1e-9)

    beta = np.asarray(data["beta"], dtype=float)
    assert beta.shape == (GRID,)
    assert beta[0] == pytest.approx(0.0, abs=1e-15)
    assert beta[-1] == pytest.approx(math.pi / 2, rel=1e-12)
    assert np.diff(beta) == pytest.approx(np.full(GRID - 1, (math.pi / 2) / (GRID - 1)), rel=1e-9)

    stable = data["stable"]
    assert isinstance(stable, list) and len(stable) == 2
    for per_la in stable:
        assert isinstance(per_la, list) and len(per_la) == GRID
        for per_alpha in per_la:
            assert isinstance(per_alpha, list) and len(per_alpha) == GRID
            assert all(isinstance(v, bool) for v in per_alpha)
    arr = np.asarray(stable)
    # A useful map: the bushing has stable and unstable grasps at both l_a.
    assert arr.any(axis=(1, 2)).all()
    assert (~arr).any(axis=(1, 2)).all()


def test_analyze_json_equals_region_map(bushing_run: dict[str, Any]) -> None:
    data = bushing_run["data"]
    section = load_catalogue().get("bushing").section(0.020)
    la = np.array([0.3, 0.9])
    alphas, betas = alpha_axis(GRID), beta_axis(GRID)
    expected = region_map(section, la, alphas, betas, Frictions(0.2, 0.4, 0.4))
    np.testing.assert_allclose(data["alpha"], alphas, rtol=0, atol=1e-15)
    np.testing.assert_allclose(data["beta"], betas, rtol=0, atol=1e-15)
    got = np.asarray(data["stable"], dtype=bool)
    assert got.shape == expected.shape == (2, GRID, GRID)
    np.testing.assert_array_equal(got, expected)


def test_analyze_passes_part_and_frictions_through(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mu = ["--mu-s", "0.5", "--mu-h", "0.1", "--mu-g", "0.8"]
    data, out_dir, _ = analyze_json(tmp_path, capsys, "--part", "cookie_can", "--la", "0.9", *mu)
    assert data["part"] == "cookie_can"
    assert "cookie_can" in assert_one_png(out_dir).name
    section = load_catalogue().get("cookie_can").section(0.020)
    alphas, betas = alpha_axis(GRID), beta_axis(GRID)
    expected = region_map(section, [0.9], alphas, betas, Frictions(0.5, 0.1, 0.8))
    default = region_map(section, [0.9], alphas, betas, Frictions(0.2, 0.4, 0.4))
    assert not np.array_equal(expected, default)  # otherwise this test shows nothing
    np.testing.assert_array_equal(np.asarray(data["stable"], dtype=bool), expected)


def test_analyze_default_part_is_bushing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data, out_dir, out = analyze_json(tmp_path, capsys, "--la", "0.5", "--finger-width", "0.010")
    assert data["part"] == "bushing"
    assert data["l_a"] == pytest.approx([0.5])
    assert "bushing" in assert_one_png(out_dir).name
    assert out.startswith("bushing:")
    # --finger-width reaches the section (Eq. 3 gives a different delta).
    section = load_catalogue().get("bushing").section(0.010)
    expected = region_map(
        section, [0.5], alpha_axis(GRID), beta_axis(GRID), Frictions(0.2, 0.4, 0.4)
    )
    np.testing.assert_array_equal(np.asarray(data["stable"], dtype=bool), expected)
    assert f"delta = {section.delta * 1e3:.2f} mm" in out


def test_analyze_subprocess(tmp_path: Path) -> None:
    out_dir = tmp_path / "figs"
    json_path = tmp_path / "map.json"
    proc = run_subprocess(
        [
            "analyze",
            "--part",
            "bushing",
            "--la",
            "0.9",
            "--grid",
            "5",
            "--out",
            str(out_dir),
            "--json",
            str(json_path),
        ],
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert_one_png(out_dir)
    data = json.loads(json_path.read_text(encoding="utf-8"))
    assert np.asarray(data["stable"]).shape == (1, 5, 5)


# --- cell plan --------------------------------------------------------------------------------


def plan_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], *args: str
) -> tuple[dict[str, Any], str]:
    json_path = tmp_path / "plan.json"
    code, out, err = run_cli(["plan", *args, "--json", str(json_path)], capsys)
    assert code == 0, err
    assert "Traceback" not in err
    return json.loads(json_path.read_text(encoding="utf-8")), out


def test_plan_bushing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data, out = plan_json(tmp_path, capsys, "--part", "bushing")
    assert {"l_a", "alpha", "delta_m", "pivotable", "reason"} <= set(data)
    assert data["pivotable"] is True
    assert 0.0 < data["l_a"] <= 1.0
    assert 0.0 < data["alpha"] < math.pi / 2
    assert data["delta_m"] == pytest.approx(0.0072, abs=1e-4)
    assert "bushing" in out and "pivotable" in out


def test_plan_bushing_is_consistent_with_check_tilt(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Whatever (l_a, alpha) the planner picks, the path check must accept it."""
    data, _ = plan_json(tmp_path, capsys, "--part", "bushing")
    code, out, err = run_cli(
        [
            "check-tilt",
            "--part",
            "bushing",
            "--la",
            repr(data["l_a"]),
            "--alpha",
            repr(data["alpha"]),
        ],
        capsys,
    )
    assert code == 0, (out, err)
    assert "ok" in out


def test_plan_water_bottle_is_refused_as_deformable(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data, out = plan_json(tmp_path, capsys, "--part", "water_bottle")
    assert data["pivotable"] is False
    assert "deformable" in data["reason"]
    assert data["l_a"] is None and data["alpha"] is None
    assert "NOT pivotable" in out


def test_plan_mounting_rail_hole_too_narrow(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data, _ = plan_json(tmp_path, capsys, "--part", "mounting_rail")
    assert data["pivotable"] is False
    assert "hole narrower than the finger" in data["reason"]


def test_plan_mounting_rail_without_json(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["plan", "--part", "mounting_rail"], capsys)
    assert code == 0, err
    assert "NOT pivotable" in out
    assert "hole narrower than the finger" in out


def test_plan_all_prints_every_part(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["plan", "--all"], capsys)
    assert code == 0, err
    assert err == ""
    for name in PARTS:
        assert name in out
    assert out.count("NOT pivotable") >= 2  # water bottle and mounting rail


def test_plan_all_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data, _ = plan_json(tmp_path, capsys, "--all")
    plans = {p["part"]: p for p in data["plans"]}
    assert list(plans) == list(PARTS)
    assert plans["bushing"]["pivotable"] is True
    assert plans["water_bottle"]["pivotable"] is False
    assert plans["mounting_rail"]["pivotable"] is False


def test_plan_uses_a_custom_catalogue(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    catalogue = tmp_path / "mine.yaml"
    catalogue.write_text(
        yaml.safe_dump(
            {
                "parts": {
                    "tube": {
                        "length_mm": 100,
                        "outer_mm": 40,
                        "hole_mm": 30,
                        "hole_shape": "circle",
                        "mass_kg": 0.1,
                        "rigid": False,
                    }
                }
            }
        ),
        encoding="utf-8",
    )
    data, out = plan_json(tmp_path, capsys, "--part", "tube", "--catalogue", str(catalogue))
    assert data["part"] == "tube"
    assert data["pivotable"] is False and "deformable" in data["reason"]


# --- user errors ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "command", "needles"),
    [
        (["analyze", "--la", "1.5"], "analyze", ("l_a", "1.5")),
        (["analyze", "--la", "0.3", "0"], "analyze", ("l_a", "got 0")),
        (["analyze", "--la", "-0.2"], "analyze", ("l_a", "-0.2")),
        (["analyze", "--la", "nan"], "analyze", ("l_a", "nan")),
        (["analyze", "--mu-g", "-0.1"], "analyze", ("mu_g", "-0.1")),
        (["analyze", "--mu-s", "inf"], "analyze", ("mu_s",)),
        (["analyze", "--part", "nosuchpart"], "analyze", ("nosuchpart", "known parts", *PARTS)),
        (
            ["analyze", "--part", "bushing", "--finger-width", "0.03"],
            "analyze",
            ("finger", "30.0 mm", "28.0 mm"),
        ),
        (["analyze", "--finger-width", "-0.01"], "analyze", ("finger_width",)),
        (["analyze", "--grid", "1"], "analyze", ("--grid", "1")),
        (["analyze", "--grid", "0"], "analyze", ("--grid", "0")),
        (["plan", "--part", "nosuchpart"], "plan", ("nosuchpart", "known parts", *PARTS)),
        (["plan", "--part", "bushing", "--mu-h", "-1"], "plan", ("mu_h", "-1")),
        (["plan", "--part", "bushing", "--la-max", "1.5"], "plan", ("1.5",)),
        (["plan", "--part", "bushing", "--stroke", "-0.05"], "plan", ("stroke",)),
        (["plan"], "plan", ("--part", "--all")),
        (["plan", "--part", "bushing", "--all"], "plan", ("--part", "--all")),
        (["check-tilt", "--la", "0.9", "--alpha", "2.0"], "check-tilt", ("alpha", "2")),
        (["check-tilt", "--la", "0.9", "--alpha", "0"], "check-tilt", ("alpha", "got 0")),
        (["check-tilt", "--la", "0.9", "--alpha", "-0.3"], "check-tilt", ("alpha", "-0.3")),
        (["check-tilt", "--la", "1.01", "--alpha", "0.3"], "check-tilt", ("l_a", "1.01")),
        (
            ["check-tilt", "--la", "0.9", "--alpha", "0.3", "--finger-width", "0.03"],
            "check-tilt",
            ("finger", "30.0 mm"),
        ),
        (
            ["check-tilt", "--part", "nosuchpart", "--la", "0.9", "--alpha", "0.3"],
            "check-tilt",
            ("nosuchpart", "known parts"),
        ),
    ],
)
def test_user_errors_exit_2_with_one_line(
    argv: list[str],
    command: str,
    needles: tuple[str, ...],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    if command == "analyze":
        argv = [*argv, "--out", str(tmp_path / "out")]
        if "--grid" not in argv:
            argv += ["--grid", "3"]
    code, out, err = run_cli(argv, capsys)
    assert_user_error(code, out, err, command, *needles)
    # A rejected analyze must not leave a half-done figure behind.
    assert not (tmp_path / "out").exists()


def _bad_catalogue(tmp_path: Path) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "parts": {
                    "bushing": {
                        "length_mm": -68,
                        "outer_mm": 34,
                        "hole_mm": 28,
                        "hole_shape": "circle",
                        "mass_kg": 0.156,
                    }
                }
            }
        ),
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize(
    "argv",
    [
        ["analyze", "--grid", "3"],
        ["plan", "--part", "bushing"],
        ["plan", "--all"],
        ["check-tilt", "--la", "0.9", "--alpha", "0.3"],
    ],
)
def test_malformed_catalogue_names_file_and_key(
    argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = _bad_catalogue(tmp_path)
    extra = ["--out", str(tmp_path / "out")] if argv[0] == "analyze" else []
    code, out, err = run_cli([*argv, *extra, "--catalogue", str(bad)], capsys)
    assert_user_error(code, out, err, argv[0], str(bad), "parts.bushing.length_mm", "-68")


def test_missing_catalogue_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "missing.yaml"
    code, out, err = run_cli(["plan", "--part", "bushing", "--catalogue", str(missing)], capsys)
    assert_user_error(code, out, err, "plan", str(missing))


def test_unwritable_json_is_a_user_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory", encoding="utf-8")
    target = blocker / "plan.json"
    code, out, err = run_cli(["plan", "--part", "bushing", "--json", str(target)], capsys)
    assert_user_error(code, out, err, "plan", str(target))


def test_user_error_subprocess_bad_la(tmp_path: Path) -> None:
    proc = run_subprocess(
        ["analyze", "--la", "1.5", "--grid", "3", "--out", str(tmp_path / "out")], cwd=tmp_path
    )
    assert_user_error(proc.returncode, proc.stdout, proc.stderr, "analyze", "1.5")


def test_user_error_subprocess_malformed_catalogue(tmp_path: Path) -> None:
    bad = _bad_catalogue(tmp_path)
    proc = run_subprocess(["plan", "--part", "bushing", "--catalogue", str(bad)], cwd=tmp_path)
    assert_user_error(
        proc.returncode, proc.stdout, proc.stderr, "plan", str(bad), "parts.bushing.length_mm"
    )


def test_user_error_subprocess_plan_without_part(tmp_path: Path) -> None:
    proc = run_subprocess(["plan"], cwd=tmp_path)
    assert_user_error(proc.returncode, proc.stdout, proc.stderr, "plan", "--all")


# --- cell check-tilt --------------------------------------------------------------------------


def test_check_tilt_bushing_paper_grasp_is_ok(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(
        ["check-tilt", "--part", "bushing", "--la", "0.9", "--alpha", "0.3142"], capsys
    )
    assert code == 0, err
    assert err == ""
    assert out.startswith("bushing:")
    assert out.rstrip().endswith("ok")


def test_check_tilt_failing_grasp_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    # At l_a = 0.3 the bushing needs a steep gripper; 3 degrees is not stable even lying flat.
    code, out, err = run_cli(["check-tilt", "--la", "0.3", "--alpha", "0.05"], capsys)
    assert code == 1, (out, err)
    assert "FAILS" in out
    assert "Traceback" not in err


def test_check_tilt_subprocess(tmp_path: Path) -> None:
    ok = run_subprocess(
        ["check-tilt", "--part", "bushing", "--la", "0.9", "--alpha", "0.3142"], cwd=tmp_path
    )
    assert ok.returncode == 0, ok.stderr
    assert "Traceback" not in ok.stderr
    bad = run_subprocess(["check-tilt", "--la", "0.9", "--alpha", "2.0"], cwd=tmp_path)
    assert_user_error(bad.returncode, bad.stdout, bad.stderr, "check-tilt", "alpha", "2")


# --- help ---------------------------------------------------------------------------------------


def test_top_level_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for command in ("analyze", "plan", "check-tilt"):
        assert command in out


@pytest.mark.parametrize(
    ("command", "options"),
    [
        ("analyze", ("--part", "--la", "--grid", "--out", "--json", "--mu-s", "--catalogue")),
        ("plan", ("--part", "--all", "--json", "--stroke", "--finger-width")),
        ("check-tilt", ("--la", "--alpha", "--to")),
    ],
)
def test_subcommand_help(
    command: str, options: tuple[str, ...], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for option in options:
        assert option in out


def test_no_command_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2
    assert "Traceback" not in capsys.readouterr().err
