"""A Robotiq 2F-85 on a virtual serial line: a real pymodbus RTU server holding the gripper's
registers, with finger motion, object stalls and injectable faults.

Three pieces, each usable alone:

* :class:`GripperModel`: the gripper's behaviour in register terms (activation, go-to, a
  position that ramps to the request at the commanded speed, a stall on a simulated object with
  gOBJ = 2, fault codes). Thread-safe; time comes from ``clock`` and runs ``time_scale`` times
  faster than real so tests stay short.
* :class:`PtyNullModem`: two pseudo-terminals joined like a null-modem cable (a relay thread
  copies bytes between their masters), so both the server and the driver open ordinary serial
  device paths. It counts the bytes the driver sends and can be ``cut`` (drops everything), which
  is how a peer goes silent or a cable is pulled.
* :class:`GripperModbusPeer`: pymodbus's ``ModbusSerialServer`` (RTU framing, unit id 9 by
  default) on one end of the null modem, its registers driven by the model. Requests for other
  unit ids get no answer at all, as on a real RS-485 line. (pymodbus 3.16's ``SimCore`` raises
  KeyError for an unknown id instead of honouring ``ignore_missing_devices``, and answers with
  an exception reply; so a catch-all device takes those requests and the outgoing-packet hook
  drops every reply not from ``unit_id``.)

The register map lives in ``drivers.robotiq_gripper.registers``; the peer uses only its encode
and decode helpers, and models the motion on its own (own open/closed limits, own speed law), so
the driver's conversions are checked against independent numbers.
"""

from __future__ import annotations

import asyncio
import os
import select
import threading
import time
import tty
from collections.abc import Callable

from pymodbus import FramerType
from pymodbus.server import ModbusSerialServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.robotiq_gripper.registers import (
    ACTION_ADDRESS,
    STATUS_ADDRESS,
    STROKE,
    ActionRequest,
    GripperStatus,
    decode_request,
    encode_status,
)

FULL_STROKE_TIME = {0: 85 / 20, 255: 85 / 150}  # s for the whole stroke at rSP 0 and 255


