"""``cell sweep``: trials as Ray tasks give a serial run's results; the table, JSON and plot;
refused parts; bad input and an unreachable cluster end in one line, exit 2, in bounded time.

One sweep runs through a real local Ray instance (module fixture, in a child process so that
Ray's processes and state never outlive it); the other tests stop before Ray would start.
"""

from __future__ import annotations

import argparse
import csv
import json
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

import lab.sweep_cmd
from cell.cli import main
from cell.errors import UserError

SWEEP_PARTS = ["bushing", "wiring_duct", "mounting_rail"]  # two quick parts and a refused one
TRIALS, SEED = 2, 5


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The contract form on 2 parts x 2 trials with 2 workers, plus a part the planner refuses."""
    out = tmp_path_factory.mktemp("sweep")
    argv = ["--part", *SWEEP_PARTS, "--trials", str(TRIALS), "--workers", "2"]
    argv += ["--seed", str(SEED), "--nominal", "--out", str(out)]
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "cell.cli", "sweep", *argv],
        capture_output=True,
        text=True,
        timeout=240,
    )
    return {
        "proc": proc,
        "out": out,
        "wall": time.perf_counter() - t0,
        "json": json.loads((out / "sweep.json").read_text()) if proc.returncode == 0 else None,
    }


def test_sweep_writes_table_json_and_plot(sweep: dict[str, Any]) -> None:
    proc, out = sweep["proc"], sweep["out"]
    assert proc.returncode == 0, proc.stderr
    # Progress: one line per result as it arrives, numbered against the total.
    progress = [line for line in proc.stderr.splitlines() if line.startswith("[")]
    assert len(progress) == 4 and progress[-1].startswith("[4/4]")
    assert "local Ray instance, 2 CPUs" in proc.stdout
    assert (out / "success.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = {r["part"]: r for r in csv.DictReader((out / "table.csv").open())}
    assert list(rows) == SWEEP_PARTS
    bushing = rows["bushing"]
    assert (bushing["status"], bushing["trials"], bushing["paper_success"]) == ("run", "2", "10/10")
    assert float(bushing["l_a"]) == pytest.approx(0.9)
    assert float(bushing["paper_alpha_deg"]) == pytest.approx(18.0, abs=0.01)
    k = int(bushing["successes"])
    assert 0 <= k <= TRIALS and 0.0 <= float(bushing["wilson_lo"]) <= k / TRIALS
    md = (out / "table.md").read_text()
    assert md.count("\n| bushing |") == 1 and "| 0.9->0.65 | 18.0 | 7.2 | 10/10 | 72-100 % |" in md
    data = sweep["json"]
    assert [p["part"] for p in data["parts"]] == SWEEP_PARTS
    assert data["parts"][0]["plan"]["l_a"] == pytest.approx(0.9)
    assert [t["seed"] for t in data["parts"][1]["per_trial"]] == [SEED, SEED + 1]


def test_refused_part_is_in_the_table_not_run(sweep: dict[str, Any]) -> None:
    assert sweep["proc"].returncode == 0, sweep["proc"].stderr
    rail = sweep["json"]["parts"][2]
    assert rail["status"] == "refused" and rail["per_trial"] == []
    assert "hole narrower than the finger" in rail["reason"]
    md = (sweep["out"] / "table.md").read_text()
    assert "| mounting_rail | refused by the planner: hole narrower than the finger" in md
    assert "| 3/10 |" in md  # the paper's row still beside it
    assert "mounting_rail" not in "".join(
        line for line in sweep["proc"].stderr.splitlines() if line.startswith("[")
    )


def test_same_seeds_same_results_as_a_serial_run(sweep: dict[str, Any]) -> None:
    """Every Ray trial equals run_trial(setup, seed) called here, one after another."""
    from lab.pivot_cmd import build_setup
    from lab.pivot_run import run_trial

    assert sweep["proc"].returncode == 0, sweep["proc"].stderr
    for part in sweep["json"]["parts"][:2]:
        ns = argparse.Namespace(
            part=part["part"],
            trials=TRIALS,
            jobs=1,
            mu_ground=None,
            record=None,
            catalogue=None,
            cell=None,
            nominal=True,
            force=False,
            la=None,
            alpha=None,
        )
        setup = build_setup(ns)[0]
        for i, remote in enumerate(part["per_trial"]):
            serial = json.loads(json.dumps(run_trial(setup, SEED + i).to_json()))
            # Everything but the trial's own wall time: outcome, phase, tilt, height, simulated
            # time, the perturbed pose, frictions and mass, to the last bit.
            assert {**remote, "wall_time": 0} == {**serial, "wall_time": 0}


@pytest.fixture
def no_ray(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if Ray would be started: bad input must be refused before it."""

    def trap(*args: object, **kwargs: object) -> bool:
        raise AssertionError("Ray was started")

    monkeypatch.setattr(lab.sweep_cmd, "connect_ray", trap)


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--trials", "0"], "--trials: must be >= 1, got 0"),
        (["--trials", "-3"], "--trials: must be >= 1, got -3"),
        (["--trials", "2", "--workers", "0"], "--workers: must be >= 1, got 0"),
        (["--trials", "2", "--part", "bushing"], "--part: bushing is given twice"),
        (["--trials", "2", "--part", "teapot"], "unknown part 'teapot'"),
        (["--trials", "2", "--address", "ray://head:10001"], "ray[client]"),
        (["--trials", "2", "--address", "head"], "--address head: expected host:port"),
        (
            ["--trials", "2", "--set", "skills.pivot.no_such_key=1"],
            "--set skills.pivot.no_such_key=1: skills.pivot.no_such_key: unknown key",
        ),
        (["--trials", "2", "--set", "sim.mu_ground=abc"], "sim.mu_ground: expected a number"),
    ],
)
def test_bad_input_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], words: str, no_ray: None
) -> None:
    argv = ["sweep", "--part", "bushing", "--out", str(tmp_path / "o"), *extra]
    code, _, err = run_cli(argv, capsys)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("cell sweep: error: ") and words in err
    assert not (tmp_path / "o").exists()


