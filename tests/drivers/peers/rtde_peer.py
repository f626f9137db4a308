"""The output side of a UR controller's RTDE server, enough for ``ur_rtde``'s real
``RTDEReceiveInterface`` to connect to it and read the robot state.

RTDE (port 30004) frames every message as ``uint16 size`` (header included), ``uint8 type``,
payload, big-endian. The peer answers, as the controller does:

* ``V`` request protocol version (``uint16``) -> ``uint8`` accepted (only version 2);
* ``v`` get URControl version -> ``uint32`` major, minor, bugfix, build;
* ``O`` setup outputs (``double`` frequency, comma-separated names) -> ``uint8`` recipe id and
  the comma-separated types, ``NOT_FOUND`` for a name it does not know;
* ``S`` start -> ``uint8`` 1, then ``U`` data packages (``uint8`` recipe id + the values in
  recipe order) at the recipe's frequency;
* ``P`` pause -> ``uint8`` 1, and the packages stop.

What it does not do: inputs (``I`` setup inputs and incoming ``U`` packages, which the control
side needs along with a URScript interpreter), text messages, several recipes. The state it
sends is :attr:`RTDEPeer.state` (set values any time); :meth:`drop_clients` closes the live
connections, as a cable pull would.

``ur_rtde`` always connects to port 30004, so this peer cannot bind port 0: it binds 30004 on a
loopback address of its own (127.x.y.z) so it collides with nothing on 127.0.0.1.
"""

from __future__ import annotations

import socket
import struct
import threading
import time

RTDE_PORT = 30004

REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")

#: RTDE type name -> struct format (big-endian payload).
FORMATS = {
    "DOUBLE": ">d",
    "VECTOR3D": ">3d",
    "VECTOR6D": ">6d",
    "INT32": ">i",
    "UINT32": ">I",
    "UINT64": ">Q",
    "VECTOR6INT32": ">6i",
    "VECTOR6UINT32": ">6I",
    "BOOL": ">?",
    "UINT8": ">B",
}

#: The outputs this peer knows (names from UR's RTDE guide) and their types.
OUTPUT_TYPES: dict[str, str] = {
    "timestamp": "DOUBLE",
    "target_q": "VECTOR6D",
    "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D",
    "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D",
    "actual_current": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",
    "actual_TCP_speed": "VECTOR6D",
    "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D",
    "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "ft_raw_wrench": "VECTOR6D",
    "payload_inertia": "VECTOR6D",
}
for _i in range(48):
    OUTPUT_TYPES[f"output_int_register_{_i}"] = "INT32"
    OUTPUT_TYPES[f"output_double_register_{_i}"] = "DOUBLE"
    OUTPUT_TYPES[f"output_bit_register_{64 + _i}"] = "BOOL"


def _default_value(kind: str) -> object:
    fmt = FORMATS[kind]
    count = int(fmt[1]) if fmt[1].isdigit() else 1
    zero: object = False if kind == "BOOL" else 0.0 if "d" in fmt else 0
    return [zero] * count if count > 1 else zero


def _loopback_host() -> str:
    """A loopback address of this process's own, so port 30004 is free there."""
    import os

    pid = os.getpid()
    return f"127.{77 + (pid >> 16) % 100}.{(pid >> 8) & 255}.{max(1, pid & 255)}"


