"""The UR controller emulator alone, on the twin's robot in an empty world, in a child process.

Why a process: ``ur_rtde``'s Python constructors hold the GIL while they wait for the
controller's replies, so an emulator on a thread of the same interpreter could never answer.
:class:`URAloneProcess` starts one and drives it over a pipe (status, cable, protective stop);
the driver tests connect the real ``ur_rtde`` to it.
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
    TwinArmBackend,
    URController,
    URServers,
)


def loopback_host() -> str:
    """A loopback address of this process's own, so ur_rtde's fixed ports are free there."""
    pid = os.getpid()
    return f"127.{100 + (pid >> 16) % 100}.{(pid >> 8) & 255}.{max(1, pid & 255)}"


class URAloneProcess:
    """A child process running :class:`URController` + :class:`URServers` on a twin robot."""

    def __init__(self, host: str | None = None, **settings: Any) -> None:
        # Not a plain fork: a parent whose numerical libraries keep a thread pool (torch,
        # OpenBLAS; a test process that ran perception first) forks a child that hangs on its
        # first parallel operation (seen: the twin's inertia arithmetic, for ever). The fork
        # server's children come from a clean process.
        ctx = mp.get_context("forkserver")
        self._pipe, child = ctx.Pipe()
        self.host = host or loopback_host()
        self._child_end = child
        self._proc = ctx.Process(
            target=_child, args=(child, self._pipe, self.host, settings), daemon=True
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


def _child(pipe: Any, parent_end: Any, host: str, settings: dict[str, Any]) -> None:
    from sim.robot import SimRobot
    from sim.world import PhysicsSettings, SimWorld

    # The child's copy of the parent's end closed, a parent that dies (even by a signal, which
    # runs no clean-up) reads as EOF below and the emulator ends with it: left running, it held
    # the parent's stdout and stderr open, and whoever waited on those waited for ever.
    parent_end.close()
    pipe.recv()
    try:
        s = ControllerSettings(**settings)
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
        elif kind == "stop":
            loop.stop()
            thread.join(timeout=2.0)
            servers.stop()
            world.close()
            with contextlib.suppress(OSError):
                pipe.send(None)
            return
