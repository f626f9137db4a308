"""`cell sim --record`: a readable GIF (640 x 480 overview, a gripper close-up in its corner, a
caption strip with the time, the running step and the wrist force against the running step's
own abort limit)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from cell.cell_cmds import load_prepared
from cell.recording import CLOSE_UP, OVERVIEW, STRIP, force_limit

from .test_cli import run_cli


def _cut_short_sim(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
    seconds: float, *extra: str,
) -> str:
    """`cell sim` of one cycle in ``tmp_path``, cut after ``seconds`` of simulated time; its
    standard output."""
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(
        ["sim", "--cycles", "1", "--max-sim-time", str(seconds), "--quiet", *extra], capsys
    )
    assert code == 1, err  # cut by --max-sim-time: out of time
    return out


def test_the_recorded_gif_has_the_close_up_and_the_caption(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    out = _cut_short_sim(tmp_path, capsys, monkeypatch, 5, "--record", "r.gif")
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
    # At 5 s the Grasp has the open fingers down in the bin: the close-up shows them (the 2F-85's
    # orange pads), not the bin's blue wall in front of them.
    r, g, b = inset[..., 0], inset[..., 1], inset[..., 2]
    wall = (b > r + 40) & (b > g + 20)
    pads = (r > 110) & (r - b > 80) & (g > 40) & (g < r - 25)
    assert wall.mean() < 0.3, f"{wall.mean():.0%} of the close-up is the bin's wall"
    assert pads.sum() > 300, f"{pads.sum()} pixels of finger pads in the close-up"
    strip_first, strip_last = first[h:], last[h:]
    assert (strip_first < 128).any()  # dark caption text on the light strip
    assert np.abs(strip_first - strip_last).sum() > 0  # the time (at least) changed
    assert "wrote r.gif" in out


def test_the_caption_names_the_running_steps_own_abort_force() -> None:
    prep = load_prepared(None, [])
    nodes = {n.name: n for n in prep.root.iterate()}
    assert force_limit(nodes["tilt"], 80.0) == 90.0  # the Tilt's own guard, not safety's
    assert force_limit(nodes["reposition"], 80.0) == 60.0
    assert force_limit(nodes["put back"], 80.0) == 250.0
    assert force_limit(nodes["plan pick"], 123.0) == 123.0  # no guard above: the default
    assert force_limit(None, 123.0) == 123.0  # nothing running


def test_the_trace_has_a_row_a_step_with_the_twins_own_state(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _cut_short_sim(tmp_path, capsys, monkeypatch, 3, "--trace", "t.csv")
    lines = (tmp_path / "t.csv").read_text().splitlines()
    header = lines[0].split(",")
    rows = [dict(zip(header, line.split(","), strict=True)) for line in lines[1:]]
    twin = [float(r["twin_s"]) for r in rows]
    assert np.allclose(np.diff(twin), 0.008) and 2.9 < twin[-1] - twin[0] <= 3.1
    # The tool hangs from the sensor (its weight, not zeroed) and the arm moves off home.
    assert all(5.0 < abs(float(r["fz_n"])) < 30.0 for r in rows[:5])
    z = [float(r["tcp_z_m"]) for r in rows]
    assert max(z) - min(z) > 0.01 and {r["mode"] for r in rows} & {"path", "joints"}
