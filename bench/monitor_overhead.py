"""What the web monitor costs the cell, how big its tick log gets, how fast a replay opens.

1. Tick time with the monitor off and on. The shipped cell runs in the twin (physics included,
   as `cell sim` runs it) for ``--sim-seconds`` from the same seed, alternately without and with
   ``--monitor`` -- the server up and a poller asking /api/tree, /api/state and /api/events four
   times a second, as the page does. Also the tick thread's own cost, timed around
   ``LiveMonitor.publish`` (folding the line, appending the wrench, swapping the view).
2. The tick log of ``--cycles`` full cycles (frames included), per cycle and scaled to 1000.
3. A 1000-cycle log: those cycles' lines repeated with ticks and times shifted (a real run's
   lines, not invented ones) -- its size, the time `cell replay --serve` takes to open it, and
   the time of the page's three requests at a line in its middle.

    python bench/monitor_overhead.py [--sim-seconds 20] [--repeats 2] [--cycles 1] [--json F]

Target: the monitor costs at most 10 % of the tick time.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

from cell.assemble import open_backend
from cell.cell_cmds import load_prepared
from cell.monitor import frames_folder, load_run, open_session
from cell.monitor.server import MonitorServer
from cell.runner import TickLoop


def _run(sim_seconds: float, monitor: bool, folder: Path, cycles: int = 1) -> dict[str, Any]:
    prep = load_prepared(None)
    prep.ctx.limits.cycles = cycles
    config = prep.config.model_copy(
        update={
            "log": prep.config.log.model_copy(
                update={
                    "tick_log": str(folder / "cell_ticks.jsonl"),
                    "state_file": None,
                    "journal": None,
                }
            )
        }
    )
    prep.config = config
    backend = open_backend(prep, seed=0)
    session = open_session(prep, "127.0.0.1:0" if monitor else None, "sim")
    publish_s: list[float] = []
    stop = threading.Event()
    polls = [0]
    if session.live is not None:
        inner = session.live.publish

        def timed(*a: Any) -> None:
            t0 = time.perf_counter()
            inner(*a)
            publish_s.append(time.perf_counter() - t0)

        session.live.publish = timed  # type: ignore[method-assign]
        url = session.server.url

        def poll() -> None:
            while not stop.wait(0.25):
                try:
                    for route in ("api/tree", "api/state", "api/events"):
                        with urllib.request.urlopen(url + route, timeout=5) as r:
                            r.read()
                except OSError:
                    return  # the run ended and the server with it
                polls[0] += 1

        threading.Thread(target=poll, daemon=True).start()
    loop = TickLoop(
        prep.root,
        backend,
        prep.state,
        session.log,
        config.cell.control_hz,
        wrench=lambda: prep.ctx.devices.ft.wrench(),
        taps=session.taps,
        monitor=session.live,
    )
    cpu0 = time.process_time()
    try:
        result = loop.run(sim_seconds)
        cpu = time.process_time() - cpu0
    finally:
        stop.set()
        session.close()
        session.log.close()
        backend.close()
    return {
        "ticks": result.ticks,
        "wall_s": result.wall_s,
        "us_per_tick": 1e6 * result.wall_s / max(1, result.ticks),
        # CPU time of the whole process (server thread included) per tick: what the monitor
        # takes from the cell, and steadier than wall time on a shared machine
        "cpu_us_per_tick": 1e6 * cpu / max(1, result.ticks),
        "publish_us_mean": 1e6 * statistics.fmean(publish_s) if publish_s else None,
        "publish_us_p99": 1e6 * sorted(publish_s)[int(0.99 * len(publish_s))]
        if publish_s
        else None,
        "polls": polls[0],
        "status": result.status,
        "sim_time_s": result.sim_time,
    }


def _scaled_log(lines: list[dict[str, Any]], header: dict[str, Any], copies: int, out: Path) -> int:
    """``copies`` runs of ``lines`` one after the other, ticks and times shifted."""
    last_tick, last_t = lines[-1]["tick"], lines[-1]["t"]
    with open(out, "w", encoding="utf-8") as fh:
        fh.write(json.dumps({"header": header}) + "\n")
        for k in range(copies):
            for line in lines:
                shifted = dict(
                    line, tick=line["tick"] + k * last_tick, t=round(line["t"] + k * last_t, 4)
                )
                fh.write(json.dumps(shifted) + "\n")
    return out.stat().st_size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sim-seconds", type=float, default=20.0)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--cycles", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="mon-bench-"))
    report: dict[str, Any] = {"runs": []}

    # 1. overhead, alternating off/on
    for r in range(args.repeats):
        for monitor in (False, True):
            res = _run(args.sim_seconds, monitor, tmp / f"o{r}{int(monitor)}")
            res["monitor"] = monitor
            report["runs"].append(res)
            print(
                f"monitor {'on ' if monitor else 'off'}: {res['ticks']} ticks, "
                f"{res['us_per_tick']:.0f} us/tick wall, {res['cpu_us_per_tick']:.0f} us CPU"
                + (
                    f", publish {res['publish_us_mean']:.1f} us mean "
                    f"({res['publish_us_p99']:.1f} p99), {res['polls']} page polls"
                    if monitor
                    else ""
                ),
                flush=True,
            )
    off = statistics.median(r["us_per_tick"] for r in report["runs"] if not r["monitor"])
    on = statistics.median(r["us_per_tick"] for r in report["runs"] if r["monitor"])
    pub = statistics.fmean(r["publish_us_mean"] for r in report["runs"] if r["monitor"])
    cpu_off = statistics.median(r["cpu_us_per_tick"] for r in report["runs"] if not r["monitor"])
    cpu_on = statistics.median(r["cpu_us_per_tick"] for r in report["runs"] if r["monitor"])
    report["overhead"] = {
        "us_per_tick_off": off,
        "us_per_tick_on": on,
        "overhead_pct": 100.0 * (on - off) / off,
        "cpu_us_per_tick_off": cpu_off,
        "cpu_us_per_tick_on": cpu_on,
        "cpu_overhead_pct": 100.0 * (cpu_on - cpu_off) / cpu_off,
        "publish_us_mean": pub,
        "publish_pct_of_tick": 100.0 * pub / off,
    }
    print(
        f"tick wall: {off:.0f} us off, {on:.0f} us on: "
        f"{report['overhead']['overhead_pct']:+.1f} %; "
        f"CPU: {cpu_off:.0f} us off, {cpu_on:.0f} us on: "
        f"{report['overhead']['cpu_overhead_pct']:+.1f} %; "
        f"publish() in the tick {pub:.1f} us = {report['overhead']['publish_pct_of_tick']:.2f} %"
    )

    # 2. the log of full cycles
    folder = tmp / "cycles"
    res = _run(150.0 * args.cycles + 60.0, False, folder, cycles=args.cycles)
    log = folder / "cell_ticks.jsonl"
    frames = frames_folder(log)
    frame_bytes = sum(p.stat().st_size for p in frames.glob("*.jpg"))
    n_frames = len(list(frames.glob("*.jpg")))
    per_cycle_log = log.stat().st_size / args.cycles
    per_cycle_frames = frame_bytes / args.cycles
    report["log"] = {
        "cycles": args.cycles,
        "status": res["status"],
        "sim_time_s": res["sim_time_s"],
        "ticks": res["ticks"],
        "log_bytes": log.stat().st_size,
        "lines": sum(1 for _ in open(log, encoding="utf-8")),
        "frames": n_frames,
        "frame_bytes": frame_bytes,
        "per_cycle_bytes": per_cycle_log,
        "per_cycle_frame_bytes": per_cycle_frames,
        "per_1000_cycles_mb": 1000 * per_cycle_log / 1e6,
        "frames_per_1000_cycles_mb": 1000 * per_cycle_frames / 1e6,
    }
    print(
        f"log: {args.cycles} cycle(s), {res['ticks']} ticks: {log.stat().st_size / 1e3:.1f} kB, "
        f"{report['log']['lines']} lines; {n_frames} frames {frame_bytes / 1e3:.0f} kB -> "
        f"1000 cycles: log {report['log']['per_1000_cycles_mb']:.1f} MB + frames "
        f"{report['log']['frames_per_1000_cycles_mb']:.1f} MB"
    )

    # 3. a 1000-cycle log: open it as `cell replay --serve` does, ask what the page asks
    run = load_run(log)
    big = tmp / "cell_ticks_1000.jsonl"
    copies = max(1, round(1000 / args.cycles))
    size = _scaled_log(run.lines, run.header, copies, big)
    t0 = time.perf_counter()
    big_run = load_run(big)
    opened = time.perf_counter() - t0
    server = MonitorServer("127.0.0.1", 0, replay=big_run)
    mid = len(big_run.lines) // 2
    t0 = time.perf_counter()
    for route in ("/api/tree", "/api/state", "/api/events"):
        json.dumps(server.payload(route, {"at": [str(mid)]}))
    step = time.perf_counter() - t0
    t0 = time.perf_counter()
    json.dumps(server.payload("/api/timeline", {}))
    timeline = time.perf_counter() - t0
    server.httpd.server_close()
    report["replay_1000"] = {
        "lines": len(big_run.lines),
        "log_mb": size / 1e6,
        "open_s": opened,
        "timeline_s": timeline,
        "step_s": step,
    }
    print(
        f"replay of 1000 cycles: {size / 1e6:.1f} MB, {len(big_run.lines)} lines: opened in "
        f"{opened:.2f} s; the slider's first request {timeline:.2f} s; one step (tree, state, "
        f"events at the middle) {1e3 * step:.0f} ms"
    )
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
