"""`cell emulate` end to end: the shipped emulated cell (its arm host moved to a loopback alias
of this test's own) prints `ready`, the real UR5 driver's start-up check passes against it, and
SIGTERM ends it with exit 0 and the twin's report."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("rtde_control")

from lab.emulate_cmd import EXAMPLE  # noqa: E402
from sim.emulate.camera_process import CAMERA_NICENESS  # noqa: E402
from tests.cell.emulated import emulated_config  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def test_emulate_serves_the_arm_and_reports_on_sigterm(tmp_path: Path) -> None:
    config = emulated_config(tmp_path)
    host = config.read_text().split("host: ", 1)[1].split()[0]
    report = tmp_path / "report.json"
    trace = tmp_path / "trace.csv"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "cell.cli", "emulate", "--config", str(config), "--report",
         str(report), "--trace", str(trace)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
    )
    try:
        line = proc.stdout.readline() if proc.stdout else ""
        assert line.strip() == "ready", proc.stderr.read() if proc.stderr else ""
        from drivers.ur5.arm import UR5Arm

        arm = UR5Arm.connect(host)
        result = arm.check()
        arm.close()
        assert result.ok, result.message
        assert result.details["control_script"] == "running"
        assert result.details["controller_version"].startswith("URSoftware 3.15")
        # The camera's renderer (forked: its command line is the emulator's) yields to the
        # twin; the FT300 streams from a spawned process of its own (with multiprocessing's
        # resource tracker beside it).
        children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()
        lines = {c: Path(f"/proc/{c}/cmdline").read_bytes() for c in children}
        forked = [c for c, line in lines.items() if b"emulate" in line]
        spawned = [c for c, line in lines.items() if b"multiprocessing" in line]
        assert len(forked) == 1 and len(spawned) >= 1 and len(children) <= 3
        # CAMERA_NICENESS below the value the emulator started with (this test's), which its
        # main thread keeps (only the stepping thread is raised).
        renderer = os.getpriority(os.PRIO_PROCESS, int(forked[0]))
        assert renderer == os.getpriority(os.PRIO_PROCESS, 0) + CAMERA_NICENESS
        assert renderer > os.getpriority(os.PRIO_PROCESS, proc.pid)
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            rc = proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    assert rc == 0
    data = json.loads(report.read_text())
    assert {"cycles", "fed", "packed", "parts"} <= set(data)
    assert data["packed"] == 0 and len(data["parts"]) == 10
    assert all(p["where"] == "in_bin" for p in data["parts"])
    # The trace: one row a step of the twin, its own clock at the control period, the tool
    # hanging at rest (its weight on the sensor, about 12 N) with the jaws as they are.
    lines = trace.read_text().splitlines()
    header = lines[0].split(",")
    rows = [dict(zip(header, line.split(","), strict=True)) for line in lines[1:]]
    assert header[:3] == ["wall_s", "twin_s", "fx_n"] and len(rows) > 50
    twin = [float(r["twin_s"]) for r in rows]
    steps = {round(b - a, 4) for a, b in zip(twin, twin[1:], strict=False)}
    assert steps == {0.008}
    last = rows[-1]
    weight = sum(float(last[k]) ** 2 for k in ("fx_n", "fy_n", "fz_n")) ** 0.5
    assert 5.0 < weight < 30.0 and 0.0 <= float(last["opening_m"]) <= 0.086
    assert last["mode"] in ("hold", "path", "joints", "servo", "force")


def test_print_config_names_the_shipped_example() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "cell.cli", "emulate", "--print-config"],
        capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
        check=True,
    ).stdout.strip()
    assert Path(out) == EXAMPLE and EXAMPLE.is_file()


def test_the_fault_schedule_counts_from_the_first_motion_and_waits_for_motion() -> None:
    from cell.config import EmulatedFault
    from lab.emulate_cmd import _Schedule

    pull = EmulatedFault(device="arm", at_s=1.0, duration_s=0.5)
    ft = EmulatedFault(device="ft", at_s=0.2, mid_motion=False)
    s = _Schedule([pull, ft])
    s.check(5.0, moving=False)  # the arm never moved yet: nothing counts
    assert s.take() == [] and s.first_motion is None
    s.check(10.0, moving=True)
    s.check(10.3, moving=False)  # ft: due without motion
    assert s.take() == [(ft, "pull")]
    s.check(11.2, moving=False)  # arm: due, but waits for motion
    assert s.take() == []
    s.check(11.4, moving=True)
    assert s.take() == [(pull, "pull")]
    s.check(11.8, moving=True)
    assert s.take() == []
    s.check(11.9, moving=False)  # 0.5 s after the pull: plugged back, once
    s.check(20.0, moving=True)
    assert s.take() == [(pull, "plug")]


@pytest.mark.parametrize(("fault", "reason"), [
    ("{device: ft, fault: protective_stop, at_s: 1}", "protective stop is the arm's"),
    ("{device: arm, fault: force_step, at_s: 1}", "force step is on the wrist sensor"),
])
def test_a_fault_on_a_device_that_has_no_such_fault_is_refused(
    tmp_path: Path, fault: str, reason: str
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"emulate:\n  faults:\n    - {fault}\n")
    r = subprocess.run([sys.executable, "-m", "cell.cli", "emulate", "--config", str(bad)],
                       capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "emulate.faults" in r.stderr and reason in r.stderr


def test_a_force_step_lasts_its_default_and_is_timed_to_the_first_stop_after_it() -> None:
    from cell.config import EmulatedFault
    from lab.emulate_cmd import FORCE_STEP_S, _Schedule, step_latency

    step = EmulatedFault(device="ft", fault="force_step", at_s=0.0)
    s = _Schedule([step])
    s.check(1.0, moving=True)
    assert s.take() == [(step, "pull")]
    s.check(1.0 + FORCE_STEP_S - 0.01, moving=True)
    assert s.take() == []
    s.check(1.0 + FORCE_STEP_S, moving=False)
    assert s.take() == [(step, "plug")]
    # Steps that fall due together (the arm stood still past their times) take turns.
    a, b = (EmulatedFault(device="ft", fault="force_step", at_s=t) for t in (1.0, 2.0))
    s = _Schedule([a, b])
    s.check(0.0, moving=True)
    s.check(5.0, moving=True)
    assert s.take() == [(a, "pull")]
    s.check(5.0 + FORCE_STEP_S - 0.01, moving=True)
    assert s.take() == []  # b waits while a lasts
    s.check(5.0 + FORCE_STEP_S, moving=True)
    assert s.take() == [(a, "plug"), (b, "pull")]
    # A stop before the step is not its stop; none within the step's time is a miss.
    assert step_latency(100.0, [99.0, 100.012, 100.2], 0.5) == 12.0
    assert step_latency(100.0, [99.0], 0.5) is None
    assert step_latency(100.0, [100.7], 0.5) is None
    assert step_latency(None, [100.1], 0.5) is None
