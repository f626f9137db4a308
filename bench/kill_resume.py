"""Kill the simulated cell with SIGKILL at random moments and resume it, again and again.

    python bench/kill_resume.py [--kills 50] [--parts 8] [--seed 0] [--out DIR]

Each round starts `cell sim --resume` (the first without --resume), lets it run a random
0.5-8 s of wall time (start-up included, so some kills land before the tree runs, some in the
middle of a motion or of a journal write) and kills it with SIGKILL. After the last kill the
cell is resumed once more and runs to the end. Then the journal must show no slot fed twice and
no box place filled twice (`Resume.from_events` refuses both), and the twin's final accounting
must find every part: packed, with none in the bin, in the hand, in the slot or on the floor.
Prints the figures; exits 1 when a check fails.
"""

from __future__ import annotations

import argparse
import json
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cell.journal import Journal, JournalError, Resume  # noqa: E402

CONFIG = """\
cell: {{layout: {{bin_inner_size: [0.50, 0.44]}}}}
sim: {{seed: {seed}}}
bin: {{parts: {parts}}}
workflow: {{machining_time_s: 1, cycles: {parts}}}
log: {{tick_log: {out}/ticks.jsonl, state_file: {out}/state.json, journal: {out}/journal.sqlite}}
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kills", type=int, default=50)
    ap.add_argument("--parts", type=int, default=8, help="parts in the bin (at most 10)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("out/kill_resume"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for f in args.out.glob("journal.sqlite*"):
        f.unlink()
    cfg = args.out / "cell.yaml"
    cfg.write_text(CONFIG.format(seed=args.seed, parts=args.parts, out=args.out.resolve()))
    rng = random.Random(args.seed)
    cmd = [sys.executable, "-m", "cell.cli", "sim", "--config", str(cfg), "--quiet"]
    t0 = time.monotonic()
    finished_early = 0
    for k in range(args.kills):
        proc = subprocess.Popen(
            cmd + (["--resume"] if k else []), stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            proc.wait(timeout=rng.uniform(0.5, 8.0))
            finished_early += 1  # it ran to the end (or had nothing left) before the kill
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
        print(f"\rkill {k + 1}/{args.kills}", end="", flush=True)
    final = args.out / "final.json"
    r = subprocess.run(cmd + ["--resume", "--json", str(final)], capture_output=True, text=True)
    print()
    try:
        journal = Journal(args.out / "journal.sqlite")
        events = journal.events()
        state = Resume.from_events(events)
    except JournalError as exc:
        print(f"FAIL: {exc}")
        return 1
    kinds = [e["kind"] for e in events]
    parts = json.loads(final.read_text())["parts"] if final.exists() else None
    print(f"{args.kills - finished_early} SIGKILLs landed ({finished_early} runs ended before "
          f"theirs) in {time.monotonic() - t0:.0f} s wall, {state.runs} runs journaled; final "
          f"run exit {r.returncode}"
          + ("" if final.exists() else f" ({r.stdout.strip().splitlines()[-1:]})"))
    print(f"journal: {len(events)} events, fed {kinds.count('fed')}, packed "
          f"{kinds.count('packed')}, returned to the bin {kinds.count('returned_to_bin')}, "
          f"to the slot {kinds.count('returned_to_slot')}; box places {sorted(state.filled)}")
    print(f"final twin accounting: {parts}")
    ok = (
        len(state.filled) == args.parts
        and len(set(state.filled)) == len(state.filled)
        and (parts is None or (parts["packed"] == args.parts and parts["on_floor"] == 0))
    )
    print("no slot fed twice, no box place filled twice, no part lost" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
