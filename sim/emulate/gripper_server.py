"""A Robotiq 2F-85 on its real wires: a Modbus RTU slave on a pseudo-terminal and the gripper
URCap's text socket, both in front of one gripper model whose fingers are a backend (the twin's).

Written from Robotiq's 2F-85/2F-140 instruction manual ("Control": the register map, the
function codes, the status semantics) and, for the socket, from the URCap's own URScript and the
clients that read it (ur_rtde's ``robotiq_gripper.py``); not from this project's driver, so the
driver is checked against an independent reading of the same documents.

Backend interface (:class:`FingerBackend`), what the fingers must offer::

    stroke: float                      # m, the largest opening (0.085 on a 2F-85)
    command(width, speed, force)       # start moving to an opening of width m, each finger at
                                       #   speed m/s, pressing with at most force N; returns at
                                       #   once; a new command replaces the running one
    width() -> float                   # m, the opening now
    moving() -> bool                   # the last command runs (neither arrived nor stalled)
    object_detected() -> bool          # the last command stalled on something

:class:`TwinFingers` implements it on the twin's :class:`sim.gripper.SimGripper`. All methods are
called from the servers' threads; the twin's are safe for that (see the class).
:class:`LinearFingers` implements it without physics (fingers that move at the commanded speed
and stop on an object of a set width), for the protocol alone: the driver tests' gripper.

Pieces, usable alone:

* :class:`Gripper2F85`: the gripper's behaviour in register terms (activation, go-to, object
  detection, request echo, faults 0x05/0x07 and injected ones), thread-safe;
* :class:`ModbusRtuServer`: a hand-written RTU slave (unit 9 by default) on the master side of an
  ``os.openpty()`` pair; :attr:`ModbusRtuServer.port` is the slave path a driver opens like a USB
  RS-485 adapter. Frames for another unit get no answer (a shared RS-485 line); a broadcast
  (unit 0) write is executed without an answer, as Modbus specifies;
* :class:`UrcapServer`: the URCap's socket (TCP 63352 by default): ``SET VAR v [VAR v ...]``
  answered with the three bytes ``ack`` and no newline, ``GET VAR`` with ``VAR v\\n``, anything it
  does not know with ``?`` (no newline).

Wire faults: :meth:`ModbusRtuServer.pull_cable` / :meth:`UrcapServer.pull_cable` make the server
read and drop everything (nothing answers, as with the cable out) until ``restore()``;
:meth:`Gripper2F85.inject_fault` puts a gFLT code in the status until the next reset.

What arrived, for tests: :attr:`Gripper2F85.requests` (every action request as the gripper read
it), :attr:`ModbusRtuServer.functions` (the function codes it served), its byte and frame counts,
:attr:`UrcapServer.lines` (every command line).
"""

from __future__ import annotations

import os
import select
import socket
import socketserver
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from sim.emulate.rtu import LineDevice, close_fds, crc_ok, open_pty, with_crc

# --- the register map (manual, "Control") -------------------------------------------------
ACTION_ADDRESS = 0x03E8  #: robot output (action request) bytes 0..5: three registers
STATUS_ADDRESS = 0x07D0  #: robot input (gripper status) bytes 0..5: three registers
REGISTERS = 3
DEFAULT_UNIT_ID = 9  #: factory slave id
DEFAULT_BAUDRATE = 115200  #: factory line settings: 115200 bit/s, 8N1
URCAP_PORT = 63352  #: the URCap's socket on the UR controller

# Action request byte 0 bits, gripper status byte 0 bits.
_ACT, _GTO, _ATR, _ARD = 0, 3, 4, 5
# gSTA, gOBJ values.
STA_RESET, STA_ACTIVATING, STA_ACTIVE = 0, 1, 3
OBJ_MOVING, OBJ_CONTACT_OPENING, OBJ_CONTACT_CLOSING, OBJ_AT_REQUEST = 0, 1, 2, 3
# gFLT codes the model raises itself.
FLT_ACTION_DELAYED = 0x05  #: a go-to while the activation runs: done once it completes
FLT_NOT_ACTIVATED = 0x07  #: a go-to with rACT = 0

