"""The wide views: the whole bin in view at the wanted parts' top, in one view or two."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.layout import CellLayout
from sim.camera import SimCamera
from sim.world import SimWorld
from skills.perception.bin_parts import Detection
from skills.perception.look import mounted_over, wholly_in_view, wide_views

HEIGHT = 0.5


def camera(layout: CellLayout, xy: tuple[float, float]):  # type: ignore[no-untyped-def]
    mount = layout.tool_T_camera()
    tool = mounted_over(xy, HEIGHT, mount)
    with SimWorld(seed=1) as world:
        cam = SimCamera(world, lambda: tool, tool_T_camera=mount)
        return cam.intrinsics(), tool @ mount


def lying(x: float, y: float, yaw: float) -> Detection:
    c = np.array([x, y, 0.017])
    return Detection(c, yaw, 0.068, 0.034, "bushing", c, True, 1.0, 900)


@pytest.mark.parametrize("size", [(0.50, 0.32), (0.50, 0.44)])
def test_a_bushing_anywhere_in_the_bin_is_wholly_in_one_of_the_wide_views(size) -> None:
    layout = CellLayout(bin_inner_size=size)
    intr, _ = camera(layout, layout.bin_center)
    views = wide_views(
        intr, layout.tool_T_camera(), layout.bin_center, layout.bin_interior(),
        layout.bin_floor_z + 0.034, HEIGHT,
    )
    assert len(views) == (2 if size[1] > 0.40 else 1)  # the shipped cell's bin needs two
    poses = [camera(layout, xy)[1] for xy in views]
    x0, x1, y0, y1 = layout.bin_interior()
    rng = np.random.default_rng(0)
    for _ in range(200):  # against the walls, any yaw
        yaw = rng.uniform(0, np.pi)
        reach = 0.5 * 0.068 * np.abs([np.cos(yaw), np.sin(yaw)]) + 0.017
        x = rng.choice([x0 + reach[0], x1 - reach[0], rng.uniform(x0 + reach[0], x1 - reach[0])])
        y = rng.choice([y0 + reach[1], y1 - reach[1], rng.uniform(y0 + reach[1], y1 - reach[1])])
        d = lying(x, y, yaw)
        assert any(wholly_in_view(d, intr, pose) for pose in poses), (x, y, yaw)


def test_a_part_the_frames_edge_cuts_is_not_wholly_in_view() -> None:
    layout = CellLayout(bin_inner_size=(0.50, 0.44))
    intr, pose = camera(layout, layout.bin_center)
    assert wholly_in_view(lying(0.47, 0.0, 0.0), intr, pose)
    assert not wholly_in_view(lying(0.47, -0.19, np.pi / 2), intr, pose)  # along the -y wall