class RTDEPeer:
    """Serve RTDE outputs on ``(host, 30004)``; start with :meth:`start` or ``with``."""

    def __init__(self, host: str | None = None, version: tuple[int, int, int, int] = (3, 15, 7, 0)
                 ) -> None:
        self.host = host or _loopback_host()
        self.port = RTDE_PORT
        self.version = version
        self.state: dict[str, object] = {
            "timestamp": 0.0,
            "actual_q": [0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
            "actual_TCP_pose": [0.4, 0.1, 0.3, 0.0, 3.14159, 0.0],
            "robot_mode": 7,
            "safety_mode": 1,
            "safety_status_bits": 1,
            "robot_status_bits": 3,
            "runtime_state": 1,
        }
        self.requested: list[list[str]] = []  #: every output recipe asked for (names)
        self.protocol_versions: list[int] = []
        self.packages_sent = 0
        self.connections = 0
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._clients: list[socket.socket] = []
        self._server = socket.create_server((self.host, self.port), reuse_port=False)
        self._server.settimeout(0.05)
        self._thread = threading.Thread(target=self._accept_loop, daemon=True)

    def start(self) -> RTDEPeer:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self.drop_clients()
        self._thread.join(timeout=2.0)
        self._server.close()

    def __enter__(self) -> RTDEPeer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def drop_clients(self) -> None:
        """Close every live connection (the controller went away)."""
        with self._lock:
            clients, self._clients = self._clients, []
        for c in clients:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()

    # --- server --------------------------------------------------------------------------

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._clients.append(conn)
                self.connections += 1
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    @staticmethod
    def _send(conn: socket.socket, kind: int, payload: bytes) -> None:
        conn.sendall(struct.pack(">HB", 3 + len(payload), kind) + payload)

    @staticmethod
    def _read_exact(conn: socket.socket, n: int) -> bytes | None:
        data = b""
        while len(data) < n:
            try:
                chunk = conn.recv(n - len(data))
            except OSError:
                return None
            if not chunk:
                return None
            data += chunk
        return data

    def _serve(self, conn: socket.socket) -> None:
        recipe: list[tuple[str, str]] = []
        period = 1.0 / 125.0
        streamer: threading.Thread | None = None
        streaming = threading.Event()
        conn.settimeout(None)
        while not self._stop.is_set():
            header = self._read_exact(conn, 3)
            if header is None:
                break
            size, kind = struct.unpack(">HB", header)
            payload = self._read_exact(conn, size - 3) if size > 3 else b""
            if payload is None:
                break
            if kind == REQUEST_PROTOCOL_VERSION:
                (v,) = struct.unpack(">H", payload[:2])
                self.protocol_versions.append(v)
                self._send(conn, kind, struct.pack(">B", 1 if v == 2 else 0))
            elif kind == GET_URCONTROL_VERSION:
                self._send(conn, kind, struct.pack(">4I", *self.version))
            elif kind == SETUP_OUTPUTS:
                (frequency,) = struct.unpack(">d", payload[:8])
                names = [n for n in payload[8:].decode().split(",") if n]
                self.requested.append(names)
                types = [OUTPUT_TYPES.get(n, "NOT_FOUND") for n in names]
                recipe = list(zip(names, types, strict=True))
                period = 1.0 / min(max(frequency, 1.0), 500.0)
                self._send(conn, kind, struct.pack(">B", 1) + ",".join(types).encode())
            elif kind == START:
                ok = bool(recipe) and all(t != "NOT_FOUND" for _, t in recipe)
                self._send(conn, kind, struct.pack(">B", int(ok)))
                if ok and streamer is None:
                    streaming.set()
                    streamer = threading.Thread(
                        target=self._stream, args=(conn, recipe, period, streaming), daemon=True
                    )
                    streamer.start()
            elif kind == PAUSE:
                streaming.clear()
                self._send(conn, kind, struct.pack(">B", 1))
            # Anything else (inputs, data from the client) is outside this peer: ignored.
        streaming.clear()
        try:
            conn.close()
        except OSError:
            pass

    def _package(self, recipe: list[tuple[str, str]]) -> bytes:
        out = [struct.pack(">B", 1)]
        for name, kind in recipe:
            value = self.state.get(name, _default_value(kind))
            fmt = FORMATS[kind]
            out.append(struct.pack(fmt, *value) if isinstance(value, list | tuple)
                       else struct.pack(fmt, value))
        return b"".join(out)

    def _stream(self, conn: socket.socket, recipe: list[tuple[str, str]], period: float,
                streaming: threading.Event) -> None:
        t_next = time.monotonic()
        while streaming.is_set() and not self._stop.is_set():
            try:
                self._send(conn, DATA_PACKAGE, self._package(recipe))
            except OSError:
                return
            self.packages_sent += 1
            self.state["timestamp"] = float(self.state.get("timestamp", 0.0)) + period
            t_next += period
            time.sleep(max(0.0, t_next - time.monotonic()))


class RTDEPeerProcess:
    """:class:`RTDEPeer` in a child process, driven over a pipe.

    Why a process: ``ur_rtde``'s Python bindings hold the GIL while they block on the socket
    (the constructor waits for the peer's replies), so a peer on a thread of the same
    interpreter could never answer. ``set_state``/``drop_clients``/``info`` cross the pipe.
    """

    def __init__(self, version: tuple[int, int, int, int] = (3, 15, 7, 0)) -> None:
        import multiprocessing as mp

        ctx = mp.get_context("fork")
        self._pipe, child = ctx.Pipe()
        self._proc = ctx.Process(target=_child_main, args=(child, version), daemon=True)
        self.host = ""
        self.port = RTDE_PORT

    def start(self) -> RTDEPeerProcess:
        self._proc.start()
        reply = self._call(("start",))
        if isinstance(reply, Exception):
            self._proc.join(timeout=2.0)
            raise reply
        self.host = str(reply)
        return self

    def _call(self, message: tuple) -> object:  # type: ignore[type-arg]
        self._pipe.send(message)
        if not self._pipe.poll(5.0):
            raise TimeoutError(f"RTDE peer process did not answer {message[0]!r}")
        return self._pipe.recv()

    def set_state(self, **values: object) -> None:
        self._call(("set", values))

    def drop_clients(self) -> None:
        self._call(("drop",))

    def info(self) -> dict[str, object]:
        """``requested`` recipes, ``protocol_versions``, ``packages_sent``, ``connections``."""
        return dict(self._call(("info",)))  # type: ignore[call-overload]

    def stop(self) -> None:
        if self._proc.is_alive():
            try:
                self._call(("stop",))
            except (TimeoutError, OSError, EOFError):
                pass
            self._proc.join(timeout=2.0)
            if self._proc.is_alive():
                self._proc.kill()

    def __enter__(self) -> RTDEPeerProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _child_main(pipe, version: tuple[int, int, int, int]) -> None:  # type: ignore[no-untyped-def]
    message = pipe.recv()
    assert message[0] == "start"
    try:
        peer = RTDEPeer(version=version).start()
    except OSError as e:
        pipe.send(e)
        return
    pipe.send(peer.host)
    while True:
        message = pipe.recv()
        if message[0] == "set":
            peer.state.update(message[1])
            pipe.send(None)
        elif message[0] == "drop":
            peer.drop_clients()
            pipe.send(None)
        elif message[0] == "info":
            pipe.send({
                "requested": peer.requested,
                "protocol_versions": peer.protocol_versions,
                "packages_sent": peer.packages_sent,
                "connections": peer.connections,
            })
        elif message[0] == "stop":
            peer.stop()
            pipe.send(None)
            return