def test_config_and_set_reach_every_parts_setup(tmp_path: Path, no_ray: None) -> None:
    """--config and --set give each part's trials the configuration, as `cell pivot` does."""
    from cell.cli import build_parser

    path = tmp_path / "cell.yaml"
    path.write_text("sim: {mu_ground: 0.6}\nskills:\n  perceive: {speed_m_s: 0.4}\n")
    argv = ["sweep", "--part", "bushing", "wiring_duct", "--trials", "1", "--out", str(tmp_path)]
    args = build_parser().parse_args(
        [*argv, "--config", str(path), "--set", "skills.pivot.approach_speed_m_s=0.07"]
    )
    rows = lab.sweep_cmd.prepare(args)
    assert [row.name for row in rows] == ["bushing", "wiring_duct"]
    for row in rows:
        assert row.setup is not None and row.setup.mu_ground == 0.6
        assert row.setup.params["approach_speed"] == 0.07 and row.setup.look.speed == 0.4


def test_trials_is_required(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["sweep", "--part", "bushing", "--out", str(tmp_path)], capsys)
    assert code == 2 and "--trials" in err


def test_only_refused_parts_need_no_ray(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_ray: None
) -> None:
    argv = ["sweep", "--part", "mounting_rail", "water_bottle", "--trials", "3"]
    code, out, err = run_cli([*argv, "--out", str(tmp_path)], capsys)
    assert code == 0, err
    assert "water_bottle: refused by the planner, not run: deformable" in out
    rows = list(csv.DictReader((tmp_path / "table.csv").open()))
    assert [(r["status"], r["trials"]) for r in rows] == [("refused", ""), ("refused", "")]
    assert (tmp_path / "success.png").stat().st_size > 0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_unreachable_address_is_named_exit_2_quickly(tmp_path: Path) -> None:
    address = f"127.0.0.1:{_free_port()}"  # nothing listens there: refused at once
    argv = ["sweep", "--part", "bushing", "--trials", "1", "--address", address]
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "cell.cli", *argv, "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert time.perf_counter() - t0 < 30
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"cell sweep: error: --address {address}: ")
    assert not (tmp_path / "o").exists()


def test_a_silent_cluster_is_given_up_after_the_timeout(monkeypatch: pytest.MonkeyPatch) -> None:
    """An address that accepts TCP but never completes Ray's handshake: ray.init would retry
    for minutes; the wait is bounded and the error names the address."""
    import ray

    release = threading.Event()
    monkeypatch.setattr(lab.sweep_cmd, "_probe", lambda address, timeout: None)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", lambda **kw: release.wait(10))
    t0 = time.perf_counter()
    with pytest.raises(UserError, match=r"--address 10\.1\.2\.3:6379: no Ray cluster answered"):
        lab.sweep_cmd.connect_ray("10.1.2.3:6379", None, timeout=0.5)
    assert time.perf_counter() - t0 < 3
    release.set()


def test_failed_handshake_is_one_line_naming_the_address(monkeypatch: pytest.MonkeyPatch) -> None:
    import ray

    def refuse(**kw: object) -> None:
        raise ConnectionError("Failed to connect to Ray cluster at 10.1.2.3:6379\nmore detail")

    monkeypatch.setattr(lab.sweep_cmd, "_probe", lambda address, timeout: None)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", refuse)
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    with pytest.raises(UserError) as info:
        lab.sweep_cmd.connect_ray("10.1.2.3:6379", None, timeout=5)
    assert str(info.value) == (
        "--address 10.1.2.3:6379: cannot connect to a Ray cluster there: "
        "Failed to connect to Ray cluster at 10.1.2.3:6379"
    )


def test_a_refused_handshake_hints_at_token_authentication(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Clusters from `ray start` want a token that a driver with an explicit address sends only
    with RAY_AUTH_MODE=token; Ray's own refusal does not say so."""
    import ray

    def refuse(**kw: object) -> None:
        raise ConnectionError("Failed to connect to Ray cluster at 10.1.2.3:6379")

    monkeypatch.setattr(lab.sweep_cmd, "_probe", lambda address, timeout: None)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", refuse)
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    with pytest.raises(UserError, match="set RAY_AUTH_MODE=token"):
        lab.sweep_cmd.connect_ray("10.1.2.3:6379", None, timeout=5)


def test_spread_keeps_crowded_points_apart_in_order_around_their_mean() -> None:
    xs = [0.9, 0.5, 0.9, 0.9, 0.2]
    out = lab.sweep_cmd.spread(xs, 0.02)
    assert out[1] == 0.5 and out[4] == 0.2  # alone: not moved
    crowd = [out[0], out[2], out[3]]
    assert crowd == sorted(crowd) and sum(crowd) / 3 == pytest.approx(0.9)
    assert min(b - a for a, b in zip(crowd, crowd[1:], strict=False)) == pytest.approx(0.02)
