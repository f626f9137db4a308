"""`cell emulate`: the cell's devices, emulated on their real wires over the PyBullet twin, in
real time, so `cell run` and `cell check-hardware` drive them through the real drivers.

Contract: ``cell emulate [--config FILE] [--report FILE] [--print-config]`` (and ``--trace FILE``,
a per-step CSV of the twin). Prints ``ready`` on
stdout once every device listens; runs until SIGINT/SIGTERM (exit 0), writing the report after
each finished cycle and on the way out. The twin judges by physics alone (where each part is):
``packed`` = parts standing in the box, ``fed`` = parts that reached the slot (packed ones
included), ``cycles`` = packed parts.

Where each device listens is the configuration's ``devices`` section, the one `cell run` reads:
the UR controller on ``devices.arm.host`` (RTDE 30004, script 30003, dashboard 29999), the
gripper's URCap socket there too (``devices.gripper.urcap_port``), the 2F-85's Modbus RTU line and
the FT300's stream on pseudo-terminals whose names the kernel picks, so a symbolic link at
``devices.gripper.port`` and ``devices.ft.port`` points at each (made on start, removed on exit;
an existing file that is not a link is never replaced) -- or, for a ``devices.ft.port`` of
``socket://host:port``, the FT300's line on that TCP port as a serial device server serves it --
and the D435's frames on ``devices.camera.stream``.

One thread owns PyBullet (:class:`sim.emulate.realtime.RealTimeLoop`): each control period it
runs the UR controller's cycle (which commands the twin's arm) and one twin step; the device
servers exchange values with it under locks. The camera renders in a forked process
(:mod:`sim.emulate.camera_process`), the FT300 streams from a spawned one
(:mod:`sim.emulate.ft300_process`). Faults on the wire: on the schedule of ``emulate.faults``,
and by signal: SIGUSR1 pulls the arm's Ethernet cable (every UR socket dropped, new connections
refused), a second SIGUSR1 plugs it back; SIGUSR2 raises a protective stop.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

from cell.errors import UserError

EXAMPLE = Path(__file__).resolve().parents[1] / "cell" / "data" / "emulated_cell.yaml"


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "emulate",
        help="emulate the cell's devices on loopback over the twin (for `cell run`)",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    p.add_argument("--config", type=Path, default=None,
                   help=f"cell configuration (default: the shipped {EXAMPLE.name})")
    p.add_argument("--report", type=Path, default=None,
                   help="JSON report: cycles, fed, packed, parts (judged by the twin)")
    p.add_argument("--trace", type=Path, default=None,
                   help="CSV, one row per step of the twin: its time, wrist wrench (raw, tool "
                   "frame), finger opening, TCP position and arm mode; for diagnosing a run")
    p.add_argument("--print-config", action="store_true",
                   help="print the shipped example configuration's path and exit")
    p.set_defaults(func=cmd_emulate)


def _ft_stats(ft: Any) -> dict[str, Any]:
    frames, gap, late = ft.stats()
    return {"frames_sent": frames, "max_gap_ms": round(1e3 * gap, 1), "late_frames": late}


def _report(backend: Any, controller: Any, loop: Any, faults: list[dict[str, Any]],
            wires: Any, ft: dict[str, Any]) -> dict[str, Any]:
    """``ft``: the FT300's stream counters (:func:`_ft_stats`, asked of its process before the
    stepping lock is taken: a stalled child must not hold up the twin)."""
    where = backend.parts_where()
    account = backend.account()
    packed = account["packed"]
    return {
        "cycles": packed,
        "fed": packed + account["in_slot"],
        "packed": packed,
        "account": account,
        "parts": [
            {"body": b.body_id, "where": w, "position_m": [round(float(v), 4)
                                                           for v in b.pose().position]}
            for b, w in where
        ],
        "ur": controller.status(),
        "faults": faults,
        "ft": ft,
        "gripper": {"modbus_requests": wires.rtu.requests, "crc_errors": wires.rtu.crc_errors},
        "realtime": loop.margin_stats(),
    }


def _link(path: str, target: str, key: str) -> Path:
    """A symbolic link ``path`` -> ``target`` (a pseudo-terminal), replacing an old link only."""
    link = Path(path)
    if link.exists() and not link.is_symlink():
        raise UserError(f"{key}: {path} exists and is not a link: the emulator does not replace "
                        "it (a real device?)")
    try:
        link.parent.mkdir(parents=True, exist_ok=True)
        tmp = link.with_name(f".{link.name}.{os.getpid()}")
        if tmp.is_symlink():
            tmp.unlink()
        tmp.symlink_to(target)
        tmp.replace(link)
    except OSError as exc:
        raise UserError(f"{key}: cannot link {path} to {target}: {exc}") from None
    return link


def _socket_url(port: str, key: str) -> tuple[str, int] | None:
    """``socket://host:port`` (a serial device server's raw TCP port) as (host, port); None
    for a device path (the emulator links a pseudo-terminal there)."""
    if not port.startswith("socket://"):
        return None
    host, sep, number = port[len("socket://"):].rpartition(":")
    if not (host and sep and number.isdigit() and 0 < int(number) < 65536):
        raise UserError(f"{key}: {port} is not socket://HOST:PORT")
    return host, int(number)


class _Wires:
    """Every emulated device's cable: pull and plug by device name."""

    def __init__(self, servers: Any, rtu: Any, urcap: Any, ft: Any, camera: Any,
                 wrist: Any) -> None:
        self.servers, self.rtu, self.urcap, self.ft, self.camera = servers, rtu, urcap, ft, camera
        self.wrist = wrist  #: the FT300 emulator's load (a force step is injected there)

    def pull(self, device: str) -> None:
        if device == "arm":
            self.servers.pull_cable()
        elif device == "gripper":
            self.rtu.pull_cable()
            self.urcap.pull_cable()
        elif device == "ft":
            self.ft.pull_cable()
        else:
            self.camera.pull_cable()

    def plug(self, device: str) -> None:
        if device == "arm":
            self.servers.plug_cable()
        elif device == "gripper":
            self.rtu.restore()
            self.urcap.restore()
        elif device == "ft":
            self.ft.restore()
        else:
            self.camera.restore()


