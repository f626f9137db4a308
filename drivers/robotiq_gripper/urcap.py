"""The 2F-85 through the Robotiq gripper URCap's socket on the UR controller (TCP 63352).

When the gripper hangs off the UR5's tool connector, the URCap owns the serial link and offers
a text protocol instead: commands end with a newline; ``SET VAR value [VAR value ...]`` is
answered with the three bytes ``ack`` and **no newline** (the URCap's own script reads exactly
three bytes back, and ur_rtde's client compares the reply with ``b"ack"``), ``GET VAR`` with
``VAR value`` and a newline, and a command or variable the URCap does not know with ``?``. The
variables are the register map's under the URCap's names: ACT, GTO, ATR, ARD, FOR, SPE, POS to
set; ACT, GTO, STA, OBJ, FLT, PRE (the request echo) and POS (the position) to read. The finger
current (gCU) is not among them, so a status over this socket has none (``cu`` is None).

This transport maps one :class:`ActionRequest` onto one ``SET`` line and a status onto a few
``GET`` lines. A ``?`` is an answer, not a lost reply: it fails that request at once with a
:class:`DeviceError` naming the command (asking again would get the same answer).

A go-to is sent as ``SET POS p SPE s FOR f ... GTO 1`` in one line: the URCap applies the
variables in the order given, so the target is in place before the motion starts.

The socket only exists while the URCap runs on the controller (Polyscope with the gripper
installed), and the controller's firewall must let the cell's PC reach port 63352.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable

from drivers.health import DeviceError
from drivers.robotiq_gripper.registers import URCAP_PORT, ActionRequest, GripperStatus
from drivers.robotiq_gripper.transport import DEVICE, TransientError, with_retries

STATUS_VARS = ("ACT", "GTO", "STA", "OBJ", "FLT", "PRE", "POS")
ACK = b"ack"
UNKNOWN = b"?"
_BLANK = b" \t\r\n"


class UrcapSocketTransport:
    """:class:`GripperTransport` over the URCap's text socket.

    ``host``: the UR controller; ``port``: 63352; ``timeout``: s for connecting and for each
    reply; ``retries``: extra tries (each after reconnecting) when the socket fails or a reply
    does not come; ``backoff_first``: s before the first retry (doubling). Thread-safe.
    """

    kind = "urcap-socket"

    def __init__(
        self,
        host: str,
        port: int = URCAP_PORT,
        timeout: float = 0.5,
        retries: int = 2,
        backoff_first: float = 0.05,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.host, self.port = host, port
        self.timeout, self.retries, self.backoff_first = timeout, retries, backoff_first
        self.address = f"{host}:{port} (URCap socket)"
        self._sleep = sleep
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._buf = b""

    # --- link ------------------------------------------------------------------------------

    def connect(self) -> None:
        """Open the socket (bounded tries); a refused or unreachable host is a DeviceError."""
        with self._lock:
            with_retries(self._open, "cannot connect", self.address, self.retries,
                         self.backoff_first, self._sleep)

    def _open(self) -> None:
        if self._sock is not None:
            return
        try:
            self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout)
        except OSError as exc:
            raise TransientError(f"connect: {exc}") from exc
        self._sock.settimeout(self.timeout)
        self._buf = b""

    def _drop(self) -> None:
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None
                self._buf = b""

    def close(self) -> None:
        """Close the socket."""
        with self._lock:
            self._drop()

    # --- protocol --------------------------------------------------------------------------

    def _exchange(self, line: str, bare: bool) -> str:
        """Send one command line and return its reply (transient errors reconnect).

        ``bare``: the reply to a SET, the three bytes ``ack`` with nothing after them; else a
        line. Either may instead be a bare ``?``. Blanks before a reply are skipped (a newline
        some URCap versions may put after ``ack`` or ``?`` is not mistaken for the next reply).
        """
        self._open()
        assert self._sock is not None
        try:
            self._sock.sendall(line.encode("ascii") + b"\n")
            while (reply := self._take(bare)) is None:
                chunk = self._sock.recv(1024)
                if not chunk:
                    raise TransientError(f"{line!r}: connection closed by the controller")
                self._buf += chunk
        except TimeoutError as exc:
            self._drop()
            raise TransientError(f"{line!r}: no reply within {self.timeout} s") from exc
        except OSError as exc:
            self._drop()
            raise TransientError(f"{line!r}: {exc}") from exc
        except TransientError:
            self._drop()
            raise
        return reply

    def _take(self, bare: bool) -> str | None:
        """One complete reply from the buffer, or None while it is incomplete."""
        buf = self._buf.lstrip(_BLANK)
        for token in ((ACK, UNKNOWN) if bare else (UNKNOWN,)):
            if buf.startswith(token):
                self._buf = buf[len(token):]
                return token.decode()
        if bare and ACK.startswith(buf):
            self._buf = buf
            return None  # "a" or "ac" so far
        if b"\n" not in buf:
            self._buf = buf
            return None
        reply, self._buf = buf.split(b"\n", 1)
        return reply.decode("ascii", "replace").strip()

    def _request(self, line: str, bare: bool) -> str:
        with self._lock:
            return with_retries(lambda: self._exchange(line, bare), f"{line!r} failed",
                                self.address, self.retries, self.backoff_first, self._sleep)

    def _set(self, pairs: list[tuple[str, int]]) -> None:
        line = "SET " + " ".join(f"{k} {v}" for k, v in pairs)
        reply = self._request(line, bare=True)
        if reply == UNKNOWN.decode():
            raise DeviceError(DEVICE, self.address, f"{line!r} refused by the URCap ('?')")
        if reply != ACK.decode():
            raise DeviceError(DEVICE, self.address, f"{line!r} answered {reply!r}, not 'ack'")

    def _get(self, var: str) -> int:
        reply = self._request(f"GET {var}", bare=False)
        if reply == UNKNOWN.decode():
            raise DeviceError(DEVICE, self.address,
                              f"'GET {var}' answered '?': the URCap does not know {var}")
        parts = reply.split()
        if len(parts) != 2 or parts[0] != var or not parts[1].lstrip("-").isdigit():
            raise DeviceError(DEVICE, self.address, f"'GET {var}' answered {reply!r}")
        return int(parts[1])

    def write_request(self, request: ActionRequest) -> None:
        """One ``SET`` line; a reset (ACT 0) clears GTO first, a go-to sets GTO last."""
        if not request.act:
            self._set([("GTO", 0), ("ATR", int(request.atr)), ("ACT", 0)])
            return
        self._set([("POS", request.position), ("SPE", request.speed), ("FOR", request.force),
                   ("ATR", int(request.atr)), ("ACT", 1), ("GTO", int(request.gto))])

    def read_status(self) -> GripperStatus:
        """``GET`` each status variable (one round trip each); no current over this socket."""
        v = {var: self._get(var) for var in STATUS_VARS}
        return GripperStatus(act=v["ACT"], gto=v["GTO"], sta=v["STA"], obj=v["OBJ"],
                             flt=v["FLT"], kflt=0, pr=v["PRE"], po=v["POS"], cu=None)
