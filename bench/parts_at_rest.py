"""Twin check: how many of a part's trial worlds leave it rolling off by itself, untouched.

Run by hand:  python bench/parts_at_rest.py --part cookie_can --trials 30 --seed 66000

Builds each trial's own world exactly as `cell pivot` does (the drawn tolerances, floor height,
frictions and pose), steps it ``--seconds`` with nothing touching the part and counts the
trials whose part moved more than ``--moved-mm`` across its axis. A real round part left lying
on a level bin floor stays there; every count above 0 is the twin's artifact, and a trial whose
part rolls before the look or during the Grasp fails for it (docs/pivot_in_hand.md).
"""

from __future__ import annotations

import argparse

from lab.pivot_cmd import build_setup, pivot_args
from lab.pivot_run import open_trial_world


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", required=True)
    ap.add_argument("--trials", type=int, default=30)
    ap.add_argument("--seed", type=int, default=66000)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--moved-mm", type=float, default=2.0)
    args = ap.parse_args()
    setup, _, _ = build_setup(pivot_args(args.part, args.trials, None, None, False))
    rolled: list[tuple[int, float]] = []
    for seed in range(args.seed, args.seed + args.trials):
        tw = open_trial_world(setup, seed)
        try:
            start = tw.body.pose().position.copy()
            for _ in range(int(args.seconds / tw.world.settings.control_dt)):
                tw.world.step()
            axis = tw.body.axis()
            shift = tw.body.pose().position - start
            across = shift[:2] - (shift[:2] @ axis[:2]) * axis[:2]  # the roll's direction
            moved = 1e3 * float((across @ across) ** 0.5)
            if moved > args.moved_mm:
                rolled.append((seed, round(moved, 1)))
        finally:
            tw.world.close()
    print(f"{args.part}: {len(rolled)} of {args.trials} trial worlds rolled the part more than "
          f"{args.moved_mm:g} mm in {args.seconds:g} s untouched: {rolled}")


if __name__ == "__main__":
    main()
