"""How soon a force over a motion's limit stops the arm, whatever the tick is doing.

The real drivers of the cell's process -- the UR5 through ``ur_rtde``, the FT300 through its
serial protocol -- against the emulated devices: the UR controller emulator in its own process
(``sim/emulate/ur_standalone.py``, real time, the twin's arm) and the FT300 emulator streaming at
100 Hz over a serial device server's TCP port (``sim/emulate/ft300_stream.py``). Each injection
starts a guarded ``moveL`` (``skills.motion.arm_motion`` under the shipped 80 N / 8 N*m limits),
then steps the wrist force to 100 N at a random moment 0.15-0.6 s into it. Every other injection
lands inside a long tick: the tick thread is busy in Python for 1.3 s (the longest tick measured
on the emulated cell) and never reads the wrench meanwhile. The interpreter's thread switch
interval is the one ``cell run`` sets on hardware (``cell.hardware.SWITCH_INTERVAL_S``).

Latency: from the first stream sample over the limit leaving the FT300 emulator to the stop
command reaching the emulated controller: the kernel's receive time of the RTDE message that
carried it (SO_TIMESTAMPNS), both on ``time.monotonic()`` (one clock for every process of the
machine, the one the emulator's real-time loop runs on). ``taken`` is the same to the
emulator's cycle that acted on it: that adds the wait for the next 8 ms cycle and for the
emulator's server thread, which shares Python's interpreter lock with the physics (a real
controller takes its inputs every 2 ms). The stop comes from the cell's process (the FT300
driver's reader thread, :mod:`drivers.limit_guard`); nothing inside the emulators stops the
arm.

    python bench/guard_latency.py [--injections 60] [--seed 0] [--json F]

``--cell`` times the same on the whole emulated cell instead: `cell emulate` with the shipped
emulated configuration serves every device, ``emulate.faults`` holds ``--injections`` force
steps (``force_step``: 300 N on the sensor's +z for 0.3 s, over every limit of the tree, each
at the first moment the arm moves ``--spacing`` s of the controller's time after the one
before), and `cell run` runs the
cell's own tree through the real drivers until every step has fired (runs that end early are
resumed with ``--resume``). The steps land wherever the cell is: in free moves, force-controlled
pushes, the pivot. Latency as above, taken by the emulator (its report's ``faults``).

    python bench/guard_latency.py --cell [--injections 50] [--spacing 4] [--json F]

Target: p99 at most 20 ms, none over 30 ms.
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

LIMIT_N, LIMIT_NM = 80.0, 8.0  #: the shipped safety limits (cell/defaults: safety section)
STEP_N = 100.0
WEIGHT = np.array([0.0, 0.0, -12.5, 0.0, 0.0, 0.0])  #: the tool's load at rest
BUSY_S = 1.3
#: --cell: over every limit of the shipped tree (its highest: 250 N, putting a part back), within
#: the FT300's +-300 N range (its counts saturate at 327.67 N)
STEP_CELL_N = 300.0


class StepWrist:
    """The FT300 emulator's load: the tool's weight, plus a force step when injected. Records
    when the first sample with the step was taken for the stream (the stream thread)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.step = False
        self.first_over: float | None = None

    def inject(self) -> None:
        with self._lock:
            self.step, self.first_over = True, None

    def clear(self) -> None:
        with self._lock:
            self.step = False

    def wrench(self) -> NDArray[np.float64]:
        with self._lock:
            if not self.step:
                return WEIGHT.copy()
            if self.first_over is None:
                self.first_over = time.monotonic()
            return WEIGHT + np.array([0.0, 0.0, STEP_N, 0.0, 0.0, 0.0])


def busy(seconds: float) -> None:
    """A tick that plans: pure Python for ``seconds``, holding the GIL as the planner's sweeps
    do between their numpy calls."""
    end = time.monotonic() + seconds
    x = 0
    while time.monotonic() < end:
        for i in range(2000):
            x += i * i
    del x


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if values else float("nan")


def summary(values: list[float]) -> dict[str, float | int]:
    return {
        "n": len(values),
        "median_ms": round(statistics.median(values), 2) if values else float("nan"),
        "p99_ms": round(percentile(values, 99), 2),
        "max_ms": round(max(values), 2) if values else float("nan"),
    }


