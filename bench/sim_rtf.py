"""Benchmark: real-time factor of the twin during a pivot, and the wall time of one pivot.

Run by hand:  python bench/sim_rtf.py [--part bushing] [--trials 5] [--seed 0]

Runs whole trials as ``cell pivot`` does and splits each one's wall time into: setting the
world up (URDF, cell, part, settling), stepping the physics with the skills ticking (the pivot
itself, camera off), and rendering the one wrist-camera frame Align takes. Prints the real-time
factor (simulated seconds per wall second) of the stepping alone -- the target is >= 20x
-- and of the whole trial, and the wall time of one pivot. Numbers are for this machine only.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import sim.camera
import sim.world
from cell.catalogue import load_catalogue
from lab.pivot_run import TrialSetup, run_trial
from skills.mechanics.planner import plan_pivot


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="bushing")
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    timers = {"step": 0.0, "camera": 0.0}
    real_step = sim.world.SimWorld.step
    real_capture = sim.camera.SimCamera.capture

    def timed_step(self):  # type: ignore[no-untyped-def]
        t0 = time.perf_counter()
        try:
            return real_step(self)
        finally:
            timers["step"] += time.perf_counter() - t0

    def timed_capture(self):  # type: ignore[no-untyped-def]
        t0 = time.perf_counter()
        try:
            return real_capture(self)
        finally:
            timers["camera"] += time.perf_counter() - t0

    sim.world.SimWorld.step = timed_step  # type: ignore[method-assign]
    sim.camera.SimCamera.capture = timed_capture  # type: ignore[method-assign]

    part = load_catalogue().get(args.part)
    # The nominal pose: the Look skill's two rendered frames are perception, timed by
    # bench/perception.py.
    setup = TrialSetup(part=part, plan=plan_pivot(part), perceive=False)
    rows = []
    for i in range(args.trials):
        timers.update(step=0.0, camera=0.0)
        r = run_trial(setup, args.seed + i)
        rows.append((r, timers["step"], timers["camera"]))
        print(
            f"trial {args.seed + i}: {'ok  ' if r.success else 'FAIL'} sim {r.sim_time:5.1f} s  "
            f"wall {r.wall_time:5.2f} s  (stepping {timers['step']:5.2f} s, camera "
            f"{timers['camera'] * 1e3:4.0f} ms)"
        )
    sim_t = sum(r.sim_time for r, _, _ in rows)
    step_t = sum(s for _, s, _ in rows)
    cam_t = sum(c for _, _, c in rows)
    wall_t = sum(r.wall_time for r, _, _ in rows)
    s = setup.physics
    print()
    print(f"machine      {platform.processor() or platform.machine()}, {os.cpu_count()} cores")
    print(
        f"physics      {s.control_hz:g} Hz control, {s.substeps} substeps "
        f"({1.0 / s.physics_dt:g} Hz), {s.solver_iterations} solver iterations, residual "
        f"{s.solver_residual:g}"
    )
    print(f"pivot RTF    {sim_t / step_t:5.1f}x real time (stepping with the skills, camera off)")
    print(f"trial RTF    {sim_t / wall_t:5.1f}x real time (whole trial: set-up, pivot, camera)")
    print(
        f"one pivot    {statistics.median(r.wall_time for r, _, _ in rows):.2f} s wall (median),"
        f" {statistics.median(r.sim_time for r, _, _ in rows):.1f} s simulated; camera frame "
        f"{1e3 * cam_t / len(rows):.0f} ms; set-up {(wall_t - step_t - cam_t) / len(rows):.2f} s"
    )


if __name__ == "__main__":
    main()
