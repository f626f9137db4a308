"""The emulated D435 in a process of its own, rendering a forked copy of the twin.

Why a process: PyBullet's TinyRenderer takes 45 ms for a 424 x 240 frame and 140-200 ms for
640 x 480 on this project's machines, inside one C call that holds the GIL. Rendered on the
thread that steps the twin, every frame would stall the emulated controller by that long. So
:class:`CameraProcess` forks the emulator once the twin is built (before any thread starts): the
child owns a copy of the whole world, and for each frame it asks the parent for a
:class:`Snapshot` -- every part's pose and every robot joint's angle, read in well under a
millisecond under the stepping lock -- applies it to its copy and renders there, on the other
core. The frames are the twin's state at the snapshot, with the twin camera's noise model.

The child serves :class:`sim.emulate.camera_stream.CameraStreamServer` itself, so the frames go
from the process that renders them straight onto the socket. Wire faults are forwarded to it.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: How much lower the renderer runs than the emulator (``nice`` steps).
CAMERA_NICENESS = 10


@dataclass
class Snapshot:
    """What the camera can see change: the parts' poses and the robot's joint angles."""

    parts: list[tuple[int, tuple[float, ...], tuple[float, ...]]]  #: body, position, quaternion
    joints: list[float]  #: every joint of the robot body, in index order (arm and fingers)


def take_snapshot(backend: Any) -> Snapshot:
    """Read the twin's movable state (call it while the twin is not stepping)."""
    p = backend.world.p
    parts = []
    for b in backend.bodies:
        pos, orn = p.getBasePositionAndOrientation(b.body_id)
        parts.append((b.body_id, tuple(pos), tuple(orn)))
    robot = backend.robot.body_id
    states = p.getJointStates(robot, list(range(p.getNumJoints(robot))))
    return Snapshot(parts, [float(s[0]) for s in states])


def apply_snapshot(backend: Any, snap: Snapshot) -> None:
    """Put the twin copy into the snapshot's state (no stepping: only what is rendered)."""
    p = backend.world.p
    for body, pos, orn in snap.parts:
        p.resetBasePositionAndOrientation(body, pos, orn)
    robot = backend.robot.body_id
    for j, q in enumerate(snap.joints):
        p.resetJointState(robot, j, q)


class _ShadowSource:
    """:class:`sim.emulate.camera_stream.FrameSource` on the child's copy of the twin."""

    def __init__(self, backend: Any, camera: Any, snapshot: Callable[[], Snapshot]) -> None:
        self._backend, self._camera, self._snapshot = backend, camera, snapshot

    def intrinsics(self) -> Any:
        return self._camera.intrinsics()

    def frame(self) -> tuple[NDArray[np.uint8], NDArray[np.floating]]:
        apply_snapshot(self._backend, self._snapshot())
        f = self._camera.capture()
        return f.rgb, f.depth


def _child(backend: Any, tool_T_camera: Any, host: str, port: int, width: int, height: int,
           fps: int, control: Connection, snaps: Connection) -> None:
    import signal

    from sim.camera import SimCamera, d435_intrinsics
    from sim.emulate.camera_stream import CameraStreamServer

    # The fault signals are the emulator's (the parent's); `pkill -USR1 -f "cell emulate"`
    # reaches this child too, whose default action would end it and unplug the camera for good.
    for sig in (signal.SIGUSR1, signal.SIGUSR2):
        signal.signal(sig, signal.SIG_IGN)
    # Below the twin's stepping thread and the cell under test: on a 2-core machine its
    # 45 ms renders took the core the twin needed in contact-rich steps (the twin slipped). A
    # render that comes late drops its slot, as a camera's dropped frame; the stream's clock
    # stays on the fps grid.
    try:
        os.nice(CAMERA_NICENESS)
    except OSError:
        pass
    robot = backend.robot
    camera = SimCamera(backend.world, lambda: robot.world_pose(robot.arm.tool_pose()),
                       tool_T_camera=tool_T_camera, intrinsics=d435_intrinsics(width, height))

    def snapshot() -> Snapshot:
        snaps.send("snap")
        return snaps.recv()  # type: ignore[no-any-return]

    try:
        server = CameraStreamServer(_ShadowSource(backend, camera, snapshot), host, port, fps)
    except OSError as exc:
        control.send(("error", f"cannot listen on {host}:{port}: {exc}"))
        return
    server.start()
    control.send(("ready", server.port))
    try:
        while True:
            try:
                cmd = control.recv()
            except (EOFError, OSError):  # the emulator is gone
                break
            if cmd == "stop":
                break
            if cmd == "pull":
                server.pull_cable()
            elif cmd == "restore":
                server.restore()
            elif cmd == "stats":
                control.send({"frames_sent": server.frames_sent, "clients": server.clients})
    finally:
        server.stop()


class CameraProcess:
    """The D435 emulator in a forked child (see the module doc). Create it before any thread
    starts; :meth:`start` forks, waits for the child to listen and starts answering its
    snapshot requests under ``lock`` (the lock the stepping loop holds while stepping)."""

    def __init__(self, backend: Any, tool_T_camera: Any, host: str, port: int, width: int,
                 height: int, fps: int, lock: threading.Lock) -> None:
        self._backend, self._lock = backend, lock
        ctx = mp.get_context("fork")
        self._control, child_control = ctx.Pipe()
        self._snaps, child_snaps = ctx.Pipe()
        self._proc = ctx.Process(
            target=_child, name="emu-d435",
            args=(backend, tool_T_camera, host, port, width, height, fps, child_control,
                  child_snaps),
            daemon=True,
        )
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._serve_snapshots, name="emu-d435-snap",
                                        daemon=True)
        self.port = port
        self.frozen = False

    def start(self, timeout: float = 30.0) -> CameraProcess:
        """Fork and wait until the child listens; OSError if it cannot."""
        self._proc.start()
        if not self._control.poll(timeout):
            self._proc.kill()
            raise OSError("the camera emulator did not start")
        kind, value = self._control.recv()
        if kind != "ready":
            self._proc.join(timeout=5.0)
            raise OSError(value)
        self.port = int(value)
        self._thread.start()
        return self

    def _serve_snapshots(self) -> None:
        while not self._stopped.is_set():
            try:
                if not self._snaps.poll(0.1):
                    continue
                self._snaps.recv()
            except (EOFError, OSError):
                return
            with self._lock:
                snap = take_snapshot(self._backend)
            try:
                self._snaps.send(snap)
            except OSError:
                return

    def pull_cable(self) -> None:
        """Freeze the camera (no frames; the connection stays)."""
        self.frozen = True
        self._control.send("pull")

    def restore(self) -> None:
        self.frozen = False
        self._control.send("restore")

    def stop(self) -> None:
        self._stopped.set()
        try:
            self._control.send("stop")
        except OSError:
            pass
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(timeout=2.0)
        self._thread.join(timeout=2.0)
