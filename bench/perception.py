"""Benchmark: bin perception over rendered scenes, classical and learned, against ground truth.

Run by hand:  python bench/perception.py [--scenes 200] [--seed 10000] [--pipelines classical]
              [--fill random]

Runs ``cell perceive`` for each pipeline on the same scenes and prints one table: recall, false
positives, position and yaw errors (median, p95) and the median processing time per frame
(rendering excluded), wall clock and this process's CPU time: wall above CPU means the run waited
for a core (another job on the machine), CPU above wall means extra threads. Targets:
recall >= 0.98, yaw p95 <= 2 deg, position p95 <= 3 mm, median <= 60 ms per frame for the
classical pipeline, on this 2-core machine. Also the time per scene with all the views the
Look takes of it (the wide view or two, the end views), by the number of parts in the bin: how
it scales.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
from pathlib import Path

from cell.cli import main as cell


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=10000)
    ap.add_argument("--pipelines", nargs="+", default=["classical", "learned"])
    ap.add_argument("--fill", choices=["staged", "random"], default="staged")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for pipeline in args.pipelines:
            out = Path(tmp) / f"{pipeline}.json"
            argv = ["perceive", "--scenes", str(args.scenes), "--seed", str(args.seed),
                    "--fill", args.fill]
            code = cell([*argv, "--json", str(out), "--pipeline", pipeline])
            if code == 0:
                rows.append(json.loads(out.read_text()))
    print()
    print(
        f"machine {platform.machine()}, {os.cpu_count()} cores; {args.scenes} scenes "
        f"from seed {args.seed}"
    )
    head = (
        "pipeline",
        "recall",
        "false pos",
        "pos med mm",
        "pos p95 mm",
        "yaw med deg",
        "yaw p95 deg",
        "ms/frame",
        "CPU ms/frame",
    )
    print(" | ".join(head))
    for r in rows:
        print(
            f"{r['pipeline']} | {r['recall']:.3f} ({r['found']}/{r['parts']}) | "
            f"{r['false_positives']} | {r['pos_err_mm_median']:.2f} | {r['pos_err_mm_p95']:.2f} | "
            f"{r['yaw_err_deg_median']:.2f} | {r['yaw_err_deg_p95']:.2f} | "
            f"{r['ms_per_frame_median']:.0f} | {r['cpu_ms_per_frame_median']:.0f}"
        )
        print(
            f"   missed by part: {r['missed_by_part']}; open end decided for "
            f"{r['open_end_decided']} of {r['open_end_one_ended_parts']} cups/bottles, right "
            f"{r['open_end_decided_right']}"
        )
        print(
            f"   {r['ms_per_scene_median']:.0f} ms per scene with all its views (median); by "
            "parts in the bin: "
            + ", ".join(
                f"{k}: {v['ms_median']:.0f} ms ({v['scenes']} scenes)"
                for k, v in r["ms_per_scene_by_parts"].items()
            )
        )


if __name__ == "__main__":
    run()
