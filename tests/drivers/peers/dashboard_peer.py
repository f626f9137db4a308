"""A UR dashboard server on localhost: the driver's client talks to it over a real TCP socket.

Like the controller's server on port 29999 it greets each connection with
``Connected: Universal Robots Dashboard Server``, reads ``\\n``-terminated commands
(case-insensitive) and answers each with one line, with the replies UR documents. It holds a
little state so sequences make sense: ``power on`` -> robot mode IDLE, ``brake release`` ->
RUNNING, ``unlock protective stop`` clears a protective stop (or refuses, as the controller does
within 5 s of the stop, when :attr:`DashboardPeer.unlock_refused` is set).

Faults to inject: :attr:`silent` (greets, then never answers), :attr:`no_greeting` (accepts and
says nothing), :attr:`replies` (override the reply to a command, e.g. ``Not in remote
control``). Every command received is recorded in :attr:`received`.
"""

from __future__ import annotations

import socket
import socketserver
import threading

GREETING = "Connected: Universal Robots Dashboard Server"


class DashboardPeer:
    """Start with :meth:`start` (or as a context manager); connect to ``(host, port)``."""

    def __init__(self) -> None:
        self.robot_mode = "POWER_OFF"
        self.safety_status = "NORMAL"
        self.version = "URSoftware 3.15.7.106331 (Jun 08 2021)"
        self.serial = "2018300123"
        self.model = "UR5"
        self.has_safetystatus = True  #: False: a controller older than 3.11 (safetymode only)
        self.unlock_refused = False
        self.silent = False
        self.no_greeting = False
        self.replies: dict[str, str] = {}
        self.received: list[str] = []
        self._lock = threading.Lock()
        self._release = threading.Event()  # set on stop: a silent handler may exit
        peer = self

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                peer._serve(self.connection, self.rfile)

        class Server(socketserver.ThreadingTCPServer):
            daemon_threads = True
            allow_reuse_address = True

        self._server = Server(("127.0.0.1", 0), Handler)
        self.host, self.port = self._server.server_address[:2]
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.01}, daemon=True
        )

    def start(self) -> DashboardPeer:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._release.set()
        self._server.shutdown()
        self._server.server_close()

    def __enter__(self) -> DashboardPeer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- the server side -----------------------------------------------------------------

    def _serve(self, conn: socket.socket, rfile) -> None:  # type: ignore[no-untyped-def]
        if self.no_greeting:
            self._release.wait()
            return
        conn.sendall((GREETING + "\n").encode())
        for raw in rfile:
            command = raw.decode("utf-8", "replace").strip()
            with self._lock:
                self.received.append(command)
            if self.silent:
                self._release.wait()
                return
            reply = self._reply(command)
            conn.sendall((reply + "\n").encode())
            if command.lower() == "quit":
                return

    def _reply(self, command: str) -> str:
        c = command.lower()
        if c in self.replies:
            return self.replies[c]
        if c == "power on":
            if self.robot_mode in ("POWER_OFF", "NO_CONTROLLER", "DISCONNECTED"):
                self.robot_mode = "IDLE"
            return "Powering on"
        if c == "power off":
            self.robot_mode = "POWER_OFF"
            return "Powering off"
        if c == "brake release":
            if self.robot_mode in ("IDLE", "POWER_ON"):
                self.robot_mode = "RUNNING"
            return "Brake releasing"
        if c == "unlock protective stop":
            if self.unlock_refused:
                return (
                    "Cannot unlock protective stop until 5s after occurrence. Always inspect "
                    "cause of protective stop before unlocking"
                )
            if self.safety_status == "PROTECTIVE_STOP":
                self.safety_status = "NORMAL"
            return "Protective stop releasing"
        if c == "close safety popup":
            return "closing safety popup"
        if c == "close popup":
            return "closing popup"
        if c == "robotmode":
            return f"Robotmode: {self.robot_mode}"
        if c == "safetystatus" and self.has_safetystatus:
            return f"Safetystatus: {self.safety_status}"
        if c == "safetymode":
            return f"Safetymode: {self.safety_status}"
        if c == "polyscopeversion":
            return self.version
        if c == "get serial number":
            return self.serial
        if c == "get robot model":
            return self.model
        if c == "quit":
            return "Disconnected"
        return f"could not understand: '{command}'"


def unused_port() -> int:
    """A localhost port nobody listens on (bound, then closed): a refused connection."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