def run(injections: int, seed: int) -> dict[str, object]:
    from cell.hardware import SWITCH_INTERVAL_S
    from drivers.arm import MotionState
    from drivers.clock import WallClock
    from drivers.ft300 import FT300
    from drivers.pose import Pose
    from drivers.ur5.arm import UR5Arm, UR5Settings
    from sim.emulate.ft300_stream import FT300Emulator
    from sim.emulate.ur_standalone import URAloneProcess
    from skills.motion import Guard, arm_motion
    from skills.status import Failure, Status

    sys.setswitchinterval(SWITCH_INTERVAL_S)  # as cell run does on hardware
    rng = random.Random(seed)
    wrist = StepWrist()
    emu = URAloneProcess().start()
    fte = FT300Emulator(wrist, listen=("127.0.0.1", 0), seed=seed).start()
    arm = UR5Arm.connect(emu.host, settings=UR5Settings())
    ft = FT300(fte.port, stale_after=0.2)
    latencies: dict[str, list[float]] = {"quiet": [], "in a long tick": []}
    missed: list[str] = []
    try:
        ft.start()
        time.sleep(0.3)
        ft.bias()
        ft.limits.connect_stop(arm.stop)  # as cell/hardware.py connects them
        clock = WallClock()
        home = arm.tool_pose()
        for k in range(injections):
            kind = "in a long tick" if k % 2 else "quiet"
            goal = Pose(home.position + np.array([0.0, 0.08 if k % 4 < 2 else -0.08, 0.0]),
                        home.rotation)
            motion = arm_motion("moveL", arm, ft, clock, Guard(LIMIT_N, LIMIT_NM, 10.0),
                                lambda g=goal: arm.move_to(g, 0.05, 0.5))
            stops_before = len(emu.stop_arrivals())
            delay = rng.uniform(0.15, 0.6)
            result = motion.tick()  # starts the move, arms the limits
            timer = threading.Timer(delay, wrist.inject)
            timer.start()
            if kind == "in a long tick":
                busy(BUSY_S)
            deadline = time.monotonic() + delay + 2.0
            while result.status is Status.RUNNING and time.monotonic() < deadline:
                time.sleep(0.008)
                result = motion.tick()
            timer.join()
            stop_times = emu.stop_arrivals()[stops_before:]
            first = wrist.first_over
            wrist.clear()
            if result.code is not Failure.FORCE_TORQUE or first is None or not stop_times:
                missed.append(f"{k}: {result.status.name} {result.message}")
            else:
                after = [t for t in stop_times if t >= first]
                if after:
                    latencies[kind].append(1000.0 * (after[0] - first))
                else:
                    missed.append(f"{k}: no stop after the step's first sample")
            # Let the stop end and the reading fall back before the next one.
            t_end = time.monotonic() + 1.0
            while arm.status().state is MotionState.MOVING and time.monotonic() < t_end:
                time.sleep(0.008)
            time.sleep(0.1)
            back = arm_motion("back", arm, ft, clock, Guard(LIMIT_N, LIMIT_NM, 10.0),
                              lambda: arm.move_to(home, 0.1, 0.5))
            r = back.tick()
            while r.status is Status.RUNNING:
                time.sleep(0.008)
                r = back.tick()
    finally:
        ft.stop()
        arm.close()
        fte.close()
        emu.stop()
    every = latencies["quiet"] + latencies["in a long tick"]
    out: dict[str, object] = dict(summary(every))
    out["by_kind"] = {kind: summary(v) for kind, v in latencies.items()}
    out["missed"] = missed
    out["limit_n"], out["step_n"], out["busy_tick_s"] = LIMIT_N, STEP_N, BUSY_S
    return out


