"""Parts standing on an end, found in the Look's wide view of a bin among lying ones (rendered,
noisy D435 frames; no ground truth reaches the code)."""

from __future__ import annotations

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.layout import CellLayout
from sim.camera import SimCamera
from sim.cell_layout import build_cell
from sim.part_body import lying_pose, spawn_part, upright_pose
from sim.scenes import look_down_pose
from sim.world import SimWorld
from skills.perception.bin_parts import detect_parts
from skills.perception.look import LookParams

CATALOGUE = load_catalogue()
RIGID = [p for p in CATALOGUE.parts.values() if p.rigid]


def wide_view(
    stand: str, open_up: bool, lying: list[tuple[str, float, float, float]]
) -> tuple[list, np.ndarray]:
    layout = CellLayout()
    c = np.asarray(layout.bin_center, float)
    with SimWorld(seed=5) as world:
        build_cell(world, layout)
        part = CATALOGUE.get(stand)
        spawn_part(world, part, upright_pose(part, c[0], c[1], layout.bin_floor_z, open_up))
        for name, dx, dy, yaw in lying:
            p = CATALOGUE.get(name)
            spawn_part(world, p, lying_pose(p, c[0] + dx, c[1] + dy, yaw, layout.bin_floor_z))
        for _ in range(100):
            world.step()
        mount = layout.tool_T_camera()
        tool = look_down_pose(layout.bin_center, LookParams().view_height, mount)
        cam = SimCamera(world, lambda: tool, tool_T_camera=mount)
        return detect_parts(
            cam.capture(), cam.intrinsics(), tool @ cam.tool_T_camera(), RIGID,
            layout.bin_interior(),
        ), c


@pytest.mark.parametrize("name", ["bushing", "plastic_cup", "medicine_bottle", "cookie_can"])
def test_a_part_standing_open_end_up_is_found_where_it_stands(name: str) -> None:
    # a lying cookie can beside it: its crest (66 mm) lies in the bushing's band (68 mm)
    dets, c = wide_view(name, True, [("cookie_can", 0.0, 0.09, 0.0), ("bushing", 0.1, -0.06, 1.0)])
    standing = [d for d in dets if d.standing]
    assert [d.part for d in standing] == [name]
    assert np.linalg.norm(standing[0].center[:2] - c) < 0.002
    assert standing[0].open_end_seen
    lying = sorted(d.part for d in dets if not d.standing)
    assert lying == ["bushing", "cookie_can"]  # the lying ones are still found, as lying


@pytest.mark.parametrize("name", ["plastic_cup", "medicine_bottle"])
def test_a_part_standing_on_its_open_end_is_found_with_its_open_end_not_seen(name: str) -> None:
    dets, c = wide_view(name, False, [])
    standing = [d for d in dets if d.standing]
    assert [d.part for d in standing] == [name]
    assert not standing[0].open_end_seen


def test_a_standing_part_is_scored_found_only_by_a_detection_that_says_it_stands() -> None:
    from skills.perception.bin_parts import Detection
    from skills.perception.scoring import Truth, score

    truth = Truth("plastic_cup", np.array([0.5, 0.0, 0.04]), 1.0, 1, standing=True, open_up=True)

    def seen(standing: bool) -> Detection:
        c = np.array([0.501, 0.0, 0.04])
        return Detection(c, 0.0, 0.073, 0.048, "plastic_cup", c, True, 1.0, 400, standing=standing)

    matches, missed, false = score([truth], [seen(False)])
    assert (len(matches), missed, false) == (0, 1, 1)
    matches, missed, false = score([truth], [seen(True)])
    assert (missed, false) == (0, 0) and matches[0].end_right is True and matches[0].yaw_err == 0


def test_a_bushing_lying_against_a_standing_one_is_found_too() -> None:
    # axis along y, its wall touching the standing one's: centres one outer size apart
    dets, c = wide_view("bushing", True, [("bushing", 0.034, 0.0, np.pi / 2)])
    assert sorted((d.part, d.standing) for d in dets) == [("bushing", False), ("bushing", True)]
