"""The only module that touches ``ur_rtde``: a thin adapter exposing exactly the calls
:class:`drivers.ur5.arm.UR5Arm` makes.

Why an adapter: everything the driver decides (states, faults, reconnect, stop) is written
against :class:`RTDEAdapter`, so its logic can be checked tick by tick with a recording double;
the real calls are checked against the UR controller emulator (:mod:`sim.emulate.ur_controller`),
which behaves as ur_rtde's control script does. This module stays so thin that reading it is the
review. ``rtde_control``/``rtde_receive`` are imported inside
:meth:`URRTDEAdapter.connect` so the simulated cell never needs the library.

Poses cross this boundary in the controller's own convention, ``[x, y, z, rx, ry, rz]`` (m and an
axis-angle rotation vector in rad, base frame); conversion to :class:`drivers.pose.Pose` is the
driver's job.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

RTDE_PORT = 30004  #: the controller's RTDE port (fixed; ur_rtde does not let it be changed)

#: Interfaces of dead links given up by :meth:`URRTDEAdapter.abandon`, process-wide: nothing but
#: the end of the process disposes of them (see :func:`links_abandoned`).
_ABANDONED: list[Any] = []


def links_abandoned() -> bool:
    """True once an interface of a dead link was given up: the process must then end with
    ``os._exit`` after flushing what it writes.

    Why: ur_rtde's ``disconnect()`` on a dead link first tries to stop the control script and
    reconnect, which took 2.8 s after a pulled cable (``cell run`` against ``cell emulate``);
    and a ``RTDEControlInterface`` destroyed while a reconnect attempt of the driver is still
    inside ur_rtde aborts the process (``terminate called``, exit 134). Neither has anything
    left to do on a dead socket, so the process ends without running their destructors."""
    return bool(_ABANDONED)


@runtime_checkable
class RTDEAdapter(Protocol):
    """What the driver needs from the controller; every method maps to one ``ur_rtde`` call."""

    host: str

    def connect(self) -> None:
        """Open the control and receive interfaces (blocking; start-up only)."""
        ...

    def disconnect(self) -> None: ...

    def abandon(self) -> None:
        """Give up both interfaces of a dead link without disconnecting them, and refuse to
        build new ones (see :func:`links_abandoned`)."""
        ...

    def control_connected(self) -> bool:
        """ur_rtde has not seen the control link drop (cheap: a flag)."""
        ...

    def receive_connected(self) -> bool:
        """ur_rtde has not seen the receive link drop (cheap: a flag)."""
        ...

    def is_connected(self) -> bool:
        """Both RTDE links up (cheap: a flag in ur_rtde)."""
        ...

    def reconnect(self) -> bool:
        """Reopen lost links at the configured frequency (blocking: TCP connects and the
        script upload)."""
        ...

    def drop_control(self) -> None:
        """Give up the control interface (a call inside it is stuck); see the class."""
        ...

    def reupload_script(self) -> bool:
        """Restart the control script after a protective stop was unlocked."""
        ...

    # --- control side (commands) ---------------------------------------------------------

    def move_l(self, pose: Sequence[float], speed: float, acceleration: float) -> bool:
        """``moveL(pose, speed, acceleration, asynchronous=True)``."""
        ...

    def move_l_path(self, path: Sequence[Sequence[float]]) -> bool:
        """``moveL(path, asynchronous=True)``; rows ``[x, y, z, rx, ry, rz, v, a, blend]``."""
        ...

    def move_j(self, q: Sequence[float], speed: float, acceleration: float) -> bool:
        """``moveJ(q, speed, acceleration, asynchronous=True)``."""
        ...

    def async_status(self) -> tuple[bool, int]:
        """``getAsyncOperationProgressEx()``: ``(running, operation id)``. The control script
        numbers each async operation it starts (7 bits, wrapping 127 -> 0; a fresh script
        starts at 0); the running bit is the operation's, so the end of one operation and the
        start of the next are told apart even when no "finished" value is ever published
        between them (the script cancels and restarts within one controller cycle)."""
        ...

    def servo_l(self, pose: Sequence[float], time: float, lookahead: float, gain: float) -> bool:
        """``servoL(pose, 0, 0, time, lookahead, gain)`` (speed and acceleration are unused)."""
        ...

    def servo_stop(self, deceleration: float) -> bool: ...

    def stop_l(self, deceleration: float) -> None:
        """``stopL(a, asynchronous=True)``: returns at once, the controller decelerates (m/s^2).

        There is no asynchronous stopJ here: ur_rtde's script runs every asynchronous stop as
        ``stopl`` whatever was asked, so an ``a`` meant in rad/s^2 would be applied in m/s^2."""
        ...

    def force_mode(
        self,
        task_frame: Sequence[float],
        selection: Sequence[int],
        wrench: Sequence[float],
        frame_type: int,
        limits: Sequence[float],
    ) -> bool: ...

    def force_mode_stop(self) -> bool: ...

    def is_program_running(self) -> bool:
        """The control script runs on the controller (it ends on a protective stop)."""
        ...

    def set_watchdog(self, min_frequency: float) -> bool: ...

    def kick_watchdog(self) -> bool: ...

    def set_speed_slider(self, fraction: float) -> bool:
        """``RTDEIOInterface.setSpeedSlider(fraction)`` on a connection of its own: the
        controller scales every motion's timing by it from its next cycle. Unlike a command it
        waits for no handshake with the control script, so it acts within a controller cycle
        even while a command is in flight. False when it could not be sent."""
        ...

    # --- receive side (state) ------------------------------------------------------------

    def tcp_pose(self) -> list[float]:
        """``getActualTCPPose()``: ``[x, y, z, rx, ry, rz]``."""
        ...

    def joint_positions(self) -> list[float]:
        """``getActualQ()`` (rad)."""
        ...

    def safety_status_bits(self) -> int:
        """``getSafetyStatusBits()``; bit meanings in :data:`drivers.ur5.arm.SAFETY_BITS`."""
        ...

    def robot_mode(self) -> int:
        """``getRobotMode()``; names in :data:`drivers.ur5.arm.ROBOT_MODES`."""
        ...

    def timestamp(self) -> float:
        """``getTimestamp()``: the controller's time (s) of the newest data package."""
        ...


