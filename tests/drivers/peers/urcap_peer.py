"""The Robotiq gripper URCap's socket (TCP 63352 on a UR controller), on localhost.

A threaded TCP server speaking the URCap's protocol: ``SET VAR value [VAR value ...]`` answered
with the three bytes ``ack`` and no newline (variables applied in the order given), ``GET VAR``
answered ``VAR value`` and a newline, anything else ``?`` (no newline), as the URCap does.
Behind it sits the same :class:`GripperModel` as the Modbus peer, so both transports are tested
against one gripper behaviour. ``silent`` makes it read commands and never answer (a hung
controller); ``lines`` records every command line received.
"""

from __future__ import annotations

import socket
import socketserver
import threading

from drivers.robotiq_gripper.registers import ActionRequest, encode_request
from tests.drivers.peers.gripper_modbus_peer import GripperModel

_SETTABLE = ("ACT", "GTO", "ATR", "POS", "SPE", "FOR")


class UrcapPeer:
    """The URCap socket on ``host`` (``127.0.0.1`` by default) and a free port (``port``);
    :meth:`stop` joins."""

    def __init__(self, model: GripperModel, host: str = "127.0.0.1") -> None:
        self.model = model
        self.silent = False
        self.lines: list[str] = []
        self.connections = 0
        self._sockets: list[socket.socket] = []
        self._vars = {"ACT": 0, "GTO": 0, "ATR": 0, "POS": 0, "SPE": 0, "FOR": 0}
        self._lock = threading.Lock()
        peer = self

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                with peer._lock:
                    peer.connections += 1
                    peer._sockets.append(self.connection)
                for raw in self.rfile:
                    line = raw.decode("ascii", "replace").strip()
                    with peer._lock:
                        peer.lines.append(line)
                    if peer.silent:
                        continue
                    try:
                        reply = peer.answer(line)
                        bare = reply in ("ack", "?")  # the URCap ends only values with \n
                        self.wfile.write((reply if bare else reply + "\n").encode("ascii"))
                    except OSError:
                        return

        class Server(socketserver.ThreadingTCPServer):
            allow_reuse_address = True
            daemon_threads = False
            block_on_close = True  # server_close() joins the connection threads

        self._server = Server((host, 0), Handler)
        self.host, self.port = self._server.server_address[:2]
        self._thread = threading.Thread(target=self._server.serve_forever,
                                        kwargs={"poll_interval": 0.05}, name="urcap-peer",
                                        daemon=True)
        self._thread.start()

    def answer(self, line: str) -> str:
        """The URCap's reply to one command line."""
        words = line.split()
        if len(words) >= 3 and words[0] == "SET" and len(words) % 2 == 1:
            with self._lock:
                for name, value in zip(words[1::2], words[2::2], strict=True):
                    if name not in _SETTABLE or not value.isdigit():
                        return "?"
                    self._vars[name] = int(value)
                self._apply()  # the whole line reaches the gripper as one request
            return "ack"
        if len(words) == 2 and words[0] == "GET":
            st = self.model.status()
            values = {"ACT": st.act, "GTO": st.gto, "STA": st.sta, "OBJ": st.obj,
                      "FLT": st.flt, "PRE": st.pr, "POS": st.po}
            if words[1] in values:
                return f"{words[1]} {values[words[1]]}"
        return "?"

    def _apply(self) -> None:
        v = self._vars
        req = ActionRequest(act=bool(v["ACT"]), gto=bool(v["GTO"]), atr=bool(v["ATR"]),
                            position=v["POS"], speed=v["SPE"], force=v["FOR"])
        self.model.write(encode_request(req))

    def stop(self) -> None:
        """Stop serving, drop the connections, close the listening socket, join the threads."""
        self._server.shutdown()
        with self._lock:
            for conn in self._sockets:
                try:
                    conn.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
        self._server.server_close()
        self._thread.join(timeout=5.0)


def free_port() -> int:
    """A localhost port nothing listens on (bound, then released), for 'connection refused'."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
