"""Writing recorded frames as an animated GIF (PIL only: no physics imported)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np


def save_gif(frames: Sequence[np.ndarray], path: str | Path, fps: float) -> Path:
    """``frames`` (H x W x 3, uint8) as a looping GIF at ``fps``; the folder is made. Raises
    ValueError when there is nothing to write."""
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not frames:
        raise ValueError("no frames were recorded")
    images = [Image.fromarray(f) for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    return path
