"""A recording double of :class:`drivers.ur5.rtde_adapter.RTDEAdapter`.

Why: ``ur_rtde``'s control side needs a UR controller or URSim, which cannot run here. The
double records every call the driver makes (name and arguments) and plays back scripted
controller state (async progress, safety status bits, robot mode, link, reconnect outcomes), so
the driver's decisions can be checked tick by tick. It checks the driver's logic, not that the
controller behaves as scripted: that is for URSim or the real cell.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


class RecordingAdapter:
    """Scripted controller state; every call appended to :attr:`calls` as ``(name, args)``."""

    def __init__(self, host: str = "10.0.0.2") -> None:
        self.host = host
        self.calls: list[tuple[str, tuple[Any, ...]]] = []
        self.connected = True
        #: what async_status() returns now: (running, operation id)
        self.op: tuple[bool, int] = (False, 0)
        self.op_script: list[tuple[bool, int]] = []  #: if set, consumed one value per read
        self.safety_bits = 1  #: bit 0: normal mode
        self.mode = 7  #: RUNNING
        self.program_running = True
        self.pose = [0.4, 0.1, 0.3, 0.0, 3.14159, 0.0]
        self.q = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
        self.accept = True  #: what commands return
        self.reconnect_results: list[bool | Exception] = []  #: consumed per reconnect()
        self.raise_on: dict[str, Exception] = {}  #: name -> exception that call raises

    def _rec(self, name: str, *args: Any) -> None:
        self.calls.append((name, args))
        if name in self.raise_on:
            raise self.raise_on[name]

    def names(self, include_reads: bool = False) -> list[str]:
        """Call names in order; by default only the control script's commands (not state
        reads, nor the speed slider: its own connection; see ``args("set_speed_slider")``)."""
        reads = {
            "is_connected", "async_status", "safety_status_bits", "robot_mode",
            "is_program_running", "tcp_pose", "joint_positions", "set_speed_slider",
        }
        return [n for n, _ in self.calls if include_reads or n not in reads]

    def args(self, name: str) -> list[tuple[Any, ...]]:
        return [a for n, a in self.calls if n == name]

    # --- link ----------------------------------------------------------------------------

    def connect(self) -> None:
        self._rec("connect")

    def disconnect(self) -> None:
        self._rec("disconnect")
        self.connected = False

    def abandon(self) -> None:
        self._rec("abandon")
        self.connected = False

    def control_connected(self) -> bool:
        return self.connected

    def receive_connected(self) -> bool:
        return self.connected

    def is_connected(self) -> bool:
        self._rec("is_connected")
        return self.connected

    def reconnect(self) -> bool:
        self._rec("reconnect")
        outcome = self.reconnect_results.pop(0) if self.reconnect_results else False
        if isinstance(outcome, Exception):
            raise outcome
        self.connected = bool(outcome)
        return bool(outcome)

    def reupload_script(self) -> bool:
        self._rec("reupload_script")
        self.program_running = True
        return True

    # --- control -------------------------------------------------------------------------

    def move_l(self, pose: Sequence[float], speed: float, acceleration: float) -> bool:
        self._rec("move_l", list(pose), speed, acceleration)
        return self.accept

    def move_l_path(self, path: Sequence[Sequence[float]]) -> bool:
        self._rec("move_l_path", [list(r) for r in path])
        return self.accept

    def move_j(self, q: Sequence[float], speed: float, acceleration: float) -> bool:
        self._rec("move_j", list(q), speed, acceleration)
        return self.accept

    def async_status(self) -> tuple[bool, int]:
        self._rec("async_status")
        if self.op_script:
            self.op = self.op_script.pop(0)
        return self.op

    def servo_l(self, pose: Sequence[float], time: float, lookahead: float, gain: float) -> bool:
        self._rec("servo_l", list(pose), time, lookahead, gain)
        return self.accept

    def servo_stop(self, deceleration: float) -> bool:
        self._rec("servo_stop", deceleration)
        return True

    def stop_l(self, deceleration: float) -> None:
        self._rec("stop_l", deceleration)

    def force_mode(self, task_frame, selection, wrench, frame_type, limits) -> bool:  # type: ignore[no-untyped-def]
        self._rec("force_mode", list(task_frame), list(selection), list(wrench), frame_type,
                  list(limits))
        return self.accept

    def force_mode_stop(self) -> bool:
        self._rec("force_mode_stop")
        return True

    def drop_control(self) -> None:
        self._rec("drop_control")

    def is_program_running(self) -> bool:
        self._rec("is_program_running")
        return self.program_running

    def set_watchdog(self, min_frequency: float) -> bool:
        self._rec("set_watchdog", min_frequency)
        return True

    def kick_watchdog(self) -> bool:
        self._rec("kick_watchdog")
        return True

    def set_speed_slider(self, fraction: float) -> bool:
        self._rec("set_speed_slider", fraction)
        return getattr(self, "slider_ok", True)

    # --- receive -------------------------------------------------------------------------

    def tcp_pose(self) -> list[float]:
        self._rec("tcp_pose")
        return list(self.pose)

    def joint_positions(self) -> list[float]:
        self._rec("joint_positions")
        return list(self.q)

    def safety_status_bits(self) -> int:
        self._rec("safety_status_bits")
        return self.safety_bits

    def robot_mode(self) -> int:
        self._rec("robot_mode")
        return self.mode

    def timestamp(self) -> float:
        """The controller's clock: a new package at every read unless ``data_frozen`` (a
        silent link that still looks connected)."""
        if not getattr(self, "data_frozen", False):
            self._stamp = getattr(self, "_stamp", 0.0) + 0.008
        return getattr(self, "_stamp", 0.0)


class FakeClock:
    """Time that moves only when a test says so."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t
