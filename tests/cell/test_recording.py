"""`cell sim --record`: a readable GIF (640 x 480 overview, a gripper close-up in its corner, a
caption strip with the time, the running step and the wrist force)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from cell.recording import CLOSE_UP, OVERVIEW, STRIP

from .test_cli import run_cli


def test_the_recorded_gif_has_the_close_up_and_the_caption(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(
        ["sim", "--cycles", "1", "--max-sim-time", "3", "--quiet", "--record", "r.gif"], capsys
    )
    assert code == 1, err  # cut by --max-sim-time: out of time
    gif = Image.open(tmp_path / "r.gif")
    assert gif.size == (OVERVIEW[0], OVERVIEW[1] + STRIP)
    assert gif.n_frames >= 3
    frames = []
    for k in (0, gif.n_frames - 1):
        gif.seek(k)
        frames.append(np.asarray(gif.convert("RGB"), dtype=int))
    first, last = frames
    w, h = OVERVIEW
    cw, ch = CLOSE_UP
    inset = last[6 : 6 + ch, w - cw - 6 : w - 6]
    assert inset.std() > 10  # a rendered view, not a blank box
    strip_first, strip_last = first[h:], last[h:]
    assert (strip_first < 128).any()  # dark caption text on the light strip
    assert np.abs(strip_first - strip_last).sum() > 0  # the time (at least) changed
    assert "wrote r.gif" in out
