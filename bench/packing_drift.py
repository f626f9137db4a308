"""Benchmark: how far each step of the packing moves the part it packs and the parts already packed.

Run by hand:  python bench/packing_drift.py [--seeds 6] [--seed 0] [--parts 7] [--set KEY=VALUE]

Each seed builds the twin with bushings standing in the bin (each +-3 mm off its spot, any turn
about its axis, the seed's sensor noise), takes the hole grasp of each in turn and packs it into
the tray's next place with the configured ``skills.pack_in_box`` (``--config``, the shipped
example by default; ``--set`` changes one :class:`~skills.packing.PackParams` field, SI, e.g.
``--set release_follow=0.2``). Seven parts fill the first row of four and three places of the
second, so the second row is pushed against the first.

Printed, per step of :class:`~skills.packing.PackInBox`: the mean and the largest horizontal
move of the part being packed and of the parts packed before it, read from the twin at each
step's end. Then, as the twin's packing verdict of ``cell sim`` judges it: how far each packed
part but the last ended from where it stood after its own packing (its limit there is 2 mm), and
how well that is predicted by how far the part's own let go moved it (the next push closes that
gap).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the twin set-up the packing tests use (tests/skills/twin.py)

from cell.config import load_config, skill_settings  # noqa: E402
from skills.packing import PackInBox, PackParams  # noqa: E402
from skills.status import Status  # noqa: E402
from tests.skills.twin import GRIP_DEPTH, make_twin, take_hole_grasp  # noqa: E402

CONFIG = ROOT / "cell" / "data" / "bushing_cell.yaml"
#: Where the bushings stand in the bin (m): apart enough that each Grasp sees its part alone.
SPOTS = ((0.45, 0.08), (0.45, -0.08), (0.45, 0.0), (0.62, 0.08), (0.62, -0.08), (0.62, 0.0),
         (0.30, 0.08), (0.30, -0.08))
#: The steps after the part was pushed home: what they move it by is the let go's drift.
AFTER_PUSHES = ("relax the push", "let go", "off the wall", "withdraw up", "up clear")
#: The steps that carry the part to its place: it moves with the hand there, not in the box.
CARRIED = ("up to the travel height", "over the place")
#: s the twin runs idle after each packing before the parts are read (as ``cell sim``'s judge)
SETTLE_S = 0.3


def params(config: Path, sets: list[str]) -> PackParams:
    """The configured packing parameters with ``--set`` applied (SI field names)."""
    cfg, _ = load_config(config)
    base: PackParams = skill_settings(cfg)["pack_in_box"]
    changes: dict[str, float] = {"grip_depth": GRIP_DEPTH, "joint_speed": 0.0}
    fields = {f.name for f in dataclasses.fields(PackParams)}
    for item in sets:
        key, _, value = item.partition("=")
        if key not in fields:
            raise SystemExit(f"--set {item}: PackParams has no field {key!r}")
        changes[key] = float(value)
    return dataclasses.replace(base, **changes)


def pack_one(tw, place, p: PackParams, k: int):  # type: ignore[no-untyped-def]
    """Pack part ``k``; per step, the moves (m, (n, 2)) of parts 0..k; the failure or None."""
    skill = PackInBox(place, tw.part, tw.dev, p)

    def where() -> np.ndarray:
        return np.array([b.pose().position[:2] for b in tw.bodies[: k + 1]])

    moves: dict[str, np.ndarray] = {}
    step, start = skill.step, where()
    result = skill.tick()
    t_end = tw.world.clock.now() + 40.0
    while not result.done and tw.world.clock.now() < t_end:
        tw.world.step()
        result = skill.tick()
        if skill.step != step or result.done:
            now = where()
            moves[step] = moves.get(step, 0.0) + (now - start)
            step, start = skill.step, now
    if not result.done:
        skill.halt()
        return moves, "out of time"
    return moves, result.message if result.status is Status.FAILURE else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0, help="first seed")
    ap.add_argument("--parts", type=int, default=7, choices=range(1, len(SPOTS) + 1))
    ap.add_argument("--config", type=Path, default=CONFIG)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    p = params(args.config, args.set)
    own: dict[str, list[np.ndarray]] = {}
    others: dict[str, list[float]] = {}
    drift_then_moved: list[tuple[float, float]] = []
    ended: list[float] = []
    failures: list[str] = []
    for seed in range(args.seed, args.seed + args.seeds):
        tw = make_twin(seed, spots=SPOTS[: args.parts])
        try:
            places = tw.layout.packing_places()
            put: list[np.ndarray] = []  # where each part stood after its own packing
            drift: list[float] = []
            for k in range(args.parts):
                failure = take_hole_grasp(tw, SPOTS[k])
                if failure is not None:
                    failures.append(f"seed {seed} part {k}: grasp: {failure}")
                    break
                moves, failure = pack_one(tw, places[k], p, k)
                if failure is not None:
                    failures.append(f"seed {seed} part {k}: pack: {failure}")
                    break
                tw.settle(SETTLE_S)
                for name, d in moves.items():
                    own.setdefault(name, []).append(d[k])
                    others.setdefault(name, []).extend(np.linalg.norm(d[:k], axis=1))
                now = np.array([b.pose().position[:2] for b in tw.bodies[: k + 1]])
                if k > 0:
                    shoved = float(np.linalg.norm(now[k - 1] - put[k - 1]))
                    drift_then_moved.append((drift[-1], shoved))
                put.append(now[k].copy())
                drift.append(float(np.linalg.norm(sum(moves[s] for s in AFTER_PUSHES)[k])))
            else:
                now = np.array([b.pose().position[:2] for b in tw.bodies])
                ended.extend(np.linalg.norm(now - np.array(put), axis=1)[:-1])
        finally:
            tw.close()
    changed = ", ".join(args.set) or "none"
    print(f"seeds {args.seed}..{args.seed + args.seeds - 1}, {args.parts} packings each; --set: "
          f"{changed}")
    print(f"{'step':28s} {'packed part: mean (x, y) mm':>28s} {'max':>6s}   "
          f"{'parts before: mean mm':>21s} {'max':>6s}")
    for name, values in own.items():
        if name in CARRIED:
            continue
        v = 1e3 * np.array(values)
        o = 1e3 * np.array(others[name]) if others[name] else np.zeros(1)
        if np.abs(v).max() < 0.05 and o.max() < 0.05:
            continue
        print(f"{name:28s} {f'({v[:, 0].mean():+.2f}, {v[:, 1].mean():+.2f})':>28s} "
              f"{np.linalg.norm(v, axis=1).max():6.2f}   {o.mean():21.2f} {o.max():6.2f}")
    if drift_then_moved:
        d, m = (1e3 * np.array(x) for x in zip(*drift_then_moved, strict=True))
        print(f"let go's drift of a part: median {statistics.median(d):.2f} mm, max {d.max():.2f}; "
              f"the next packing moved it: median {statistics.median(m):.2f} mm, max {m.max():.2f} "
              f"(correlation {np.corrcoef(d, m)[0, 1]:.2f})")
    if ended:
        e = 1e3 * np.array(ended)
        print(f"at the end, each packed part from where its own packing left it: median "
              f"{statistics.median(e):.2f} mm, max {e.max():.2f} mm ({len(e)} parts)")
    for line in failures:
        print("FAILED", line)


if __name__ == "__main__":
    main()