# The 2F-85's specification sheet: finger speed 20..150 mm/s, grip force 20..235 N over 0..255.
SPEED_RANGE = (0.020, 0.150)  #: m/s
FORCE_RANGE = (20.0, 235.0)  #: N
ACTIVATION_SPEED = 0.150  #: m/s, the fingers' speed through the activation stroke
ACTIVATION_FORCE = 20.0  #: N, the gentlest force, for the activation stroke


@runtime_checkable
class FingerBackend(Protocol):
    """The fingers behind the emulated gripper (see the module doc)."""

    stroke: float

    def command(self, width: float, speed: float, force: float) -> None: ...

    def width(self) -> float: ...

    def moving(self) -> bool: ...

    def object_detected(self) -> bool: ...


class TwinFingers:
    """:class:`FingerBackend` on the twin's gripper.

    PyBullet is driven by the loop that steps the world, so nothing here calls it from a server
    thread: :meth:`command` only records the newest command, and a hook the world runs after each
    control step hands it to the :class:`sim.gripper.SimGripper` and takes a snapshot of the
    fingers that the queries read. A command not yet handed over counts as moving. The fingers
    open with the twin's own opening force; ``force`` applies to closing (as on the 2F-85, whose
    force setting limits the grip).
    """

    def __init__(self, gripper, world) -> None:  # type: ignore[no-untyped-def]
        """``gripper``: the twin's ``SimGripper``; ``world``: the ``SimWorld`` it lives in."""
        self._gripper = gripper
        self.stroke = float(gripper.stroke)
        self._lock = threading.Lock()
        self._pending: tuple[float, float, float] | None = None
        self._width = float(gripper.true_width())
        self._moving = bool(gripper.moving())
        self._object = bool(gripper.object_detected())
        world.after_step(self._sync)

    def command(self, width: float, speed: float, force: float) -> None:
        with self._lock:
            self._pending = (float(width), float(speed), float(force))

    def width(self) -> float:
        with self._lock:
            return self._width

    def moving(self) -> bool:
        with self._lock:
            return self._pending is not None or self._moving

    def object_detected(self) -> bool:
        with self._lock:
            return self._pending is None and self._object

    def _sync(self) -> None:
        """On the stepping thread: apply the newest command, snapshot the fingers."""
        with self._lock:
            pending, self._pending = self._pending, None
        g = self._gripper
        if pending is not None:
            width, speed, force = pending
            if width >= g.true_width():
                g.open(width, speed)
            else:
                g.close(force, speed, width)
        snapshot = (float(g.true_width()), bool(g.moving()), bool(g.object_detected()))
        with self._lock:
            if self._pending is None:
                self._width, self._moving, self._object = snapshot
            else:  # a newer command arrived meanwhile: keep it pending, update the width only
                self._width = snapshot[0]


