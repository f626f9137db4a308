"""Benchmark: one stable-grasp map by per-point LP (HiGHS) and by the exact vectorized test.

Run by hand:  python bench/grasp_map.py [--grid 181] [--la 0.9] [--repeat 5]
Prints both times, the ratio and the number of grid points where the two disagree.
Targets: vectorized >= 1000x faster, < 0.3 s per 181x181 map, 0 disagreements.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from drivers.parts import Section, delta_round
from skills.mechanics.balance import form_closure_lp, gravity_balance_lp
from skills.mechanics.cone import eq7_feasible, eq8_feasible
from skills.mechanics.contact import Frictions, contact_wrenches
from skills.mechanics.region import alpha_axis, beta_axis


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=181)
    parser.add_argument("--la", type=float, default=0.9)
    parser.add_argument("--repeat", type=int, default=5, help="repeats of the vectorized map")
    parser.add_argument(
        "--mu", type=float, nargs=3, default=(0.2, 0.4, 0.4), metavar=("S", "H", "G")
    )
    parser.add_argument("--equation", choices=("eq7", "eq8"), default="eq8")
    args = parser.parse_args()

    section = Section(0.034, 0.017, delta_round(0.034, 0.028, 0.020))  # the bushing
    fr = Frictions(*args.mu)
    al, be = alpha_axis(args.grid), beta_axis(args.grid)
    fast_fn, lp_fn = (
        (eq8_feasible, gravity_balance_lp)
        if args.equation == "eq8"
        else (eq7_feasible, form_closure_lp)
    )

    def vectorized() -> np.ndarray:
        w = contact_wrenches(section, args.la, al[:, None], be[None, :], fr, normalized=True)
        return fast_fn(w)

    vectorized()  # warm-up
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        fast = vectorized()
        times.append(time.perf_counter() - t0)
    t_fast = min(times)

    t0 = time.perf_counter()
    w = contact_wrenches(section, args.la, al[:, None], be[None, :], fr, normalized=True)
    slow = np.zeros(fast.shape, dtype=bool)
    for idx in np.ndindex(slow.shape):
        slow[idx] = lp_fn(w[idx]).feasible
    t_lp = time.perf_counter() - t0

    n = fast.size
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpu(s)")
    print(
        f"map: bushing, l_a={args.la}, mu={tuple(args.mu)}, {args.equation}, "
        f"{args.grid}x{args.grid} = {n} points, {int(fast.sum())} stable"
    )
    print(f"LP (HiGHS, one per point): {t_lp:8.3f} s  ({t_lp / n * 1e3:.3f} ms/point)")
    print(
        f"vectorized cone test:      {t_fast:8.4f} s  (best of {args.repeat}; "
        f"median {np.median(times):.4f} s)"
    )
    print(f"ratio LP / vectorized:     {t_lp / t_fast:8.0f}x")
    print(f"disagreements:             {int((fast != slow).sum())}")


if __name__ == "__main__":
    main()
