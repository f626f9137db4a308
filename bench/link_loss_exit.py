"""How long a process takes to end after the UR's RTDE cable is pulled.

Each repeat runs a child process that connects the UR5 driver through the real ur_rtde to the UR
controller emulator (``sim/emulate/ur_standalone.py``), polls it as the tick loop does, pulls
the cable, waits for the driver's FAULT, closes the arm and ends the process. Two ways of
ending are timed, from the pull (the child's wall clock) to the parent seeing the child gone:

* ``abandon``: what ``cell run`` does -- ``UR5Arm.close()`` abandons the dead link and
  ``cell.cli.end_process`` ends the process without ur_rtde's destructors;
* ``disconnect``: ur_rtde's ``disconnect()`` on the dead link, then a normal interpreter exit
  (what ``cell run`` did before).

    python bench/link_loss_exit.py [--repeats 5] [--json F]

Target: the process ends within 0.5 s of the loss.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path


def child(mode: str) -> None:
    """One pull, in this process: the timing line on stdout, then the end ``mode`` names."""
    from cell.cli import end_process
    from drivers.arm import MotionState
    from drivers.ur5.arm import UR5Arm, UR5Settings
    from sim.emulate.ur_standalone import URAloneProcess

    emu = URAloneProcess(script_start_delay=0.15).start()
    arm = UR5Arm.connect(emu.host, settings=UR5Settings(watchdog_hz=5.0))
    arm.start_watchdog()  # as cell run does once its ticks start
    for _ in range(25):  # polled as the tick loop does
        arm.status()
        time.sleep(0.008)
    pulled = time.time()
    emu.pull_cable()
    while arm.status().state is not MotionState.FAULT:
        time.sleep(0.008)
    faulted = time.time()
    if mode == "abandon":
        arm.close()
    else:
        arm.stop()
        arm._rtde.disconnect()  # noqa: SLF001 -- the earlier shutdown, reproduced
    closed = time.time()
    print(f"PULLED {pulled:.6f} FAULTED {faulted:.6f} CLOSED {closed:.6f}", flush=True)
    emu.stop()
    if mode == "abandon":
        end_process(1)
    sys.exit(1)


def once(mode: str) -> dict[str, float]:
    proc = subprocess.run([sys.executable, __file__, "--child", mode], capture_output=True,
                          text=True, timeout=60, cwd=Path(__file__).resolve().parents[1])
    ended = time.time()
    line = next((x for x in proc.stdout.splitlines() if x.startswith("PULLED")), None)
    if line is None:
        raise RuntimeError(f"{mode}: no timing line (exit {proc.returncode}): {proc.stderr[-500:]}")
    f = line.split()
    pulled, faulted, closed = float(f[1]), float(f[3]), float(f[5])
    return {"rc": proc.returncode, "fault_s": faulted - pulled, "close_s": closed - faulted,
            "exit_s": ended - pulled}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--child", choices=("abandon", "disconnect"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        child(args.child)
    out: dict[str, object] = {}
    for mode in ("abandon", "disconnect"):
        runs = [once(mode) for _ in range(args.repeats)]
        exits = [r["exit_s"] for r in runs]
        out[mode] = {"runs": runs, "exit_median_s": statistics.median(exits),
                     "exit_max_s": max(exits)}
        print(f"{mode:10s} exit codes {sorted({r['rc'] for r in runs})}; "
              f"fault after the pull median {statistics.median(r['fault_s'] for r in runs)*1e3:.0f}"
              f" ms; close median {statistics.median(r['close_s'] for r in runs)*1e3:.0f} ms; "
              f"process gone after the pull: median {statistics.median(exits)*1e3:.0f} ms, "
              f"max {max(exits)*1e3:.0f} ms")
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=2))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
