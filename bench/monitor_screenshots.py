"""The pictures of docs/monitor.md: the live page during a `cell sim` of the shipped cell, and the
replay page over the log that run left, at its first abort (two thirds of the way through a run
without one). The window is tall enough for the whole shipped tree.

    python bench/monitor_screenshots.py [--out docs]

Needs headless Chromium (Debian: apt-get install chromium).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from tests.cdp import Browser  # noqa: E402
from tests.cell.test_monitor import get, wait_url  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs")
    ap.add_argument("--tip", default="tilt", help="the live picture is taken while this runs")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="mon-shots-"))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    sim = subprocess.Popen(
        [sys.executable, "-m", "cell.cli", "sim", "--cycles", "1", "--quiet",
         "--monitor", "127.0.0.1:0"],
        cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )
    url = wait_url(sim, r"monitor on (http://127\.0\.0\.1:\d+/)")
    with Browser(1400, 1120) as b:
        b.open(url)
        b.wait_for(f"document.getElementById('tip').textContent === {args.tip!r}", timeout=300)
        time.sleep(2.0)
        b.screenshot(args.out / "monitor_live.png")
    print(f"wrote {args.out / 'monitor_live.png'}")
    sim.communicate(timeout=900)
    log = tmp / "out" / "cell_ticks.jsonl"
    replay = subprocess.Popen(
        [sys.executable, "-m", "cell.cli", "replay", str(log), "--serve", "127.0.0.1:0"],
        cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
    )
    replay.stderr = replay.stdout
    url = wait_url(replay, r"serving (http://127\.0\.0\.1:\d+/)")
    tl = get(url + "api/timeline")
    with Browser(1400, 1120) as b:
        b.open(url)
        b.wait_for("document.body.dataset.tick !== undefined")
        if tl["marks"]["first_abort"] is not None:
            mark = tl["marks"]["first_abort"]
            b.click("#first-abort")
        else:  # a run without an abort: the slider dragged to two thirds of the run
            mark = 2 * tl["lines"] // 3
            b.js(
                f"(() => {{ const s = document.getElementById('slider'); s.value = {mark}; "
                "s.dispatchEvent(new Event('input')); })()"
            )
        b.wait_for(f"Number(document.body.dataset.tick) === {tl['tick'][mark]}")
        time.sleep(1.0)
        b.screenshot(args.out / "monitor_replay.png")
    print(f"wrote {args.out / 'monitor_replay.png'} (line {mark}, tick {tl['tick'][mark]})")
    replay.stderr = None
    replay.terminate()
    replay.communicate(timeout=30)


if __name__ == "__main__":
    main()