class LinearFingers:
    """:class:`FingerBackend` without physics: the opening changes at twice the commanded finger
    speed (both fingers move) and, closing past an object of :attr:`object_width` m, stops on
    it. ``clock``: monotonic seconds (a faster clock runs the fingers faster: short tests).
    :attr:`commands` records every command (width, speed, force)."""

    stroke = 0.085

    def __init__(self, width: float = 0.085, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.object_width: float | None = None
        self.commands: list[tuple[float, float, float]] = []
        self._lock = threading.Lock()
        self._w0, self._t0, self._target, self._rate = width, clock(), width, 0.0
        self._stop_at = width

    def command(self, width: float, speed: float, force: float) -> None:
        with self._lock:
            now = self.clock()
            w = self._at(now)
            self.commands.append((width, speed, force))
            self._w0, self._t0, self._target = w, now, width
            self._rate = 2 * speed
            self._stop_at = width
            ow = self.object_width
            if ow is not None and width < w and width < ow <= w:
                self._stop_at = ow

    def _at(self, now: float) -> float:
        span = self._stop_at - self._w0
        moved = self._rate * (now - self._t0)
        return self._stop_at if abs(span) <= moved else self._w0 + moved * (1 if span > 0 else -1)

    def width(self) -> float:
        with self._lock:
            return self._at(self.clock())

    def moving(self) -> bool:
        with self._lock:
            return self._at(self.clock()) != self._stop_at

    def object_detected(self) -> bool:
        with self._lock:
            return self._stop_at != self._target and self._at(self.clock()) == self._stop_at


def _bit(byte: int, n: int) -> int:
    return byte >> n & 1


@dataclass(frozen=True)
class ActionRequest:
    """One action request as the gripper reads its six output bytes (manual, "Control")."""

    act: bool
    gto: bool
    atr: bool
    ard: bool
    position: int  #: rPR
    speed: int  #: rSP
    force: int  #: rFR

    @classmethod
    def of(cls, out: bytes) -> ActionRequest:
        return cls(act=bool(_bit(out[0], _ACT)), gto=bool(_bit(out[0], _GTO)),
                   atr=bool(_bit(out[0], _ATR)), ard=bool(_bit(out[0], _ARD)),
                   position=out[3], speed=out[4], force=out[5])


class Gripper2F85:
    """The 2F-85's behaviour behind its six output and six input bytes (thread-safe).

    ``open_count`` / ``closed_count``: the position counts (gPO) where this unit's fingers stop
    fully open and fully closed; a real unit stops a few counts inside 0..255 and each differs a
    little, which is why drivers calibrate. ``clock``: monotonic seconds (for the fault age only).

    Behaviour, after the manual: a rising rACT starts the activation (gSTA 1) during which the
    fingers run through their stroke (close fully, then open fully), then gSTA 3; rACT 0 resets
    (gACT, gSTA, gOBJ and the faults clear; the fingers stay). With the gripper active, a rising
    rGTO or a new position, speed or force while rGTO is 1 starts a motion; rGTO 0 stops the
    fingers where they are. gOBJ is 0 while the fingers move, 1/2 when they stopped on something
    while opening/closing, 3 at the request (also after an object is lost). A go-to with rACT 0
    raises fault 0x07; during the activation, 0x05, and the go-to runs once the activation
    completes. gPR echoes rPR; gCU is an illustrative finger current (see :meth:`_current`).
    """

    def __init__(
        self,
        fingers: FingerBackend,
        open_count: int = 3,
        closed_count: int = 228,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not 0 <= open_count < closed_count <= 255:
            raise ValueError(f"need 0 <= open_count < closed_count <= 255, got {open_count}, "
                             f"{closed_count}")
        self.fingers = fingers
        self.open_count, self.closed_count = open_count, closed_count
        self.clock = clock
        self.lock = threading.RLock()
        self.output = bytearray(6)  #: the action request bytes as last written
        self.writes = 0  #: action requests received (any path)
        self.reads = 0  #: status reads served
        self.requests: list[ActionRequest] = []  #: every action request written, in order
        self._act = self._sta = self._obj = self._flt = 0
        self._injected = 0
        self._leg: str | None = None  # activation stroke: "closing", then "opening"
        self._delayed = False  # a go-to arrived during the activation
        self._motion = False  # a go-to was handed to the fingers (gOBJ follows them)
        self._closing = False  # ... towards a smaller opening

    # --- geometry of this unit --------------------------------------------------------------

    def width_of(self, count: int) -> float:
        """Opening (m) the fingers reach for position request ``count`` (clipped at the stops)."""
        c = min(max(count, self.open_count), self.closed_count)
        return (self.closed_count - c) / (self.closed_count - self.open_count) * self.fingers.stroke

    def count_of(self, width: float) -> int:
        """Position count gPO for an opening of ``width`` (m)."""
        frac = min(max(width / self.fingers.stroke, 0.0), 1.0)
        return int(round(self.closed_count - frac * (self.closed_count - self.open_count)))

    # --- the wire's view ---------------------------------------------------------------------

    def write_output(self, offset: int, data: bytes) -> None:
        """Bytes ``data`` written into the action request from byte ``offset`` (0..5)."""
        if offset < 0 or offset + len(data) > 6:
            raise ValueError("outside the action request bytes")
        with self.lock:
            old = bytes(self.output)
            self.output[offset:offset + len(data)] = data
            self.writes += 1
            self.requests.append(ActionRequest.of(self.output))
            self._on_request(old, bytes(self.output))

    def output_bytes(self) -> bytes:
        with self.lock:
            return bytes(self.output)

    def input_bytes(self) -> bytes:
        """The six status bytes now (gripper status, reserved, fault, gPR, gPO, gCU)."""
        with self.lock:
            self._advance()
            self.reads += 1
            out = self.output
            status = (self._act << _ACT | _bit(out[0], _GTO) << _GTO | self._sta << 4
                      | self._obj << 6)
            fault = self._injected or self._flt
            return bytes([status, 0, fault & 0x0F, out[3], self.count_of(self.fingers.width()),
                          self._current()])

    def inject_fault(self, code: int) -> None:
        """Show gFLT ``code`` (1..15) until the next reset (rACT 0), stopping any motion."""
        if not 0 < code <= 0x0F:
            raise ValueError(f"gFLT is a 4-bit code 1..15, got {code}")
        with self.lock:
            self._injected = code
            if self._motion or self._leg:
                self.fingers.command(self.fingers.width(), SPEED_RANGE[1], FORCE_RANGE[0])
                self._motion, self._leg = False, None

    # --- behaviour ---------------------------------------------------------------------------

    def _on_request(self, old: bytes, new: bytes) -> None:
        act, gto = _bit(new[0], _ACT), _bit(new[0], _GTO)
        if not act:
            if _bit(old[0], _ACT) or self._act:
                self._act = self._sta = self._obj = 0
                self._leg, self._delayed, self._motion = None, False, False
                self._injected = 0
            self._flt = FLT_NOT_ACTIVATED if gto else 0
            return
        if self._injected:
            return  # a faulted gripper waits for a reset
        if not _bit(old[0], _ACT):  # rising rACT: the activation stroke
            self._act, self._sta, self._obj, self._flt = 1, STA_ACTIVATING, 0, 0
            self._leg = "closing"
            self.fingers.command(0.0, ACTIVATION_SPEED, ACTIVATION_FORCE)
        if not gto:
            self._delayed = False
            if self._motion:  # rGTO 0 stops the fingers where they are
                self.fingers.command(self.fingers.width(), SPEED_RANGE[1], FORCE_RANGE[0])
                self._motion = False
            return
        if self._sta != STA_ACTIVE:
            self._flt, self._delayed = FLT_ACTION_DELAYED, True
            return
        rising = not _bit(old[0], _GTO)
        if rising or old[3:6] != new[3:6] or not self._motion:
            self._flt = 0
            self._go()

    def _go(self) -> None:
        out = self.output
        target = self.width_of(out[3])
        speed = SPEED_RANGE[0] + out[4] / 255 * (SPEED_RANGE[1] - SPEED_RANGE[0])
        force = FORCE_RANGE[0] + out[5] / 255 * (FORCE_RANGE[1] - FORCE_RANGE[0])
        self._closing = target < self.fingers.width()
        self.fingers.command(target, speed, force)
        self._motion, self._obj = True, OBJ_MOVING

    def _advance(self) -> None:
        """Follow the fingers: the activation legs, then gOBJ of the running go-to."""
        f = self.fingers
        if self._leg is not None:
            if f.moving():
                return
            if self._leg == "closing":
                self._leg = "opening"
                f.command(f.stroke, ACTIVATION_SPEED, ACTIVATION_FORCE)
                return
            self._leg, self._sta = None, STA_ACTIVE
            if self._delayed and _bit(self.output[0], _GTO):
                self._delayed, self._flt = False, 0
                self._go()
            return
        if self._motion and self._sta == STA_ACTIVE:
            if f.moving():
                self._obj = OBJ_MOVING
            elif f.object_detected():
                self._obj = OBJ_CONTACT_CLOSING if self._closing else OBJ_CONTACT_OPENING
            else:
                self._obj = OBJ_AT_REQUEST

    def _current(self) -> int:
        """gCU (x 10 mA): the manual gives the unit only. Illustrative values: 0 at rest, about
        0.25 A while moving, and in a grip a current growing with the force setting."""
        if self._leg is not None or (self._motion and self._obj == OBJ_MOVING):
            return 25
        if self._obj in (OBJ_CONTACT_OPENING, OBJ_CONTACT_CLOSING):
            return 5 + self.output[5] * 55 // 255
        return 0

    # --- URCap variables (the socket's names for the same bytes) ----------------------------

    def set_vars(self, pairs: list[tuple[str, int]]) -> bool:
        """Write URCap variables as one action request (the pairs in order, then one write, so
        ``SET POS p SPE s FOR f GTO 1`` starts one motion); False, and nothing written, if a
        name is not settable or a value is out of range."""
        bits = {"ACT": _ACT, "GTO": _GTO, "ATR": _ATR, "ARD": _ARD}
        places = {"POS": 3, "SPE": 4, "FOR": 5}
        with self.lock:
            new = bytearray(self.output)
            for name, value in pairs:
                if name in bits and value in (0, 1):
                    new[0] = new[0] & ~(1 << bits[name]) | value << bits[name]
                elif name in places and 0 <= value <= 255:
                    new[places[name]] = value
                else:
                    return False
            self.write_output(0, bytes(new))
            return True

    def get_var(self, name: str) -> int | None:
        """Read one URCap variable (None: not one the URCap knows)."""
        with self.lock:
            st = self.input_bytes()
            out = self.output
            values = {
                "ACT": _bit(st[0], _ACT), "GTO": _bit(st[0], _GTO), "STA": st[0] >> 4 & 3,
                "OBJ": st[0] >> 6 & 3, "FLT": st[2] & 0x0F, "PRE": st[3], "POS": st[4],
                "ATR": _bit(out[0], _ATR), "ARD": _bit(out[0], _ARD), "SPE": out[4],
                "FOR": out[5],
            }
        return values.get(name)


# --- Modbus RTU --------------------------------------------------------------------------------

ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE = 0x01, 0x02, 0x03
#: how long a pause ends a frame here: RTU's 3.5 character times are 0.3 ms at 115200 bit/s, but
#: a pseudo-terminal delivers a frame in one piece and scheduling jitter is larger than that
FRAME_GAP = 0.02


def _frame_length(buf: bytes | bytearray) -> int | None:
    """Length of the request at the start of ``buf`` by its function code (None: not yet
    known, or a function whose length is not fixed here)."""
    if len(buf) < 2:
        return None
    fc = buf[1]
    if fc in (3, 4, 6):
        return 8
    if fc == 16:
        return 9 + buf[6] if len(buf) >= 7 else None
    if fc == 23:
        return 13 + buf[10] if len(buf) >= 11 else None
    return None


class ModbusRtuServer(LineDevice):
    """The 2F-85's Modbus RTU slave on a pseudo-terminal (start it; point a driver at
    :attr:`port`).

    Function codes (manual): 3 and 4 read registers (the status from 0x07D0, also the action
    request from 0x03E8), 6 and 16 write the action request, 23 writes then reads in one
    request. Exception replies: 01 for another function, 02 for an address outside the two
    three-register blocks, 03 for a bad count. ``turnaround``: s between the request's last byte
    and the reply (the gripper's processing; the line time at ``baudrate`` is added).
    """

    def __init__(self, device: Gripper2F85, unit_id: int = DEFAULT_UNIT_ID,
                 baudrate: int = DEFAULT_BAUDRATE, turnaround: float = 0.001) -> None:
        super().__init__("emu-2f85-rtu")
        self.device, self.unit_id = device, unit_id
        self.baudrate, self.turnaround = baudrate, turnaround
        self._master, self._slave, self.port = open_pty()
        self.requests = 0  #: valid frames for this unit (answered or broadcast)
        self.functions: Counter[int] = Counter()  #: those frames by function code
        self.crc_errors = 0  #: frames dropped for a bad CRC
        self.other_units = 0  #: valid frames for another unit, left unanswered
        self.received_bytes = 0  #: every byte that reached the line's end (cable out or not)
        self.dropped_bytes = 0  #: bytes read and dropped while the cable was out

    def _close_line(self) -> None:
        """Both ends of the pseudo-terminal."""
        close_fds(self._master, self._slave)

    # --- the line ----------------------------------------------------------------------------

    def _run(self) -> None:
        buf = bytearray()
        last = time.monotonic()
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.01)
            now = time.monotonic()
            if buf and now - last > FRAME_GAP:
                buf.clear()  # a pause ends a frame: whatever is left was not a whole one
            if not ready:
                continue
            try:
                data = os.read(self._master, 4096)
            except (BlockingIOError, OSError):
                continue
            last = now
            self.received_bytes += len(data)
            if self._cut.is_set():
                self.dropped_bytes += len(data)
                buf.clear()
                continue
            buf += data
            self._frames(buf)

    def _frames(self, buf: bytearray) -> None:
        while True:
            n = _frame_length(buf)
            if n is None:
                if len(buf) >= 2 and buf[1] not in (3, 4, 6, 16, 23) and len(buf) >= 4:
                    # Unknown function: the whole pending chunk is one frame if its CRC holds.
                    if crc_ok(buf):
                        frame = bytes(buf)
                        buf.clear()
                        self._handle(frame)
                        continue
                return
            if len(buf) < n:
                return
            frame = bytes(buf[:n])
            if not crc_ok(frame):
                self.crc_errors += 1
                del buf[:1]  # resynchronise on the next byte
                continue
            del buf[:n]
            self._handle(frame)

    def _handle(self, frame: bytes) -> None:
        unit, fc = frame[0], frame[1]
        if unit not in (0, self.unit_id):
            self.other_units += 1
            return
        self.requests += 1
        self.functions[fc] += 1
        reply = self._reply(fc, frame[2:-2])
        if unit == 0 or reply is None:
            return  # a broadcast is never answered
        out = with_crc(bytes([self.unit_id]) + reply)
        time.sleep(self.turnaround + len(out) * 10 / self.baudrate)
        if self._cut.is_set():
            return
        try:
            os.write(self._master, out)
        except OSError:
            pass

    def _reply(self, fc: int, pdu: bytes) -> bytes | None:
        """The reply PDU (function code onwards) to request ``pdu`` (after the function code)."""
        def error(code: int) -> bytes:
            return bytes([fc | 0x80, code])

        if fc in (3, 4):
            addr, count = int.from_bytes(pdu[0:2], "big"), int.from_bytes(pdu[2:4], "big")
            data = self._read(addr, count)
            if isinstance(data, int):
                return error(data)
            return bytes([fc, len(data)]) + data
        if fc == 6:
            addr = int.from_bytes(pdu[0:2], "big")
            err = self._write(addr, 1, pdu[2:4])
            return error(err) if err else bytes([fc]) + pdu[:4]
        if fc == 16:
            addr, count = int.from_bytes(pdu[0:2], "big"), int.from_bytes(pdu[2:4], "big")
            if pdu[4] != 2 * count or len(pdu) != 5 + 2 * count:
                return error(ILLEGAL_VALUE)
            err = self._write(addr, count, pdu[5:])
            return error(err) if err else bytes([fc]) + pdu[:4]
        if fc == 23:
            raddr, rcount = int.from_bytes(pdu[0:2], "big"), int.from_bytes(pdu[2:4], "big")
            waddr, wcount = int.from_bytes(pdu[4:6], "big"), int.from_bytes(pdu[6:8], "big")
            if pdu[8] != 2 * wcount or len(pdu) != 9 + 2 * wcount:
                return error(ILLEGAL_VALUE)
            err = self._write(waddr, wcount, pdu[9:])
            if err:
                return error(err)
            data = self._read(raddr, rcount)
            if isinstance(data, int):
                return error(data)
            return bytes([fc, len(data)]) + data
        return error(ILLEGAL_FUNCTION)

    def _read(self, addr: int, count: int) -> bytes | int:
        if not 1 <= count <= 125:
            return ILLEGAL_VALUE
        for base, source in ((STATUS_ADDRESS, self.device.input_bytes),
                             (ACTION_ADDRESS, self.device.output_bytes)):
            if base <= addr and addr + count <= base + REGISTERS:
                start = 2 * (addr - base)
                return source()[start:start + 2 * count]
        return ILLEGAL_ADDRESS

    def _write(self, addr: int, count: int, data: bytes) -> int:
        if not 1 <= count <= 123:
            return ILLEGAL_VALUE
        if not (ACTION_ADDRESS <= addr and addr + count <= ACTION_ADDRESS + REGISTERS):
            return ILLEGAL_ADDRESS
        self.device.write_output(2 * (addr - ACTION_ADDRESS), data)
        return 0


# --- the URCap socket --------------------------------------------------------------------------

#: The variables the URCap's socket knows (its URScript's names).
URCAP_VARS = ("ACT", "GTO", "ATR", "ARD", "FOR", "SPE", "OBJ", "STA", "FLT", "POS", "PRE")
ACK = b"ack"
UNKNOWN = b"?"


class UrcapServer:
    """The gripper URCap's socket in front of ``device`` on ``(host, port)`` (port 0: a free one;
    :attr:`port` tells which). Starts serving at once; :meth:`stop` joins.

    Commands end with a newline (``\\r`` tolerated). ``SET`` applies its pairs in the order given,
    each as the URCap writes a variable to the gripper, and answers ``ack`` (three bytes, no
    newline, which is what the URCap's own script reads back with ``socket_read_byte_list(3)``)
    after writing them to the gripper as one request; a pair it cannot apply answers ``?`` and
    none is applied. ``GET VAR``
    answers ``VAR value\\n`` (POS is the finger position gPO, PRE the request echo gPR). ``SID``
    (the gripper's id on the URCap's bus) is accepted and ignored.
    """

    def __init__(self, device: Gripper2F85, host: str = "127.0.0.1", port: int = URCAP_PORT
                 ) -> None:
        self.device = device
        self.lines: list[str] = []  #: every command line received
        self.connections = 0
        self._cut = threading.Event()
        self._lock = threading.Lock()
        self._conns: list[socket.socket] = []
        server = self

        class Handler(socketserver.BaseRequestHandler):
            def handle(self) -> None:
                server._serve(self.request)

        class Server(socketserver.ThreadingTCPServer):
            allow_reuse_address = True
            daemon_threads = True

        self._server = Server((host, port), Handler)
        self.host, self.port = self._server.server_address[:2]
        self._thread = threading.Thread(target=self._server.serve_forever,
                                        kwargs={"poll_interval": 0.05}, name="emu-urcap",
                                        daemon=True)
        self._thread.start()

    def pull_cable(self) -> None:
        """Read and drop every command, answer nothing, until :meth:`restore`."""
        self._cut.set()

    def restore(self) -> None:
        self._cut.clear()

    def stop(self) -> None:
        """Stop serving, drop the connections, close the socket, join the accept thread."""
        self._server.shutdown()
        with self._lock:
            for conn in self._conns:
                try:
                    conn.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
        self._server.server_close()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> UrcapServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _serve(self, conn: socket.socket) -> None:
        with self._lock:
            self.connections += 1
            self._conns.append(conn)
        buf = b""
        try:
            while True:
                chunk = conn.recv(1024)
                if not chunk:
                    return
                buf += chunk
                while b"\n" in buf:
                    raw, buf = buf.split(b"\n", 1)
                    line = raw.decode("ascii", "replace").strip()
                    if not line:
                        continue
                    with self._lock:
                        self.lines.append(line)
                    if self._cut.is_set():
                        continue
                    conn.sendall(self.answer(line))
        except OSError:
            return
        finally:
            with self._lock:
                if conn in self._conns:
                    self._conns.remove(conn)

    def answer(self, line: str) -> bytes:
        """The URCap's reply bytes to one command line."""
        words = line.split()
        if len(words) >= 3 and words[0] == "SET" and len(words) % 2 == 1:
            pairs = []
            for name, value in zip(words[1::2], words[2::2], strict=True):
                if not value.isdigit():
                    return UNKNOWN
                if name != "SID":
                    pairs.append((name, int(value)))
            return ACK if not pairs or self.device.set_vars(pairs) else UNKNOWN
        if len(words) == 2 and words[0] == "GET" and words[1] in URCAP_VARS:
            value = self.device.get_var(words[1])
            if value is not None:
                return f"{words[1]} {value}\n".encode("ascii")
        return UNKNOWN
