"""Benchmark: how far below its abort limit packing's contact pushes stay, over many seeds.

Run by hand:  python bench/packing_margin.py [--seeds 10] [--seed 0]

Each seed builds the twin with two bushings standing in the bin (each +-3 mm off its spot, any
turn about its axis, the seed's sensor noise), takes the hole grasp of each and packs them into
the tray's first two places, the second pushed against the first. For every guarded contact
move of PackInBox it records the peak wrist force and prints, per move, the worst peak over all
seeds against the push guard and against the tree's packing limit (the shipped tree's
``pack_in_box`` node, ``max_force_n``). A cell whose outcome hangs on floating-point differences
between machines pushes close to a limit; this shows the margin.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the twin set-up the packing tests use (tests/skills/twin.py)

from skills.packing import PackInBox, PackParams  # noqa: E402
from tests.skills.twin import BIN_SPOTS, make_twin, take_hole_grasp  # noqa: E402

TREE = ROOT / "cell" / "data" / "trees" / "bushing_machining.yaml"


def tree_limit() -> float:
    """``max_force_n`` of the shipped tree's ``pack_in_box`` node (N)."""

    def walk(node: object) -> float | None:
        if isinstance(node, dict):
            if node.get("type") == "pack_in_box":
                return float(node["max_force_n"])
            for value in node.values():
                found = walk(value)
                if found is not None:
                    return found
        elif isinstance(node, list):
            for value in node:
                found = walk(value)
                if found is not None:
                    return found
        return None

    found = walk(yaml.safe_load(TREE.read_text()))
    if found is None:
        raise SystemExit(f"{TREE}: no pack_in_box node with max_force_n")
    return found


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0, help="first seed")
    args = ap.parse_args()
    peaks: dict[str, list[float]] = {}
    failures: list[str] = []
    for seed in range(args.seed, args.seed + args.seeds):
        tw = make_twin(seed, spots=BIN_SPOTS)
        try:
            places = tw.layout.packing_places()
            for i in range(2):
                failure = take_hole_grasp(tw, BIN_SPOTS[i])
                if failure is not None:
                    failures.append(f"seed {seed} part {i + 1}: grasp: {failure}")
                    break
                pack = PackInBox(places[i], tw.part, tw.dev)
                failure = tw.run(pack, 40.0)
                for step in pack.sequence.steps:
                    peak = getattr(step, "peak_force", None)
                    if peak is not None and peak > 0.0:
                        peaks.setdefault(step.name, []).append(float(peak))
                if failure is not None:
                    failures.append(f"seed {seed} part {i + 1}: pack: {failure}")
                    break
                tw.settle(0.3)
        finally:
            tw.close()
    guard, limit = PackParams().push_guard.max_force, tree_limit()
    print(f"seeds {args.seed}..{args.seed + args.seeds - 1}, two packings each")
    print(f"{'move':28s} {'n':>3s} {'median N':>9s} {'max N':>7s}  margin to guard "
          f"{guard:g} N / tree {limit:g} N")
    for name, values in peaks.items():
        worst = max(values)
        print(f"{name:28s} {len(values):3d} {statistics.median(values):9.1f} {worst:7.1f}  "
              f"{guard - worst:6.1f} N / {limit - worst:6.1f} N")
    for line in failures:
        print("FAILED", line)


if __name__ == "__main__":
    main()