def cell_config(directory: Path, injections: int, spacing: float, watchdog_hz: float | None,
                first_at: float = 3.0) -> Path:
    """The shipped emulated cell with its tree path made absolute and ``injections`` force
    steps scheduled; written to ``directory``."""
    from lab.emulate_cmd import EXAMPLE

    config = yaml.safe_load(EXAMPLE.read_text())
    config["tree"]["file"] = str(EXAMPLE.parent / config["tree"]["file"])
    config["log"] = {k: str(directory / Path(v).name) for k, v in config["log"].items()}
    config["log"]["journal"] = str(directory / "journal.sqlite")
    config["devices"]["gripper"]["port"] = str(directory / "gripper")
    if watchdog_hz is not None:
        config["devices"]["arm"]["watchdog_hz"] = watchdog_hz
    config["emulate"]["faults"] = [
        {"device": "ft", "fault": "force_step", "force_n": STEP_CELL_N, "duration_s": 0.3,
         "at_s": round(first_at + k * spacing, 3), "mid_motion": True}
        for k in range(injections)
    ]
    path = directory / "cell.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def run_cell(injections: int, spacing: float, watchdog_hz: float | None,
             keep: Path | None = None, max_runs: int = 6) -> dict[str, object]:
    """The force steps on the whole emulated cell (see the module doc)."""
    cell = shutil.which("cell") or "cell"
    with tempfile.TemporaryDirectory(prefix="guard-latency-") as tmp:
        work = keep if keep is not None else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        config = cell_config(work, injections, spacing, watchdog_hz)
        report = work / "report.json"
        emu_out = (work / "emulate.out").open("w")
        emu = subprocess.Popen([cell, "emulate", "--config", str(config), "--report",
                                str(report)], stdout=emu_out, stderr=subprocess.STDOUT,
                               cwd=work)
        runs: list[dict[str, object]] = []
        try:
            deadline = time.monotonic() + 120.0
            while "ready" not in (work / "emulate.out").read_text():
                if emu.poll() is not None or time.monotonic() > deadline:
                    raise SystemExit("cell emulate did not start:\n"
                                     + (work / "emulate.out").read_text())
                time.sleep(0.5)
            for k in range(max_runs):
                # Cycles enough for every step; a run that ends early (a cycle failed) resumes.
                cmd = [cell, "run", "--config", str(config), "--cycles", "10",
                       "--json", str(work / f"run{k}.json")] + (["--resume"] if k else [])
                proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL,
                                        stderr=(work / f"run{k}.err").open("w"), cwd=work)
                while proc.poll() is None:
                    time.sleep(1.0)
                    fired = _steps(report)
                    if len(fired) >= injections:
                        proc.terminate()  # SIGTERM: the run stops and writes its JSON
                        proc.wait(timeout=30)
                tail = (work / f"run{k}.err").read_text().splitlines()[-3:]
                runs.append({"rc": proc.returncode, "tail": tail})
                if len(_steps(report)) >= injections:
                    break
        finally:
            emu.terminate()
            emu.wait(timeout=30)
            emu_out.close()
        steps = _steps(report)
        data = json.loads(report.read_text())
    latencies = [float(f["latency_ms"]) for f in steps if f.get("latency_ms") is not None]
    out: dict[str, object] = dict(summary(latencies))
    out["injections"] = len(steps)
    pulls = [f for f in data.get("faults", [])
             if f.get("fault") == "force_step" and f.get("what") == "pull"]
    out["missed"] = [f"step at {f['t_s']} s: no stop within its 0.3 s" for f in steps
                     if f.get("latency_ms") is None]
    modes: dict[str, list[float]] = {}
    for p, f in zip(pulls, steps, strict=False):
        if f.get("latency_ms") is not None:
            modes.setdefault(str(p.get("arm_mode")), []).append(float(f["latency_ms"]))
    out["by_arm_mode"] = {m: summary(v) for m, v in sorted(modes.items())}
    # To the cycle that acted on the stop: the emulator's own wait added (see the module doc).
    out["taken"] = summary([float(f["taken_ms"]) for f in steps
                            if f.get("taken_ms") is not None])
    out["arm_at_rest"] = sum(bool(f.get("arm_at_rest")) for f in steps)
    out["each"] = [{"t_s": f.get("t_s"), "arm_mode": p.get("arm_mode"),
                    "latency_ms": f.get("latency_ms"), "taken_ms": f.get("taken_ms"),
                    "arm_at_rest": f.get("arm_at_rest")}
                   for p, f in zip(pulls, steps, strict=False)]
    out["runs"] = runs
    out["cell"] = {"cycles": data.get("cycles"), "realtime": data.get("realtime")}
    out["limit"] = "the running motion's (shipped configuration)"
    out["step_n"] = STEP_CELL_N
    return out


def _steps(report: Path) -> list[dict[str, object]]:
    """The force steps the emulator has taken away again (each with its latency)."""
    try:
        data = json.loads(report.read_text())
    except (OSError, ValueError):
        return []
    return [f for f in data.get("faults", [])
            if f.get("fault") == "force_step" and f.get("what") == "plug"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--injections", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--cell", action="store_true",
                    help="on the whole emulated cell (cell emulate + cell run)")
    ap.add_argument("--spacing", type=float, default=4.0,
                    help="--cell: s of the controller's time between two force steps")
    ap.add_argument("--watchdog-hz", type=float, default=None,
                    help="--cell: devices.arm.watchdog_hz (default: the shipped one)")
    ap.add_argument("--keep", type=Path, default=None,
                    help="--cell: run in this folder and keep it (configuration, reports, logs)")
    args = ap.parse_args()
    if args.cell:
        out = run_cell(args.injections, args.spacing, args.watchdog_hz, args.keep)
    else:
        out = run(args.injections, args.seed)
    print(json.dumps(out, indent=2))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