#: How long a force step lasts when its fault names no ``duration_s`` (s).
FORCE_STEP_S = 0.5


def _lasts(fault: Any) -> float | None:
    """How long a fault lasts (s) before it is undone; None: once, for good."""
    if fault.fault == "protective_stop":
        return None
    if fault.fault == "force_step":
        return fault.duration_s if fault.duration_s is not None else FORCE_STEP_S
    return fault.duration_s  # type: ignore[no-any-return]


def step_latency(first_stepped: float | None, stop_times: list[float],
                 within: float | None) -> float | None:
    """ms from the first reading with a force step to the first of ``stop_times`` after it
    (both ``time.monotonic()``: the stops' arrivals at the emulated controller, or the cycles
    that took them), or None if none came within ``within`` s."""
    if first_stepped is None or within is None:
        return None
    after = [t for t in stop_times if first_stepped <= t <= first_stepped + within]
    return round(1e3 * (after[0] - first_stepped), 2) if after else None


class _Schedule:
    """``emulate.faults`` against the emulated controller's clock (the twin's time), checked
    from the stepping thread after each step; the wire is touched from the main thread."""

    def __init__(self, faults: list[Any]) -> None:
        self.faults = list(faults)
        self.first_motion: float | None = None
        self.fired: list[dict[str, Any]] = []  #: for the report: what happened when
        self._due: list[tuple[int, str]] = []  # (index, "pull"/"plug"), for the main thread
        self._pulled_at: dict[int, float] = {}
        self._done: set[int] = set()
        self._lock = threading.Lock()

    def check(self, t: float, moving: bool) -> None:
        """On the stepping thread: ``t`` the controller's time (s), ``moving`` the arm."""
        if self.first_motion is None:
            if not moving:
                return
            self.first_motion = t
        since = t - self.first_motion
        for i, f in enumerate(self.faults):
            if i in self._done:
                continue
            if i not in self._pulled_at:
                # One fault at a time on a device: two force steps overlapping would share a
                # first reading and time neither (several fall due at once when the arm stood
                # still past their times, e.g. while a stopped run was being resumed).
                busy = any(j not in self._done and self.faults[j].device == f.device
                           for j in self._pulled_at)
                if since >= f.at_s and (moving or not f.mid_motion) and not busy:
                    self._pulled_at[i] = t
                    with self._lock:
                        self._due.append((i, "pull"))
                    if _lasts(f) is None:
                        self._done.add(i)
            elif (lasts := _lasts(f)) is not None and t - self._pulled_at[i] >= lasts:
                self._done.add(i)
                with self._lock:
                    self._due.append((i, "plug"))

    def take(self) -> list[tuple[Any, str]]:
        with self._lock:
            due, self._due = self._due, []
        return [(self.faults[i], what) for i, what in due]


