"""One headless end-to-end cycle of the cell in the twin, through the contract CLI; the log and
its replay; SIGTERM stops the run cleanly."""

from __future__ import annotations

import json
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

CONFIG = """\
sim:
  seed: 3
bin:
  parts: 2
workflow:
  cycles: 1
  machining_time_s: 3.0  # longer than the way back over the slot: the wait shows
log:
  tick_log: {log}
  state_file: {state}
  journal: {state}.sqlite
"""


def _write_config(tmp_path: Path, text: str = CONFIG) -> tuple[Path, Path, Path]:
    log, state = tmp_path / "ticks.jsonl", tmp_path / "state.json"
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(text.format(log=log, state=state))
    return cfg, log, state


@pytest.fixture(scope="module")
def one_cycle(tmp_path_factory: pytest.TempPathFactory) -> dict:
    tmp = tmp_path_factory.mktemp("cycle")
    cfg, log, state = _write_config(tmp)
    out = tmp / "sim.json"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cell.cli",
            "sim",
            "--config",
            str(cfg),
            "--cycles",
            "1",
            "--seed",
            "3",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    return {"run": r, "out": out, "log": log, "state": state, "tmp": tmp}


def test_one_cycle_feeds_machines_and_packs_a_part_judged_by_the_twin(one_cycle) -> None:
    r = one_cycle["run"]
    assert r.returncode == 0, r.stderr[-2000:]
    s = json.loads(one_cycle["out"].read_text())
    for key in ("cycles", "packed", "fed", "aborts", "tact_time_s_mean", "wall_s"):
        assert key in s
    assert s["cycles"] == 1 and s["fed"] == 1 and s["packed"] == 1, s
    kinds = [e["kind"] for e in s["events"]]
    assert (
        kinds.index("picked")
        < kinds.index("fed")
        < kinds.index("machined")
        < kinds.index("picked_from_slot")
        < kinds.index("packed")
    )
    # Judged from the simulated state, not from the plan.
    machined = next(e for e in s["events"] if e["kind"] == "machined")
    assert machined["verdict"]["ok"] and machined["verdict"]["tilt_deg"] < 10
    packed = next(e for e in s["events"] if e["kind"] == "packed")
    assert packed["verdict"]["ok"], packed["verdict"]
    assert s["tact_time_s_mean"] > 20.0  # simulated seconds of a whole cycle
    assert "packed (judged)" in r.stdout
    # Where the tact goes: each leaf's time, summing to about the whole cycle.
    phases = {row["phase"]: row for row in s["phases"]}
    for leaf in ("grasp", "tilt", "feed slot", "wait machining", "pack in box"):
        assert phases[leaf]["runs"] >= 1 and phases[leaf]["per_part_s"] > 0, phases
    assert "ft sampler" not in phases
    total = sum(row["total_s"] for row in s["phases"])
    assert 0.8 * s["sim_time_s"] < total <= s["sim_time_s"] + 1e-6


def test_state_is_saved_and_the_log_replays_as_a_timeline(one_cycle) -> None:
    state = json.loads(one_cycle["state"].read_text())
    assert state["counts"]["packed"] == 1 and state["stop_reason"] is None
    assert state["filled"] == [0]  # the first box place
    lines = one_cycle["log"].read_text().splitlines()
    assert "header" in json.loads(lines[0])  # the tree's shape, for `cell replay --serve`
    first = json.loads(lines[1])
    assert {"tick", "t", "changed", "tip", "feedback"} <= set(first)
    assert any("wrench" in json.loads(x) for x in lines)
    r = subprocess.run(
        [sys.executable, "-m", "cell.cli", "replay", str(one_cycle["log"])],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    for words in (
        "start   perceive",
        "success tilt",
        "event   fed",
        "success pack in box",
        "end of log",
    ):
        assert words in r.stdout, words


def test_replay_of_a_broken_log_is_a_clear_error(tmp_path) -> None:
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"tick": 1}\nnot json\n')
    r = subprocess.run(
        [sys.executable, "-m", "cell.cli", "replay", str(bad)], capture_output=True, text=True
    )
    assert r.returncode == 2 and f"{bad}:2: not a JSON line" in r.stderr
    assert "Traceback" not in r.stderr


def test_sigterm_stops_the_arm_flushes_the_log_saves_the_state(tmp_path) -> None:
    long_run = CONFIG.replace("parts: 2", "parts: 6").replace("cycles: 1", "cycles: 6")
    cfg, log, state = _write_config(tmp_path, long_run)
    proc = subprocess.Popen(
        [sys.executable, "-m", "cell.cli", "sim", "--config", str(cfg), "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # wait until the tree runs (the log has lines)
        if log.exists() and log.stat().st_size > 0:
            break
        time.sleep(0.2)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err[-2000:]
    assert "interrupted: arm stopped" in err and "Traceback" not in err
    saved = json.loads(state.read_text())
    assert saved["tick"] > 0
    for line in log.read_text().splitlines():  # every line whole: the log was flushed
        json.loads(line)
    # The state file and the journal agree: the same run, stopped for the same reason.
    assert saved["stop_reason"] == "interrupted by SIGTERM"
    assert saved["stop_code"] == "interrupted"
    from cell.journal import Journal

    events = Journal(Path(f"{state}.sqlite")).events()
    stops = [e for e in events if e["kind"] == "stop"]
    assert saved["run"] == 1 and {e["run"] for e in events} == {1}
    assert stops and stops[-1]["code"] == "interrupted"
    # The message names the command that resumes it; that command resumes run 1 as run 2.
    hint = err.split("resume with: ", 1)[1].strip().splitlines()[0]
    assert hint == f"cell sim --config {cfg} --quiet --resume", hint
    words = shlex.split(hint)[1:] + ["--max-sim-time", "1"]
    r = subprocess.run(
        [sys.executable, "-m", "cell.cli", *words], capture_output=True, text=True, timeout=300
    )
    assert "Traceback" not in r.stderr, r.stderr
    assert f"run 2 resumes where run 1 of {state}.sqlite stopped" in r.stdout, r.stdout
    assert json.loads(state.read_text())["run"] == 2