class GripperModel:
    """The 2F-85's behaviour behind its registers.

    ``min_count``/``max_count``: where this unit's fingers really stop opening/closing (the
    software limits a calibration measures); ``activation_time``: s the activation takes;
    ``time_scale``: how much faster than real the model runs. Set ``object_width`` (m, opening
    at which a part blocks the fingers) and ``injected_fault`` (a gFLT code) from tests.
    """

    def __init__(
        self,
        min_count: int = 4,
        max_count: int = 227,
        activation_time: float = 1.0,
        time_scale: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.min_count, self.max_count = min_count, max_count
        self.activation_time, self.time_scale = activation_time, time_scale
        self.clock = clock
        self.lock = threading.Lock()
        self.object_width: float | None = None
        self.injected_fault = 0
        self.requests: list[ActionRequest] = []  # every action request written, in order
        self.status_reads = 0
        self._req = ActionRequest(act=False)
        self._act = self._sta = self._obj = 0
        self._flt = 0
        self._pos = float(min_count)
        self._activation_end: float | None = None
        self._last = clock()

    # --- geometry (the peer's own, independent of the driver's calibration) ----------------

    def count_at(self, width: float) -> float:
        """Position count where the opening is ``width`` (m) on this unit."""
        return self.max_count - width / STROKE * (self.max_count - self.min_count)

    def width_at(self, count: float) -> float:
        """Opening (m) at position count ``count`` on this unit."""
        return (self.max_count - count) / (self.max_count - self.min_count) * STROKE

    # --- registers -----------------------------------------------------------------------

    def write(self, registers: list[int]) -> None:
        """Function 16 on 0x03E8: a new action request."""
        with self.lock:
            self._advance()
            req = decode_request(registers)
            self.requests.append(req)
            prev, self._req = self._req, req
            if not req.act:  # reset: clears the activation and the request-caused faults
                self._act = self._sta = self._obj = 0
                self._flt = 0x07 if req.gto else 0  # a go-to without rACT is refused
                self._activation_end = None
                return
            if not prev.act:  # rising rACT: activation starts
                self._act, self._sta = 1, 1
                self._activation_end = self.clock() + self.activation_time / self.time_scale
            if req.gto and self._sta != 3:
                self._flt = 0x07 if not self._act else 0x05
            elif req.gto:
                self._flt = 0
                self._obj = 0

    def status(self) -> GripperStatus:
        """The status registers now (the motion advanced to this instant)."""
        with self.lock:
            self._advance()
            self.status_reads += 1
            moving = self._req.gto and self._sta == 3 and self._obj == 0
            current = 20 if moving else (self._req.force // 4 if self._obj == 2 else 0)
            return GripperStatus(
                act=self._act, gto=int(self._req.gto), sta=self._sta, obj=self._obj,
                flt=self.injected_fault or self._flt, kflt=0, pr=self._req.position,
                po=int(round(self._pos)), cu=current,
            )

    def _advance(self) -> None:
        now = self.clock()
        dt, self._last = (now - self._last) * self.time_scale, now
        if self._activation_end is not None and now >= self._activation_end:
            self._activation_end = None
            self._sta = 3
            self._pos = float(self.min_count)
        if not (self._req.gto and self._sta == 3 and self._obj == 0) or self.injected_fault:
            return
        target = float(min(max(self._req.position, self.min_count), self.max_count))
        full = FULL_STROKE_TIME[0] + (FULL_STROKE_TIME[255] - FULL_STROKE_TIME[0]) * (
            self._req.speed / 255)
        step = (self.max_count - self.min_count) / full * dt
        closing = target > self._pos
        stop_at = target
        if closing and self.object_width is not None:
            blocked = self.count_at(self.object_width)
            if self._pos <= blocked < target:
                stop_at = blocked
        if abs(stop_at - self._pos) <= step:
            self._pos = stop_at
            self._obj = 3 if stop_at == target else 2
        else:
            self._pos += step if closing else -step


class PtyNullModem:
    """Two pseudo-terminals joined by a relay thread: ``driver_path`` <-> ``peer_path``."""

    def __init__(self) -> None:
        self._ma, self._sa = os.openpty()
        self._mb, self._sb = os.openpty()
        for fd in (self._sa, self._sb):
            tty.setraw(fd)  # no echo or line editing before pyserial opens the port
        self.driver_path = os.ttyname(self._sa)
        self.peer_path = os.ttyname(self._sb)
        self.cut = False  #: drop every byte in both directions (a pulled cable)
        self.bytes_to_peer = 0  #: bytes the driver sent (counted even while cut)
        self._wake_r, self._wake_w = os.pipe()
        self._stop = False
        self._thread = threading.Thread(target=self._relay, name="pty-null-modem", daemon=True)
        self._thread.start()

    def _relay(self) -> None:
        pairs = {self._ma: self._mb, self._mb: self._ma}
        while not self._stop:
            ready, _, _ = select.select([self._ma, self._mb, self._wake_r], [], [], 0.5)
            for fd in ready:
                if fd == self._wake_r:
                    return
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    continue
                if fd == self._ma:
                    self.bytes_to_peer += len(data)
                if not self.cut:
                    os.write(pairs[fd], data)

    def close(self) -> None:
        """Stop the relay and close all four descriptors."""
        self._stop = True
        os.write(self._wake_w, b"x")
        self._thread.join(timeout=2.0)
        for fd in (self._ma, self._sa, self._mb, self._sb, self._wake_r, self._wake_w):
            os.close(fd)


class GripperModbusPeer:
    """A pymodbus RTU serial server on ``port`` answering as a 2F-85 with id ``unit_id``.

    The server runs its own asyncio loop in a thread; :meth:`stop` shuts it down and joins.
    Both function 3 and 4 read the status (the registers are one shared block, as on the
    gripper), function 16 writes the action request.
    """

    def __init__(self, port: str, model: GripperModel, unit_id: int = 9,
                 baudrate: int = 115200) -> None:
        self.model, self.unit_id = model, unit_id
        self.function_codes: list[int] = []  #: requests served for ``unit_id``, in order
        self.dropped_replies = 0  #: requests for other unit ids, left unanswered

        def registers() -> list[SimData]:
            return [SimData(ACTION_ADDRESS, count=3, values=0, datatype=DataType.REGISTERS),
                    SimData(STATUS_ADDRESS, count=3, values=0, datatype=DataType.REGISTERS)]

        self._devices = [SimDevice(id=unit_id, simdata=registers(), action=self._action),
                         SimDevice(id=0, simdata=registers())]  # any other id; never answers
        self._port, self._baudrate = port, baudrate
        self._server: ModbusSerialServer | None = None
        self._loop = asyncio.new_event_loop()
        self._error: BaseException | None = None
        started = threading.Event()
        self._thread = threading.Thread(target=self._serve, args=(started,),
                                        name="gripper-modbus-peer", daemon=True)
        self._thread.start()
        if not started.wait(5.0) or self._error is not None:
            raise RuntimeError(f"the gripper Modbus peer did not start: {self._error}")

    async def _listen(self) -> None:
        # pymodbus binds its server to the running loop, so it is built inside it.
        self._server = ModbusSerialServer(
            self._devices, framer=FramerType.RTU, port=self._port, baudrate=self._baudrate,
            ignore_missing_devices=True, trace_packet=self._outgoing,
        )
        await self._server.serve_forever(background=True)

    def _serve(self, started: threading.Event) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._listen())
        except BaseException as exc:  # reported by __init__
            self._error = exc
            started.set()
            return
        started.set()
        self._loop.run_forever()

    def _outgoing(self, sending: bool, packet: bytes) -> bytes:
        """Drop replies for other unit ids: on RS-485 only the addressed device talks."""
        if sending and packet and packet[0] != self.unit_id:
            self.dropped_replies += 1
            return b""
        return packet

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: list[int] | list[bool] | None) -> None:
        self.function_codes.append(function_code)
        if function_code == 16 and address == ACTION_ADDRESS and set_values is not None:
            self.model.write([int(v) for v in set_values])
        elif function_code in (3, 4) and address <= STATUS_ADDRESS < address + count:
            offset = STATUS_ADDRESS - start_address
            registers[offset:offset + 3] = encode_status(self.model.status())
        return None

    def stop(self) -> None:
        """Shut the server down, stop its loop and join its thread."""
        if self._server is not None:
            fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop)
            fut.result(timeout=5.0)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5.0)
        self._loop.close()
