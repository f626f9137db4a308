"""The wide view's height: the whole bin in view at the wanted parts' top, no higher."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.layout import CellLayout
from sim.camera import SimCamera
from sim.world import SimWorld
from skills.perception.look import COVER_STEP, covering_height, mounted_over


def corners_in_view(layout: CellLayout, height: float, top: float) -> bool:
    with SimWorld(seed=1) as world:
        mount = layout.tool_T_camera()
        tool = mounted_over(layout.bin_center, height, mount)
        cam = SimCamera(world, lambda: tool, tool_T_camera=mount)
        k, view = cam.intrinsics(), tool @ mount
    x0, x1, y0, y1 = layout.bin_interior()
    local = (np.array([[x, y, top] for x in (x0, x1) for y in (y0, y1)]) - view.position)
    local = local @ view.rotation
    u = k.fx * local[:, 0] / local[:, 2] + k.cx
    v = k.fy * local[:, 1] / local[:, 2] + k.cy
    return bool(np.all((u >= 0) & (u <= k.width) & (v >= 0) & (v <= k.height)))


@pytest.mark.parametrize("size", [(0.50, 0.32), (0.50, 0.44)])
def test_the_wide_view_rises_just_enough_to_take_in_the_bin(size) -> None:
    layout = CellLayout(bin_inner_size=size)
    top = layout.bin_floor_z + 0.034  # a bushing's top, lying
    with SimWorld(seed=1) as world:
        cam = SimCamera(world, lambda: None, tool_T_camera=layout.tool_T_camera())
        intr = cam.intrinsics()
    h = covering_height(
        intr, layout.tool_T_camera(), layout.bin_center, layout.bin_interior(), top, 0.5, 0.7
    )
    assert corners_in_view(layout, h, top)
    if h > 0.5:  # raised: one step lower leaves a corner out
        assert not corners_in_view(layout, h - COVER_STEP, top)
    assert (h > 0.5) == (size[1] > 0.40)  # the shipped cell's 0.44 m bin needs more than 0.5 m
