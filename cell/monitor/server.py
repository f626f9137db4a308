"""The monitor's web server: the page and its JSON, live or over a recorded run.

Read-only by construction: it answers GET and HEAD and nothing else, and no route reaches a
device -- the page can watch the cell, never command it. Standard library only
(:mod:`http.server` in a daemon thread): a cell PC needs nothing installed for it, and the
traffic is one person's browser polling a few times a second.

Routes (``?at=LINE`` picks a line of a replay; live, the latest tick):

* ``/`` -- the page
* ``/api/tree`` -- ``{"tick", "t", "nodes": [{"id", "name", "type", "status", "feedback",
  "children": [ids]}]}`` (a node also has ``limits`` for a guard or a timeout, and ``last``, its
  last SUCCESS/FAILURE with tick and feedback, which a one-tick failure would otherwise hide)
* ``/api/events`` -- the events so far (list), aborts as ``"kind": "abort"``
* ``/api/state`` -- blackboard, wrench window, active FT limits, counts, the frame and its
  detections in pixels, whether the run is live / running
* ``/api/timeline`` -- replay only: line count, each line's tick and time, and the marks
  (first failure, first abort, first failed cycle)
* ``/frames/N.jpg`` -- a camera frame
"""

from __future__ import annotations

import ipaddress
import json
import socket
import sys
import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from cell.errors import UserError
from cell.monitor.live import LiveMonitor, encode_jpeg
from cell.monitor.model import (
    RunModel,
    View,
    active_limits,
    counts,
    events_json,
    project_detections,
    tree_json,
)

PAGE = Path(__file__).with_name("page.html")
#: where the page takes what it shows first (see MonitorServer.page)
FIRST_SLOT = '<script id="first" type="application/json">null</script>'


def parse_address(text: str, option: str = "--monitor") -> tuple[str, int]:
    """``HOST:PORT`` (``[::1]:PORT`` for IPv6); PORT 0 lets the system choose."""
    host, sep, port_text = text.rpartition(":")
    if not sep or not host:
        raise UserError(f"{option}: expected HOST:PORT (e.g. 127.0.0.1:8765), got {text!r}")
    host = host.strip("[]")
    try:
        port = int(port_text)
    except ValueError:
        raise UserError(f"{option}: the port must be a number, got {port_text!r}") from None
    if not 0 <= port <= 65535:
        raise UserError(f"{option}: the port must lie in [0, 65535], got {port}")
    return host, port


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True


#: addresses that mean "every address of this machine"
WILDCARDS = frozenset({"0.0.0.0", "::", ""})
#: an address of the documentation range (RFC 5737): never reached, only routed to, so that the
#: system names the interface a visitor from the network would come in on
_PROBE = ("192.0.2.1", 9)


