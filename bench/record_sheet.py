"""A contact sheet of a `cell sim --record` GIF: one frame per named step of the run, tiled, for
docs/ (the first cycle's picture in docs/figures.md).

    python bench/record_sheet.py out/cell.gif --log out/cell_ticks.jsonl \\
        --at "perceive:0.5" "tilt:0.5" "align:0.95" "feed slot:0.15" "feed slot:0.85" \\
        "pick from slot:0.8" "via home:0.5" "pack in box:0.6" --out docs/cell_first_cycle.png

Why steps and not frame numbers: the frames are picked from the tick log by the step the tree
was running (its tip), so the sheet shows the same moments after the run's timing changes.
Each ``STEP:FRACTION`` is the first span of that step at or after the previous pick, at that
fraction of its length; `cell sim` captures a frame every ``--every`` ticks, from tick
``--every`` on.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from PIL import Image, ImageSequence


def spans(log: Path) -> list[tuple[str, int, int]]:
    """(step, first tick, last tick) for each stretch of ticks with the same tip, in order."""
    out: list[tuple[str, int, int]] = []
    with log.open(encoding="utf-8") as f:
        for line in f:
            d = json.loads(line)
            if "header" in d or "tick" not in d:
                continue
            tip = d.get("tip")
            if out and out[-1][0] == tip:
                out[-1] = (tip, out[-1][1], d["tick"])
            else:
                if out:
                    step, first, _ = out[-1]
                    out[-1] = (step, first, d["tick"] - 1)
                out.append((tip, d["tick"], d["tick"]))
    return out


def pick_ticks(all_spans: list[tuple[str, int, int]], wanted: list[str]) -> list[int]:
    ticks, cursor = [], 0
    for item in wanted:
        step, _, fraction = item.rpartition(":")
        if not step:
            raise SystemExit(f"--at {item!r}: expected STEP:FRACTION")
        for i in range(cursor, len(all_spans)):
            if all_spans[i][0] == step:
                cursor = i
                break
        else:
            raise SystemExit(f"--at {item!r}: no span of {step!r} at or after the previous pick")
        _, first, last = all_spans[cursor]
        ticks.append(round(first + float(fraction) * (last - first)))
    return ticks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("gif", type=Path)
    ap.add_argument("--log", type=Path, required=True, help="the run's tick log")
    ap.add_argument("--at", nargs="+", required=True, metavar="STEP:FRACTION")
    ap.add_argument("--every", type=int, default=25, help="ticks between two frames")
    ap.add_argument("--columns", type=int, default=4)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    gif = Image.open(args.gif)
    frames = [f.convert("RGB") for f in ImageSequence.Iterator(gif)]
    ticks = pick_ticks(spans(args.log), args.at)
    idx = [min(len(frames) - 1, max(0, t // args.every - 1)) for t in ticks]
    w, h = (round(args.scale * s) for s in frames[0].size)
    rows = (len(idx) + args.columns - 1) // args.columns
    sheet = Image.new("RGB", (w * args.columns, h * rows), (255, 255, 255))
    for k, i in enumerate(idx):
        tile = frames[i].resize((w, h), Image.LANCZOS) if args.scale != 1.0 else frames[i]
        sheet.paste(tile, ((k % args.columns) * w, (k // args.columns) * h))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(args.out, optimize=True)
    print(f"wrote {args.out}: frames {idx} (ticks {ticks})")


if __name__ == "__main__":
    main()
