"""The UR controller emulator alone, on the twin's robot in an empty world (or on a
:class:`~sim.emulate.ur_controller.StillArm`, no physics), in a child process.

Why a process: ``ur_rtde``'s Python constructors hold the GIL while they wait for the
controller's replies, so an emulator on a thread of the same interpreter could never answer.
:class:`URAloneProcess` starts one and drives it over a pipe (status, cable, protective stop,
dashboard commands, where a still arm stands, what the RTDE server was asked); the driver tests
connect the real ``ur_rtde`` to it.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import threading
from dataclasses import asdict
from typing import Any

from sim.emulate.realtime import RealTimeLoop
from sim.emulate.ur_controller import (
    ControllerSettings,
    StillArm,
    TwinArmBackend,
    URController,
    URServers,
)


def loopback_host() -> str:
    """A loopback address of this process's own, so ur_rtde's fixed ports are free there."""
    pid = os.getpid()
    return f"127.{100 + (pid >> 16) % 100}.{(pid >> 8) & 255}.{max(1, pid & 255)}"


class URAloneProcess:
    """A child process running :class:`URController` + :class:`URServers` on a twin robot
    (``arm="twin"``) or on a :class:`StillArm` (``arm="still"``: no PyBullet, a quick start;
    for the receive side and the dashboard). ``settings``: :class:`ControllerSettings`'."""

    def __init__(self, host: str | None = None, arm: str = "twin", **settings: Any) -> None:
        if arm not in ("twin", "still"):
            raise ValueError(f"arm must be 'twin' or 'still', got {arm!r}")
        # Not a plain fork: a parent whose numerical libraries keep a thread pool (torch,
        # OpenBLAS; a test process that ran perception first) forks a child that hangs on its
        # first parallel operation (seen: the twin's inertia arithmetic, for ever). The fork
        # server's children come from a clean process.
        ctx = mp.get_context("forkserver")
        self._pipe, child = ctx.Pipe()
        self.host = host or loopback_host()
        self._child_end = child
        self._proc = ctx.Process(
            target=_child, args=(child, self._pipe, self.host, arm, settings), daemon=True
        )

    def start(self) -> URAloneProcess:
        self._proc.start()
        self._child_end.close()  # the child's alone now: its death reads as EOF here
        reply = self._call(("ready",), timeout=60.0)
        if isinstance(reply, Exception):
            self._proc.join(timeout=2.0)
            raise reply
        return self

    def _call(self, message: tuple, timeout: float = 10.0) -> Any:  # type: ignore[type-arg]
        self._pipe.send(message)
        if not self._pipe.poll(timeout):
            raise TimeoutError(f"UR emulator process did not answer {message[0]!r}")
        return self._pipe.recv()

    def status(self) -> dict[str, Any]:
        return dict(self._call(("status",)))

    def pull_cable(self) -> None:
        self._call(("pull",))

    def plug_cable(self) -> None:
        self._call(("plug",))

    def protective_stop(self, reason: str = "injected") -> None:
        self._call(("protective", reason))

    def stop_times(self) -> list[float]:
        """``time.monotonic()`` (the machine's clock, the same in every process) of each stop
        command as the emulated controller's cycle took it."""
        return list(self._call(("stop_times",)))

    def stop_arrivals(self) -> list[float]:
        """The same stops' arrivals at the emulated controller (its RTDE messages received by
        the network stack, :attr:`ControllerLog.stop_arrivals`), in the same order."""
        return list(self._call(("stop_arrivals",)))

    def requested_frequencies(self) -> list[float]:
        return list(self._call(("requested",)))

    def rtde_log(self) -> dict[str, Any]:
        """What the RTDE server was asked: ``protocol_versions``, ``recipes`` (each output
        recipe's names, in order) and ``connections`` (accepted so far)."""
        return dict(self._call(("rtde_log",)))

    def drop_rtde_clients(self) -> None:
        """Close every live RTDE connection (the controller dropped them; it still listens)."""
        self._call(("drop_rtde",))

    def dashboard(self, command: str) -> str:
        """The controller's reply to one dashboard command (as if sent on port 29999)."""
        return str(self._call(("dashboard", command)))

    def place(self, q: list[float] | None = None, tcp: list[float] | None = None) -> None:
        """Put a still arm (``arm="still"``) at joints ``q`` and/or TCP pose ``tcp``."""
        reply = self._call(("place", q, tcp))
        if isinstance(reply, Exception):
            raise reply

    def stop(self) -> None:
        if self._proc.is_alive():
            try:
                self._call(("stop",))
            except (TimeoutError, OSError, EOFError):
                pass
            self._proc.join(timeout=3.0)
            if self._proc.is_alive():
                self._proc.kill()

    def __enter__(self) -> URAloneProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _child(pipe: Any, parent_end: Any, host: str, arm: str, settings: dict[str, Any]) -> None:
    # The child's copy of the parent's end closed, a parent that dies (even by a signal, which
    # runs no clean-up) reads as EOF below and the emulator ends with it: left running, it held
    # the parent's stdout and stderr open, and whoever waited on those waited for ever.
    parent_end.close()
    pipe.recv()
    world: Any = None
    still: StillArm | None = None
    try:
        s = ControllerSettings(**settings)
        if arm == "still":
            still = StillArm()
            controller = URController(still, s)
        else:
            from sim.robot import SimRobot
            from sim.world import PhysicsSettings, SimWorld

            world = SimWorld(settings=PhysicsSettings(control_hz=s.frequency))
            robot = SimRobot(world)
            controller = URController(TwinArmBackend(robot.arm, robot.ft), s)
        servers = URServers(controller, host).start()
    except Exception as e:  # the parent raises it
        pipe.send(e)
        return
    lock = threading.Lock()

    def step() -> None:
        with lock:
            controller.cycle()
            if world is not None:
                world.step()

    loop = RealTimeLoop(1.0 / s.frequency, step)
    thread = threading.Thread(target=loop.run, daemon=True)
    thread.start()
    pipe.send(True)
    while True:
        try:
            message = pipe.recv()
        except (EOFError, OSError):  # the parent is gone
            message = ("stop",)
        kind = message[0]
        if kind == "status":
            with lock:
                out = controller.status()
            out["margin"] = loop.margin_stats()
            out["settings"] = asdict(s)
            pipe.send(out)
        elif kind == "pull":
            servers.pull_cable()
            pipe.send(None)
        elif kind == "plug":
            servers.plug_cable()
            pipe.send(None)
        elif kind == "protective":
            controller.raise_protective_stop(message[1])
            pipe.send(None)
        elif kind == "stop_times":
            with lock:
                pipe.send(list(controller.log.stop_times))
        elif kind == "stop_arrivals":
            with lock:
                pipe.send(list(controller.log.stop_arrivals))
        elif kind == "requested":
            pipe.send([f for f, _ in servers.rtde.requested])
        elif kind == "rtde_log":
            pipe.send({"protocol_versions": list(servers.rtde.protocol_versions),
                       "recipes": [list(names) for _, names in servers.rtde.requested],
                       "connections": servers.rtde.listener.connections})
        elif kind == "drop_rtde":
            servers.rtde.listener.drop_clients()
            pipe.send(None)
        elif kind == "dashboard":
            pipe.send(controller.dashboard(message[1]))
        elif kind == "place":
            if still is None:
                pipe.send(ValueError("place: only a still arm (arm='still') can be put"))
            else:
                still.place(message[1], message[2])
                pipe.send(None)
        elif kind == "stop":
            loop.stop()
            thread.join(timeout=2.0)
            servers.stop()
            if world is not None:
                world.close()
            with contextlib.suppress(OSError):
                pipe.send(None)
            return