#: What the receive side subscribes to: only what the driver reads, so the recipe also works on
#: controllers whose software lacks some of ur_rtde's default outputs (its default list asks for
#: ``payload_inertia``, for one).
RECEIVE_VARIABLES = [
    "timestamp",
    "actual_q",
    "actual_TCP_pose",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
]


class URRTDEAdapter:
    """:class:`RTDEAdapter` over ``ur_rtde``'s ``RTDEControlInterface`` and
    ``RTDEReceiveInterface``.

    ``frequency``: the RTDE rate (Hz), 125 on a CB3 UR5, 500 on an e-Series; -1 lets ur_rtde
    choose from the controller version. The ``*_receive``/``*_control`` halves exist so the
    receive side can be tested alone against an RTDE peer.
    """

    def __init__(self, host: str, frequency: float = 125.0) -> None:
        self.host = host
        self.frequency = frequency
        self._control: Any = None
        self._receive: Any = None
        self._io: Any = None
        # Interfaces given up on: kept referenced, never destroyed under a thread of theirs
        # that may still be inside a blocking call.
        self._retired: list[Any] = []
        self._abandoned = False

    def connect(self) -> None:
        self.connect_receive()
        self.connect_control()
        self.connect_io()

    def connect_io(self) -> None:
        import rtde_io

        if self._abandoned:
            raise RuntimeError("the link was abandoned (shutting down)")
        self._io = self._keep(rtde_io.RTDEIOInterface(self.host))

    def connect_receive(self) -> None:
        # Imported here, not at the top: only the hardware path needs ur_rtde.
        import rtde_receive

        if self._abandoned:
            raise RuntimeError("the link was abandoned (shutting down)")
        self._receive = self._keep(
            rtde_receive.RTDEReceiveInterface(self.host, self.frequency, RECEIVE_VARIABLES)
        )

    def connect_control(self) -> None:
        import rtde_control

        if self._abandoned:
            raise RuntimeError("the link was abandoned (shutting down)")
        self._control = self._keep(rtde_control.RTDEControlInterface(self.host, self.frequency))

    def disconnect(self) -> None:
        for iface in (self._control, self._receive, self._io):
            if iface is not None:
                iface.disconnect()

    def abandon(self) -> None:
        # A reconnect attempt already inside connect_*() on another thread must not leave a
        # live interface behind (with a fresh script running) that nothing will close.
        self._abandoned = True
        _ABANDONED.extend(
            i for i in (self._control, self._receive, self._io, *self._retired) if i is not None
        )
        self._control = self._receive = self._io = None
        self._retired = []

    def _keep(self, iface: Any) -> Any:
        """``iface`` just built, or None (and abandoned with the rest) after :meth:`abandon`."""
        if self._abandoned:
            _ABANDONED.append(iface)
            return None
        return iface

    def receive_connected(self) -> bool:
        return self._receive is not None and bool(self._receive.isConnected())

    def control_connected(self) -> bool:
        return self._control is not None and bool(self._control.isConnected())

    def is_connected(self) -> bool:
        return self.receive_connected() and self.control_connected()

    # ur_rtde's own reconnect() resets the receive side's frequency to its default (125 or
    # 500 Hz): a reconnect builds fresh interfaces with the configured frequency instead.

    def reconnect_receive(self) -> bool:
        if self.receive_connected():
            return True
        self._retire(self._receive)
        self._receive = None
        self.connect_receive()
        return self.receive_connected()

    def reconnect_control(self) -> bool:
        if self.control_connected():
            return True
        self._retire(self._control)
        self._control = None
        self.connect_control()
        return self.control_connected()

    def reconnect_io(self) -> bool:
        if self._io is not None and bool(self._io.isConnected()):
            return True
        self._retire(self._io)
        self._io = None
        self.connect_io()
        return self._io is not None

    def reconnect(self) -> bool:
        return self.reconnect_receive() and self.reconnect_control() and self.reconnect_io()

    def drop_control(self) -> None:
        """Disconnect the control interface so a late command it still sends goes nowhere;
        the next reconnect builds a new one."""
        self._retire(self._control)
        self._control = None

    def _retire(self, iface: Any) -> None:
        if iface is not None:
            self._retired.append(iface)
            try:
                iface.disconnect()
            except Exception:  # already dead: nothing to close
                pass

    def _ctl(self) -> Any:
        """The control interface, refused once ur_rtde has seen its link drop: a command on
        it waits for a controller that will not answer (``stopL`` on the link of a controller
        whose process was killed never returned), so it raises here and the driver counts a
        lost link. A link that drops during a call is the driver's ``data_timeout`` to catch."""
        ctl = self._control
        if ctl is None or not ctl.isConnected():
            raise RuntimeError("RTDE control link down")
        return ctl

    def reupload_script(self) -> bool:
        return bool(self._ctl().reuploadScript())

    def move_l(self, pose: Sequence[float], speed: float, acceleration: float) -> bool:
        return bool(self._ctl().moveL(list(pose), speed, acceleration, True))

    def move_l_path(self, path: Sequence[Sequence[float]]) -> bool:
        return bool(self._ctl().moveL([list(row) for row in path], True))

    def move_j(self, q: Sequence[float], speed: float, acceleration: float) -> bool:
        return bool(self._ctl().moveJ(list(q), speed, acceleration, True))

    def async_status(self) -> tuple[bool, int]:
        status = self._control.getAsyncOperationProgressEx()
        return bool(status.isAsyncOperationRunning()), int(status.operationId())

    def servo_l(self, pose: Sequence[float], time: float, lookahead: float, gain: float) -> bool:
        return bool(self._ctl().servoL(list(pose), 0.0, 0.0, time, lookahead, gain))

    def servo_stop(self, deceleration: float) -> bool:
        return bool(self._ctl().servoStop(deceleration))

    def stop_l(self, deceleration: float) -> None:
        self._ctl().stopL(deceleration, True)

    def force_mode(
        self,
        task_frame: Sequence[float],
        selection: Sequence[int],
        wrench: Sequence[float],
        frame_type: int,
        limits: Sequence[float],
    ) -> bool:
        return bool(
            self._ctl().forceMode(
                list(task_frame), list(selection), list(wrench), frame_type, list(limits)
            )
        )

    def force_mode_stop(self) -> bool:
        return bool(self._ctl().forceModeStop())

    def is_program_running(self) -> bool:
        return bool(self._control.isProgramRunning())

    def set_watchdog(self, min_frequency: float) -> bool:
        return bool(self._ctl().setWatchdog(min_frequency))

    def kick_watchdog(self) -> bool:
        return bool(self._ctl().kickWatchdog())

    def set_speed_slider(self, fraction: float) -> bool:
        io = self._io
        if io is None or not io.isConnected():
            return False
        return bool(io.setSpeedSlider(float(fraction)))

    def tcp_pose(self) -> list[float]:
        return list(self._receive.getActualTCPPose())

    def joint_positions(self) -> list[float]:
        return list(self._receive.getActualQ())

    def safety_status_bits(self) -> int:
        return int(self._receive.getSafetyStatusBits())

    def robot_mode(self) -> int:
        return int(self._receive.getRobotMode())

    def timestamp(self) -> float:
        return float(self._receive.getTimestamp())