def outward_address() -> str:
    """The IPv4 address this machine is reached at from its network (a UDP socket "connected"
    to an unreachable address sends nothing, but is given the outgoing interface's address);
    its name where it has no network but the loopback."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(_PROBE)
            address = probe.getsockname()[0]
    except OSError:
        return socket.gethostname()
    return socket.gethostname() if address.startswith("127.") else address


class MonitorServer:
    """Serves one source: a :class:`LiveMonitor` or a :class:`RunModel` (replay)."""

    def __init__(
        self,
        host: str,
        port: int,
        live: LiveMonitor | None = None,
        replay: RunModel | None = None,
        frames_dir: Path | None = None,
        option: str = "--monitor",
    ) -> None:
        self.live, self.replay, self.frames_dir = live, replay, frames_dir
        self._jpeg: tuple[int, bytes] | None = None
        handler = _handler(self)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        _Server.address_family = family
        try:
            self.httpd = _Server((host, port), handler)
        except OSError as exc:
            raise UserError(f"{option}: cannot listen on {host}:{port}: {exc.strerror}") from None
        self.host, self.port = host, self.httpd.server_address[1]
        self.thread = threading.Thread(
            target=self.httpd.serve_forever, name="monitor server", daemon=True
        )

    @property
    def url(self) -> str:
        """The link to open; bound to every address (0.0.0.0, ::), the machine's address on
        its network: a browser cannot follow a link to 0.0.0.0, and another machine may not
        resolve this one's name."""
        host = outward_address() if self.host in WILDCARDS else self.host
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/"

    def start(self) -> MonitorServer:
        self.thread.start()
        return self

    def close(self) -> None:
        if self.thread.is_alive():  # shutdown() waits for a serve_forever() that never began
            self.httpd.shutdown()
        self.httpd.server_close()

    # --- data ---------------------------------------------------------------------------------
    def _source(self, query: dict[str, list[str]]) -> tuple[dict[str, Any], View, Any] | None:
        if self.replay is not None:
            at = query.get("at", [None])[0]
            index = len(self.replay.lines) - 1 if at is None else int(at)
            return self.replay.header, self.replay.view_at(index), None
        live = self.live
        assert live is not None
        p = live.published
        if p is None or live.header is None:
            return None
        return live.header, p.view, p

    def page(self, query: dict[str, list[str]]) -> bytes:
        """The page with what it shows first inside it (the timeline, the tree, the state and
        the events at ``?at=`` or the start of a replay, now when live): its first paint is the
        cell, with no request of its own to wait for."""
        if self.replay is not None and "at" not in query:
            query = {**query, "at": ["0"]}
        first = {"timeline": self.payload("/api/timeline", query)}
        for name in ("tree", "state", "events"):
            first[name] = self.payload(f"/api/{name}", query)
        # "</" cannot end the script element early inside the JSON: escaped as "<\/".
        blob = json.dumps(first).replace("</", "<\\/")
        html = PAGE.read_text(encoding="utf-8")
        return html.replace(FIRST_SLOT, FIRST_SLOT.replace(">null<", f">{blob}<"), 1).encode()

    def payload(self, route: str, query: dict[str, list[str]]) -> Any:
        if route == "/api/timeline":
            if self.replay is None:
                return {"live": True}
            r = self.replay
            return {
                "live": False,
                "lines": len(r.lines),
                "tick": [ln["tick"] for ln in r.lines],
                "t": [ln["t"] for ln in r.lines],
                "marks": r.marks(),
            }
        source = self._source(query)
        if source is None:
            return {"tick": 0, "t": 0.0, "nodes": []} if route == "/api/tree" else {}
        header, view, published = source
        if route == "/api/tree":
            return tree_json(header, view)
        if route == "/api/events":
            return events_json(view)
        if route == "/api/state":
            return self._state(header, view, published)
        raise KeyError(route)

    def _state(self, header: dict[str, Any], view: View, published: Any) -> dict[str, Any]:
        if published is not None:
            trace: dict[str, Any] = _window(
                published.wrench_t, published.wrench_w, published.n_wrench, view.t
            )
            running = published.running
        else:
            trace = self.replay.wrench.window(view.t)  # type: ignore[union-attr]
            running = False
        frame = None
        if view.frame is not None:
            f = view.frame
            detections = view.blackboard.get("/part/detections")
            frame = {
                "n": f["n"],
                "url": f"/frames/{f['n']}.jpg",
                "size": f.get("size"),
                "stamp": f.get("stamp"),
                "detections": project_detections(f, detections),
            }
        c = counts(view)
        return {
            "live": self.replay is None,
            "running": running,
            "tick": view.tick,
            "t": round(view.t, 4),
            "blackboard": view.blackboard,
            "wrench": trace,
            "limits": active_limits(header, view),
            "counts": c,
            "cycles": {
                "asked": header.get("cycles"),
                "done": c.get("cycle_done", 0),
                "failed": c.get("cycle_failed", 0),
            },
            "frame": frame,
            "backend": header.get("backend"),
        }

    def frame_jpeg(self, n: int) -> bytes | None:
        live = self.live
        if live is not None and live.frames is not None and live.frames.latest is not None:
            latest_n, rgb, _ = live.frames.latest
            if latest_n == n:
                if self._jpeg is None or self._jpeg[0] != n:
                    self._jpeg = (n, encode_jpeg(rgb))
                return self._jpeg[1]
        if self.frames_dir is not None:
            path = self.frames_dir / f"{n:06d}.jpg"
            if path.is_file():
                return path.read_bytes()
        return None


def _window(t: list[float], w: list[list[float]], n: int, t_end: float) -> dict[str, Any]:
    from cell.monitor.model import WRENCH_WINDOW_S, WrenchTrace

    trace = WrenchTrace()
    trace.t, trace.w = t, w
    return trace.window(t_end, WRENCH_WINDOW_S, n)


def _handler(server: MonitorServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "cell-monitor"

        def log_message(self, format: str, *args: Any) -> None:  # noqa: A002
            pass  # the cell's terminal is for the cell

        def _send(self, code: int, body: bytes, kind: str) -> None:
            self.send_response(code)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def do_GET(self) -> None:  # noqa: N802 -- http.server's name
            parts = urlsplit(self.path)
            route, query = parts.path, parse_qs(parts.query)
            try:
                if route in ("/", "/index.html"):
                    self._send(200, server.page(query), "text/html; charset=utf-8")
                elif route.startswith("/frames/") and route.endswith(".jpg"):
                    jpeg = server.frame_jpeg(int(route[len("/frames/") : -4]))
                    if jpeg is None:
                        self._send(404, b"no such frame", "text/plain")
                    else:
                        self._send(200, jpeg, "image/jpeg")
                elif route.startswith("/api/"):
                    body = json.dumps(server.payload(route, query)).encode()
                    self._send(200, body, "application/json")
                else:
                    self._send(404, b"not found", "text/plain")
            except KeyError:
                self._send(404, b"not found", "text/plain")
            except ValueError:
                self._send(400, b"bad request", "text/plain")
            except (BrokenPipeError, ConnectionResetError):
                pass

        do_HEAD = do_GET  # noqa: N815

        def _refuse(self) -> None:
            self._send(HTTPStatus.METHOD_NOT_ALLOWED, b"the monitor is read-only", "text/plain")

        do_POST = do_PUT = do_DELETE = do_PATCH = _refuse  # noqa: N815

    return Handler


def warn_if_exposed(host: str, option: str, command: str) -> None:
    """A line on stderr, headed by the command as its errors are, when ``host`` is not a
    loopback address: the page shows the cell's state to anyone on the network."""
    if not is_loopback(host):
        print(
            f"cell {command}: warning: {option} {host}: the monitor is reachable from other "
            "machines (read-only, no password); use 127.0.0.1 to keep it on this one",
            file=sys.stderr,
        )


__all__ = ["MonitorServer", "is_loopback", "parse_address", "warn_if_exposed"]
