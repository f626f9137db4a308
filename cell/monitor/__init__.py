"""The cell's web monitor: the tree live, the wrist wrench, the camera, the events -- and the same
page over a recorded run (`cell replay LOG --serve`).

:func:`open_session` is what `cell sim` / `cell run` call: it sets up the tick log with the
monitor's header, the camera tap (frames for the replay, and for the page), and, with
``--monitor HOST:PORT``, the live server. :func:`serve_replay` is `cell replay --serve`.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cell.errors import UserError


def frames_folder(tick_log: str | Path) -> Path:
    """Where a tick log's camera frames live: ``out/cell_ticks.jsonl`` ->
    ``out/cell_ticks_frames/``."""
    p = Path(tick_log)
    return p.with_name(p.stem + "_frames")


@dataclasses.dataclass
class Session:
    """The tick log, its taps, and the live monitor and server (None without ``--monitor``)."""

    log: Any
    taps: list[Any]
    live: Any = None
    server: Any = None
    frames: Any = None

    def close(self) -> None:
        if self.live is not None:
            self.live.finish()
        if self.frames is not None:
            self.frames.close()
        if self.server is not None:
            self.server.close()


def open_session(
    prep: Any, address: str | None, command: str, accepted: Callable[[], None] | None = None
) -> Session:
    """Call after the backend is open (the camera is tapped) and before the tick loop.

    The monitor's port is bound first: a busy one refuses the start before ``accepted`` runs
    (the caller's last step of the start, the journal's opening) and before the tick log or the
    frames folder is written."""
    from cell.runner import TickLog

    config = prep.config
    s = config.safety
    server = None
    if address is not None:
        from cell.monitor.server import MonitorServer, parse_address, warn_if_exposed

        host, port = parse_address(address)
        warn_if_exposed(host, "--monitor", command)
        server = MonitorServer(host, port, frames_dir=None)
    try:
        if accepted is not None:
            accepted()
    except BaseException:
        if server is not None:
            server.close()
        raise
    meta = {
        "command": command,
        "backend": config.cell.backend,
        "control_hz": config.cell.control_hz,
        "cycles": prep.ctx.limits.cycles,
        "safety": {
            "max_force_n": s.ft_abort_force_n,
            "max_torque_nm": s.ft_abort_torque_nm,
            "timeout_s": s.default_timeout_s,
        },
        "started": time.strftime("%Y-%m-%d %H:%M:%S"),
        "wrench_deadband": [config.log.wrench_deadband_n, config.log.wrench_deadband_nm],
    }
    tick_log = config.log.tick_log
    folder = frames_folder(tick_log) if tick_log is not None and config.log.frames else None
    if folder is not None:
        meta["frames"] = folder.name
    log = TickLog(
        tick_log,
        deadband=(config.log.wrench_deadband_n, config.log.wrench_deadband_nm),
        meta=meta,
    )
    log.keep_lines = address is not None
    session = Session(log, [])
    devices = prep.ctx.devices
    if devices is not None and devices.camera is not None and (folder or address):
        from cell.monitor.live import FrameTap

        tap = FrameTap(devices.camera, devices.arm, folder)
        prep.ctx.devices = dataclasses.replace(devices, camera=tap)
        session.frames = tap
        session.taps.append(tap.tap)
    if server is not None:
        from cell.monitor.live import LiveMonitor

        session.live = LiveMonitor(meta)
        session.live.frames = session.frames
        server.live, server.frames_dir = session.live, folder
        session.server = server.start()
        print(f"cell {command}: monitor on {session.server.url} (read-only)", file=sys.stderr)
        sys.stderr.flush()
    return session


def load_run(path: Path) -> Any:
    """A tick log as a :class:`~cell.monitor.model.RunModel`; errors name the file and line."""
    from cell.monitor.model import RunModel

    try:
        fh = open(path, encoding="utf-8")  # noqa: SIM115 -- closed below
    except OSError as exc:
        raise UserError(f"{path}: cannot read the tick log: {exc.strerror}") from None
    header = None
    lines: list[dict[str, Any]] = []
    with fh:
        for n, raw in enumerate(fh, start=1):
            if not raw.strip():
                continue
            try:
                line = json.loads(raw)
            except json.JSONDecodeError as exc:
                raise UserError(f"{path}:{n}: not a JSON line: {exc.msg}") from None
            if "header" in line:
                header = line["header"]
            else:
                lines.append(line)
    if header is None:
        raise UserError(
            f"{path}: no header line (a log written before the monitor's format); "
            "`cell replay LOG` prints its timeline"
        )
    if not lines:
        raise UserError(f"{path}: the tick log holds no tick")
    return RunModel(header, lines)


def serve_replay(path: Path, address: str) -> int:
    from cell.monitor.server import MonitorServer, parse_address, warn_if_exposed

    host, port = parse_address(address, "--serve")
    t0 = time.perf_counter()
    run = load_run(path)
    took = time.perf_counter() - t0
    folder = path.with_name(run.header["frames"]) if "frames" in run.header else None
    server = MonitorServer(host, port, replay=run, frames_dir=folder, option="--serve")
    warn_if_exposed(host, "--serve", "replay")
    print(
        f"cell replay: {path}: {len(run.lines)} lines, ticks 1..{run.lines[-1]['tick']}, "
        f"opened in {took:.2f} s; serving {server.url} (Ctrl-C ends)",
        flush=True,
    )
    try:
        server.httpd.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.httpd.server_close()
    return 0


__all__ = ["Session", "frames_folder", "load_run", "open_session", "serve_replay"]
