"""Client for the UR controller's dashboard server (TCP 29999, a line-based text protocol).

Why a client of our own over a plain socket: the dashboard is a public text protocol, so it can be
tested against a real TCP peer here, and every failure becomes a :class:`DeviceError` naming
``host:29999`` and the controller's reply, which is what a person at the cell needs.

Protocol: on connect the server sends a greeting line (``Connected: Universal Robots Dashboard
Server``); each command is one ``\\n``-terminated line and gets one reply line. The calls block for
at most ``timeout`` seconds each, so they belong to start-up, recovery and ``check()``, never to a
control tick.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable

from drivers.health import DeviceError, backoff_delays

DASHBOARD_PORT = 29999
GREETING = "Connected: Universal Robots Dashboard Server"
DEVICE = "UR5 dashboard"


class DashboardClient:
    """One connection to the dashboard server; connects lazily on the first command.

    ``timeout``: seconds for connecting and for each reply. ``connect_attempts``: bounded tries
    with :func:`drivers.health.backoff_delays` between them (``sleep`` is injectable for tests).
    """

    def __init__(
        self,
        host: str,
        port: int = DASHBOARD_PORT,
        timeout: float = 2.0,
        connect_attempts: int = 3,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.host, self.port, self.timeout = host, port, timeout
        self.connect_attempts = max(1, connect_attempts)
        self._sleep = sleep
        self._sock: socket.socket | None = None
        self._buffer = b""

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    def _error(self, cause: str) -> DeviceError:
        return DeviceError(DEVICE, self.address, cause)

    # --- connection ----------------------------------------------------------------------

    def connect(self) -> None:
        """Open the socket and read the greeting; bounded retries with back-off."""
        self.close()
        delays = backoff_delays(self.connect_attempts)
        last = ""
        for attempt in range(self.connect_attempts):
            try:
                self._sock = socket.create_connection((self.host, self.port), self.timeout)
                self._sock.settimeout(self.timeout)
                greeting = self._read_line("the greeting")
            except DeviceError:
                self.close()
                raise
            except OSError as e:
                self.close()
                last = f"{type(e).__name__}: {e}" if str(e) else type(e).__name__
                if attempt < len(delays):
                    self._sleep(delays[attempt])
                continue
            if not greeting.startswith(GREETING):
                self.close()
                raise self._error(f"unexpected greeting {greeting!r} (is this a UR controller?)")
            return
        raise self._error(f"cannot connect after {self.connect_attempts} attempt(s): {last}")

    def close(self) -> None:
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None
                self._buffer = b""

    def __enter__(self) -> DashboardClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _read_line(self, what: str) -> str:
        assert self._sock is not None
        deadline = time.monotonic() + self.timeout
        while b"\n" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                self.close()
                raise self._error(f"no reply to {what} within {self.timeout:g} s")
            self._sock.settimeout(left)
            try:
                chunk = self._sock.recv(4096)
            except TimeoutError:
                self.close()
                raise self._error(f"no reply to {what} within {self.timeout:g} s") from None
            except OSError as e:
                self.close()
                raise self._error(f"connection lost waiting for {what}: {e}") from e
            if not chunk:
                self.close()
                raise self._error(f"connection closed by the controller waiting for {what}")
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        return line.decode("utf-8", "replace").strip()

    def command(self, text: str) -> str:
        """Send one command line and return the reply line (stripped)."""
        if self._sock is None:
            self.connect()
        assert self._sock is not None
        try:
            self._sock.sendall(text.encode("utf-8") + b"\n")
        except OSError as e:
            self.close()
            raise self._error(f"sending {text!r} failed: {e}") from e
        return self._read_line(repr(text))

    def _expect(self, text: str, reply_prefix: str) -> str:
        reply = self.command(text)
        if not reply.lower().startswith(reply_prefix.lower()):
            raise self._error(f"{text!r} answered {reply!r}, expected {reply_prefix!r}")
        return reply

    def _value(self, text: str, label: str) -> str:
        """Commands answered ``Label: VALUE``; returns VALUE."""
        reply = self._expect(text, label + ":")
        return reply.split(":", 1)[1].strip()

    # --- commands ------------------------------------------------------------------------

    def power_on(self) -> None:
        self._expect("power on", "Powering on")

    def power_off(self) -> None:
        self._expect("power off", "Powering off")

    def brake_release(self) -> None:
        self._expect("brake release", "Brake releasing")

    def unlock_protective_stop(self) -> None:
        """Fails (with the controller's reason) within 5 s of the stop or if none is active."""
        self._expect("unlock protective stop", "Protective stop releasing")

    def close_safety_popup(self) -> None:
        self._expect("close safety popup", "closing safety popup")

    def close_popup(self) -> None:
        self._expect("close popup", "closing popup")

    def robot_mode(self) -> str:
        """E.g. ``RUNNING``, ``IDLE`` (powered, brakes on), ``POWER_OFF``."""
        return self._value("robotmode", "Robotmode")

    def safety_status(self) -> str:
        """E.g. ``NORMAL``, ``PROTECTIVE_STOP``; falls back to ``safetymode`` on controllers
        older than 3.11/5.4 that lack ``safetystatus``."""
        reply = self.command("safetystatus")
        if reply.lower().startswith("safetystatus:"):
            return reply.split(":", 1)[1].strip()
        if reply.lower().startswith("could not understand"):
            return self._value("safetymode", "Safetymode")
        raise self._error(f"'safetystatus' answered {reply!r}, expected 'Safetystatus:'")

    def polyscope_version(self) -> str:
        """E.g. ``URSoftware 3.15.7.106331 (Jun 08 2021)``."""
        reply = self._expect("PolyscopeVersion", "URSoftware")
        return reply

    def serial_number(self) -> str:
        reply = self.command("get serial number")
        if not reply or not reply.replace("-", "").isalnum() or " " in reply:
            raise self._error(f"'get serial number' answered {reply!r}")
        return reply

    def robot_model(self) -> str:
        reply = self.command("get robot model")
        if not reply.upper().startswith("UR"):
            raise self._error(f"'get robot model' answered {reply!r}")
        return reply
