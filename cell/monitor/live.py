"""The live side of the monitor: what the tick loop hands over, and the camera's frames.

The tick loop calls :meth:`LiveMonitor.publish` once a tick with that tick's wrench and the
tick-log line (None when nothing changed). It folds the line (:class:`~cell.monitor.model.Fold`,
copy-on-write), appends the wrench, and swaps one reference: the server thread reads that
reference and never takes a lock the tick could wait on. Encoding a camera frame as JPEG -- the
one costly step -- happens on the server thread for the page, and on a writer thread for the
files the replay reads, never in the tick.
"""

from __future__ import annotations

import io
import queue
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cell.monitor.model import WRENCH_WINDOW_S, Fold, View, WrenchTrace

#: Width (px) of the frames the page shows and the replay keeps: enough to see the parts and
#: the detections, small on disk (about 15 kB a frame).
FRAME_WIDTH = 320


def encode_jpeg(rgb: np.ndarray, width: int = FRAME_WIDTH) -> bytes:
    from PIL import Image

    img = Image.fromarray(np.asarray(rgb, dtype=np.uint8))
    if img.width > width:
        img = img.resize((width, round(img.height * width / img.width)), Image.BILINEAR)
    out = io.BytesIO()
    img.save(out, format="JPEG", quality=80)
    return out.getvalue()


@dataclass(frozen=True)
class Published:
    """One tick's page data: the view, the wrench lists and how much of them is this tick's."""

    view: View
    wrench_t: list[float]
    wrench_w: list[list[float]]
    n_wrench: int
    running: bool = True


class LiveMonitor:
    """What the server reads while the cell runs."""

    def __init__(self, meta: dict[str, Any]) -> None:
        self.meta = meta
        self.header: dict[str, Any] | None = None
        self.fold = Fold()
        self.wrench = WrenchTrace()
        self.published: Published | None = None
        self.frames: FrameTap | None = None
        self.keep = int(3 * WRENCH_WINDOW_S * float(meta.get("control_hz", 125.0)))
        self.deadband: tuple[float, float] = tuple(meta.get("wrench_deadband", (1.0, 0.1)))
        self._last: np.ndarray | None = None

    def publish(
        self,
        tick: int,
        t: float,
        wrench: Any,
        line: dict[str, Any] | None,
        header: dict[str, Any] | None,
    ) -> None:
        if header is not None:
            self.header = header
        if line is not None:
            self.fold.apply(line)
        else:
            self.fold.tick, self.fold.t = tick, t
        w = self.wrench
        if wrench is not None:
            # As the log does: a sample when it moved past the deadband, and at least every
            # 0.1 s -- the page draws each value held until the next, so nothing is lost that
            # the deadband would not lose, and the page's JSON stays small.
            v = np.asarray(wrench, dtype=float).ravel()
            last = self._last
            if (
                last is None
                or t - w.t[-1] >= 0.1
                or float(np.max(np.abs(v[:3] - last[:3]))) > self.deadband[0]
                or float(np.max(np.abs(v[3:] - last[3:]))) > self.deadband[1]
            ):
                w.add(t, v)
                self._last = v
                if len(w.t) > 2 * self.keep:  # new lists: a reader keeps the old ones
                    w.t, w.w = w.t[-self.keep :], w.w[-self.keep :]
        self.published = Published(self.fold.view(), w.t, w.w, len(w.t))

    def finish(self) -> None:
        """The run ended: the page says so (the server stays until the command exits)."""
        if self.published is not None:
            p = self.published
            self.published = Published(p.view, p.wrench_t, p.wrench_w, p.n_wrench, False)


class FrameTap:
    """The camera with a tap: each capture is kept for the page and, with a tick log, written
    beside it as JPEG (on a writer thread) and referenced on the tick's log line.

    The pose at the capture (the camera in the robot base frame) and the intrinsics go with the
    frame, so the page draws the detections -- given in the base frame -- on it.
    """

    def __init__(self, camera: Any, arm: Any, folder: Path | None) -> None:
        self.camera, self.arm, self.folder = camera, arm, folder
        self.count = 0
        self.latest: tuple[int, np.ndarray, dict[str, Any]] | None = None
        self._pending: dict[str, Any] | None = None
        self._queue: queue.Queue[tuple[Path, np.ndarray] | None] = queue.Queue()
        self._writer: threading.Thread | None = None
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            for old in folder.glob("*.jpg"):
                old.unlink()  # a new run's frames only
            self._writer = threading.Thread(target=self._write, name="frame writer", daemon=True)
            self._writer.start()

    # --- the camera's interface, forwarded ----------------------------------------------------
    def __getattr__(self, name: str) -> Any:
        return getattr(self.camera, name)

    def capture(self) -> Any:
        frame = self.camera.capture()
        self.count += 1
        n = self.count
        intr = self.camera.intrinsics()
        scale = min(1.0, FRAME_WIDTH / float(intr.width))
        pose = self.arm.tool_pose() @ self.camera.tool_T_camera()
        matrix = np.eye(4)
        matrix[:3, :3], matrix[:3, 3] = pose.rotation, pose.position
        ref: dict[str, Any] = {
            "n": n,
            "stamp": round(float(frame.stamp), 4),
            "K": [intr.fx * scale, intr.fy * scale, intr.cx * scale, intr.cy * scale],
            "size": [round(intr.width * scale), round(intr.height * scale)],
            "pose": [[round(float(x), 5) for x in row] for row in matrix],
        }
        if self.folder is not None:
            name = f"{n:06d}.jpg"
            ref["file"] = f"{self.folder.name}/{name}"
            self._queue.put((self.folder / name, frame.rgb))
        self.latest = (n, frame.rgb, ref)
        self._pending = ref
        return frame

    # --- the tick log's tap -------------------------------------------------------------------
    def tap(self) -> dict[str, Any]:
        """``{"frame": ref}`` on the tick after a capture, else nothing."""
        ref, self._pending = self._pending, None
        return {} if ref is None else {"frame": ref}

    def _write(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            path, rgb = item
            try:
                path.write_bytes(encode_jpeg(rgb))
            except OSError:
                pass  # a full disk must not stop the cell; the replay shows no picture then

    def close(self) -> None:
        if self._writer is not None:
            self._queue.put(None)
            self._writer.join(timeout=10.0)


__all__ = ["FRAME_WIDTH", "FrameTap", "LiveMonitor", "Published", "encode_jpeg"]
