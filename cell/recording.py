"""`cell sim --record`: an animation people would rather watch than read about.

Why not the plain overview: at 320 x 240 the whole cell fits, but the gripper -- where the pivot
happens -- is a few pixels wide, and nothing says which step is running or how hard the arm
pushes. So each frame here is the overview at 640 x 480 with a close-up of the gripper (a
second camera aimed at the tool, from the side and above) in its corner, and a caption
strip: simulated time, the tree's running step and the force magnitude at the wrist, with the
abort limit it is held to.

The close-up looks down at about 50 deg from the side (:data:`CLOSE_UP_EYE`): from lower, the
bin's 80 mm walls filled the whole inset during the Grasp and the Tilt, and the machine's side
hid the part going into the slot -- the close-up showed a wall exactly when it mattered.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

OVERVIEW = (640, 480)
CLOSE_UP = (240, 180)
STRIP = 30  #: caption strip height, px
#: caption text height, px: readable when a frame is shown at two thirds of its size (the
#: README's picture puts two frames side by side)
CAPTION_PX = 16
#: The close-up camera's eye from the point it looks at (m, world): to the side and above, so it
#: looks over the bin's walls into the bin and down into the machine's slot and the box.
CLOSE_UP_EYE = (0.0, -0.22, 0.26)


def _render(world: Any, eye: np.ndarray, target: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    p = world.p
    view = p.computeViewMatrix(eye.tolist(), target.tolist(), [0, 0, 1])
    proj = p.computeProjectionMatrixFOV(45, size[0] / size[1], 0.01, 3.0)
    img = p.getCameraImage(size[0], size[1], view, proj, renderer=p.ER_TINY_RENDERER)[2]
    return np.asarray(img, np.uint8).reshape(size[1], size[0], 4)[:, :, :3].copy()


class CellRecorder:
    """Frames of a cell run: overview, gripper close-up and caption, composed with PIL."""

    def __init__(
        self,
        world: Any,
        target: tuple[float, float, float],
        direction: tuple[float, float, float],
        distance: float,
        height: float,
        tool_position: Any,
        caption: Any,
    ) -> None:
        """``tool_position()``: the tool's position (m, world); ``caption()``: the text of the
        strip for the current tick."""
        self.world = world
        t = np.asarray(target, float)
        n = np.asarray(direction, float)
        self.eye = t + distance * n + np.array([0.0, 0.0, height])
        self.target = t
        self.tool_position, self.caption = tool_position, caption
        self.frames: list[np.ndarray] = []
        self._font: Any = None  #: the caption's font, loaded by the first capture

    def capture(self) -> None:
        from PIL import Image, ImageDraw, ImageFont

        overview = _render(self.world, self.eye, self.target, OVERVIEW)
        tool = np.asarray(self.tool_position(), float)
        look = tool + np.array([0.0, 0.0, -0.09])  # the fingertips and the part, below the flange
        close = _render(self.world, look + np.array(CLOSE_UP_EYE), look, CLOSE_UP)
        w, h = OVERVIEW
        frame = Image.new("RGB", (w, h + STRIP), (245, 245, 245))
        frame.paste(Image.fromarray(overview), (0, 0))
        cw, ch = CLOSE_UP
        x0, y0 = w - cw - 6, 6
        draw = ImageDraw.Draw(frame)
        draw.rectangle((x0 - 2, y0 - 2, x0 + cw + 1, y0 + ch + 1), outline=(40, 40, 40), width=2)
        frame.paste(Image.fromarray(close), (x0, y0))
        draw.text((x0 + 4, y0 + ch - 14), "gripper close-up", fill=(255, 255, 255))
        if self._font is None:
            self._font = ImageFont.load_default(size=CAPTION_PX)
        draw.text((8, h + (STRIP - CAPTION_PX) // 2 - 1), self.caption(), fill=(20, 20, 20),
                  font=self._font)
        self.frames.append(np.asarray(frame))

    def save_gif(self, path: str | Path, fps: float = 12.0) -> Path:
        from sim.gif import save_gif

        return save_gif(self.frames, path, fps)


def force_limit(node: Any, default: float) -> float:
    """The abort force the running step is held to: that of the innermost FT guard above
    ``node`` (a motion leaf's own, e.g. the Tilt's 90 N), else ``default`` (the safety
    section's, as between motions) -- the limit the monitor's wrench plot draws too."""
    from trees.decorators import FTGuard

    while node is not None:
        if isinstance(node, FTGuard):
            return float(node.max_force)
        node = node.parent
    return float(default)


def caption_for(prep: Any) -> Any:
    """The caption of the current tick: time, running step, |F| against its limit."""

    def text() -> str:
        state = prep.state
        tip = prep.root.tip()
        try:
            force = float(np.linalg.norm(np.asarray(prep.ctx.devices.ft.wrench())[:3]))
            limit = force_limit(tip, prep.ctx.default_guard.max_force)
            f_text = f"|F| {force:.1f} N (abort {limit:g} N)"
        except Exception:  # noqa: BLE001 -- a lost stream shows as such, never stops a recording
            f_text = "|F| --"
        packed = state.counts.get("packed", 0)
        step = tip.name if tip is not None else "-"
        return f"t {state.time:.1f} s  |  {step}  |  {f_text}  |  packed {packed}"

    return text


__all__ = ["CLOSE_UP", "CLOSE_UP_EYE", "OVERVIEW", "CellRecorder", "caption_for", "force_limit"]
