"""Frames of a run for people to look at: a side view of the pivot plane, saved as a GIF.

Rendered with PyBullet's TinyRenderer (no display needed). The camera looks along the pivot
plane's normal from outside the plane, a little from above, so the Tilt reads as a rotation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from sim.world import SimWorld


class Recorder:
    def __init__(
        self,
        world: SimWorld,
        target: ArrayLike,
        normal: ArrayLike,
        distance: float = 0.32,
        height: float = 0.10,
        size: tuple[int, int] = (320, 240),
    ) -> None:
        self.world = world
        target = np.asarray(target, float)
        n = np.asarray(normal, float)
        eye = target + distance * n + np.array([0.0, 0.0, height])
        self.view = world.p.computeViewMatrix(eye.tolist(), target.tolist(), [0, 0, 1])
        self.proj = world.p.computeProjectionMatrixFOV(45, size[0] / size[1], 0.01, 3.0)
        self.size = size
        self.frames: list[np.ndarray] = []

    def capture(self) -> None:
        w, h = self.size
        img = self.world.p.getCameraImage(
            w, h, self.view, self.proj, renderer=self.world.p.ER_TINY_RENDERER
        )[2]
        self.frames.append(np.asarray(img, np.uint8).reshape(h, w, 4)[:, :, :3].copy())

    def save_gif(self, path: str | Path, fps: float = 15.0) -> Path:
        from sim.gif import save_gif

        return save_gif(self.frames, path, fps)

    def save_contact_sheet(self, path: str | Path, count: int = 12, columns: int = 4) -> Path:
        """The last ``count`` frames (or all, evenly picked) tiled into one PNG."""
        from PIL import Image

        path = Path(path)
        idx = np.linspace(0, len(self.frames) - 1, min(count, len(self.frames))).astype(int)
        w, h = self.size
        rows = (len(idx) + columns - 1) // columns
        sheet = Image.new("RGB", (w * columns, h * rows))
        for k, i in enumerate(idx):
            sheet.paste(Image.fromarray(self.frames[i]), ((k % columns) * w, (k // columns) * h))
        sheet.save(path)
        return path