def cmd_emulate(args: argparse.Namespace) -> int:
    if args.print_config:
        print(EXAMPLE)
        return 0
    from cell.assemble import build_twin
    from cell.cell_cmds import load_prepared, report_config_error
    from sim.emulate.camera_process import CameraProcess
    from sim.emulate.ft300_process import FT300Process
    from sim.emulate.gripper_server import Gripper2F85, ModbusRtuServer, TwinFingers, UrcapServer
    from sim.emulate.ur_controller import (
        ControllerSettings,
        TwinArmBackend,
        URController,
        URServers,
    )
    from trees.yaml_lines import ConfigError

    try:
        prep = load_prepared(args.config or EXAMPLE)
    except ConfigError as exc:
        return report_config_error(exc, "emulate")
    # Many I/O threads beside one that steps PyBullet: with the default 5 ms switch interval a
    # thread woken by its socket or line waits up to 5 ms for the interpreter at every wake-up
    # (the FT300 stream's frames then came 50 ms apart). 0.5 ms keeps them on time.
    sys.setswitchinterval(0.0005)
    config = prep.config
    dev, emu = config.devices, config.emulate
    if not dev.camera.stream:
        raise UserError(f"{prep.doc.source}: devices.camera.stream: `cell emulate` serves the "
                        "D435 as a frame stream; name its host:port")
    cam_host, _, cam_port = dev.camera.stream.rpartition(":")
    backend = build_twin(prep)
    robot = backend.robot
    lock = threading.Lock()
    opened: list[Any] = []  # what to close, in reverse
    links: list[Path] = []
    try:
        # The camera forks the emulator: before any thread of it starts.
        camera = CameraProcess(backend, prep.layout.tool_T_camera(), cam_host, int(cam_port),
                               emu.camera_width, emu.camera_height, emu.camera_fps, lock)
        try:
            camera.start()
        except OSError as exc:
            raise UserError(f"devices.camera.stream: {exc}") from None
        opened.append(camera.stop)
        # Only the stepping thread is raised (emulate.step_niceness, in its loop): a stop's
        # arrival is stamped by the kernel, not by the servers' threads, and with them raised
        # too the stepping thread kept no better time (0.89 % of steps late against 0.90 %).
        settings = ControllerSettings(frequency=float(config.cell.control_hz))
        controller = URController(TwinArmBackend(robot.arm, robot.ft), settings)
        try:
            servers = URServers(controller, dev.arm.host).start()
        except OSError as exc:
            raise UserError(f"cannot listen on {dev.arm.host} (devices.arm.host): {exc}") from None
        opened.append(servers.stop)
        gripper = Gripper2F85(TwinFingers(robot.gripper, backend.world))
        rtu = ModbusRtuServer(gripper, unit_id=dev.gripper.slave_id).start()
        opened.append(rtu.close)
        try:
            urcap = UrcapServer(gripper, dev.arm.host, dev.gripper.urcap_port)
        except OSError as exc:
            raise UserError(f"devices.gripper.urcap_port: cannot listen on "
                            f"{dev.arm.host}:{dev.gripper.urcap_port}: {exc}") from None
        opened.append(urcap.stop)
        ft_listen = _socket_url(dev.ft.port, "devices.ft.port")
        try:
            # its own process: in this one its thread waited behind PyBullet's steps
            ft = FT300Process(robot.ft, backend.world, unit_id=dev.ft.slave_id,
                              seed=config.sim.seed, listen=ft_listen).start()
            wrist = ft.wrist
        except OSError as exc:
            raise UserError(f"devices.ft.port: cannot listen on {dev.ft.port}: {exc}") from None
        opened.append(ft.close)
        links.append(_link(dev.gripper.port, rtu.port, "devices.gripper.port"))
        if ft_listen is None:
            links.append(_link(dev.ft.port, ft.port, "devices.ft.port"))
        wires = _Wires(servers, rtu, urcap, ft, camera, wrist)
        schedule = _Schedule(emu.faults)
        return _serve(args, backend, controller, servers, wires, schedule, lock, settings,
                      config.emulate.step_niceness)
    finally:
        for link in links:
            try:
                if link.is_symlink():
                    link.unlink()
            except OSError:
                pass
        for close in reversed(opened):
            try:
                close()
            except Exception:  # noqa: BLE001 -- every device must be closed
                pass
        backend.close()


def _serve(args: argparse.Namespace, backend: Any, controller: Any, servers: Any, wires: _Wires,
           schedule: _Schedule, lock: threading.Lock, settings: Any, emulate_niceness: int) -> int:
    import numpy as np

    from drivers.arm import MotionState
    from sim.emulate.realtime import RealTimeLoop

    state = {"packed": -1}

    def write_report() -> None:
        if args.report is None:
            return
        ft = _ft_stats(wires.ft)
        with lock:
            report = _report(backend, controller, loop, schedule.fired, wires, ft)
        args.report.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.report.with_suffix(args.report.suffix + ".tmp")
        tmp.write_text(json.dumps(report, indent=2))
        tmp.replace(args.report)

    twin_arm = backend.robot.arm
    trace = None
    if args.trace is not None:
        from sim.trace import TwinTrace

        trace = TwinTrace(args.trace, backend.world, backend.robot)

    def step() -> None:
        with lock:
            controller.cycle()
            backend.step()
            if schedule.faults:
                schedule.check(controller.t, twin_arm.status().state is MotionState.MOVING)

    loop = RealTimeLoop(1.0 / settings.frequency, step, niceness=emulate_niceness)
    stop = threading.Event()

    def on_stop(signum: int, frame: Any) -> None:
        stop.set()
        loop.stop()

    def on_cable(signum: int, frame: Any) -> None:
        if servers.cable:
            servers.pull_cable()
        else:
            servers.plug_cable()

    def on_protective(signum: int, frame: Any) -> None:
        controller.raise_protective_stop("raised by SIGUSR2")

    signal.signal(signal.SIGINT, on_stop)
    signal.signal(signal.SIGTERM, on_stop)
    signal.signal(signal.SIGUSR1, on_cable)
    signal.signal(signal.SIGUSR2, on_protective)
    # The twin, the servers and the modules live as long as the emulator: out of the
    # collector's sight, a full collection no longer holds the stepping thread for 25 ms. (No
    # collection first: the device servers already stream.)
    gc.freeze()
    thread = threading.Thread(target=loop.run, name="twin", daemon=True)
    thread.start()
    print("ready", flush=True)
    next_report = 0.0
    try:
        while not stop.wait(0.01):
            for fault, what in schedule.take():
                entry: dict[str, Any] = {}
                if fault.fault == "protective_stop":
                    controller.raise_protective_stop("raised by emulate.faults")
                elif fault.fault == "force_step":
                    if what == "pull":
                        wires.wrist.inject(np.array([0.0, 0.0, fault.force_n, 0.0, 0.0, 0.0]))
                        entry["arm_mode"] = twin_arm.mode  # what the arm was doing
                    else:
                        wires.wrist.clear()
                        # The stop must come from the cell's process: nothing here stops the arm.
                        # latency: to the stop's arrival at the controller (its RTDE
                        # message received); taken: to the cycle that acted on it (the
                        # emulator's own scheduling added); at rest: the move had ended
                        first, within = wires.wrist.first_stepped, _lasts(fault)
                        log_ = controller.log
                        acting = step_latency(first, list(log_.stop_arrivals), within)
                        resting = step_latency(first, list(log_.rest_stop_arrivals), within)
                        entry["latency_ms"] = min(
                            (v for v in (acting, resting) if v is not None), default=None)
                        entry["taken_ms"] = step_latency(first, list(log_.stop_times),
                                                         within)
                        entry["arm_at_rest"] = acting is None and resting is not None
                        entry["force_n"] = fault.force_n
                elif what == "pull":
                    wires.pull(fault.device)
                else:
                    wires.plug(fault.device)
                schedule.fired.append({"device": fault.device, "fault": fault.fault,
                                       "what": what, "t_s": round(controller.t, 3),
                                       "wall": time.time(), **entry})
                print(f"emulate: {fault.device} {fault.fault} {what} at "
                      f"{controller.t:.3f} s", file=sys.stderr, flush=True)
                write_report()  # what a fault did is on disk as it happens
            now = time.monotonic()
            if now < next_report:
                continue
            next_report = now + 0.5
            with lock:
                packed = backend.account()["packed"]
            if packed != state["packed"]:  # a cycle finished (or the first report)
                state["packed"] = packed
                write_report()
    finally:
        loop.stop()
        thread.join(timeout=2.0)
        write_report()
        if trace is not None:
            trace.close()
    print(json.dumps({"realtime": loop.margin_stats()}), file=sys.stderr)
    return 0
