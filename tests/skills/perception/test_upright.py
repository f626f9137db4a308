"""Finding a standing part from a rendered, noisy D435 frame (no ground truth reaches the code)."""

from __future__ import annotations

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.pose import Pose
from sim.camera import SimCamera
from sim.cell_layout import build_cell
from sim.part_body import lying_pose, spawn_part, upright_pose
from sim.world import SimWorld
from skills.perception import locate_upright_part

DOWN = np.diag([1.0, -1.0, -1.0])  # tool z (and the optical axis) pointing down


def look(world: SimWorld, xy: np.ndarray, height: float) -> tuple[SimCamera, Pose]:
    """A camera whose optical centre is ``height`` above ``xy``."""
    cam = SimCamera(world, lambda: tool)
    offset = DOWN @ cam.tool_T_camera().position
    tool = Pose(np.array([xy[0], xy[1], height]) - offset, DOWN)
    return cam, tool


@pytest.mark.parametrize("name", ["bushing", "plastic_cup", "wiring_duct", "cookie_can"])
def test_finds_the_rim_of_a_standing_part_to_a_millimetre(name: str) -> None:
    part = load_catalogue().get(name)
    with SimWorld(seed=3) as world:
        build_cell(world)
        true_xy = np.array([0.47, 0.012])
        spawn_part(world, part, upright_pose(part, *true_xy))
        for _ in range(50):
            world.step()
        guess = true_xy + [0.03, -0.02]  # where the mechanics expected it: 3.6 cm off
        cam, tool = look(world, guess, part.length + 0.2)
        found = locate_upright_part(
            cam.capture(), cam.intrinsics(), tool @ cam.tool_T_camera(), part, guess
        )
    assert found is not None
    assert np.linalg.norm(found.center - true_xy) < 0.0015
    assert found.points > 200


def test_a_lying_part_is_not_taken_for_a_standing_one() -> None:
    part = load_catalogue().get("bushing")
    with SimWorld(seed=3) as world:
        build_cell(world)
        spawn_part(world, part, lying_pose(part, 0.47, 0.0, 0.0))
        for _ in range(50):
            world.step()
        cam, tool = look(world, np.array([0.47, 0.0]), part.length + 0.2)
        found = locate_upright_part(
            cam.capture(), cam.intrinsics(), tool @ cam.tool_T_camera(), part, [0.47, 0.0]
        )
    assert found is None


def test_a_wall_beside_the_part_is_not_taken_for_its_rim() -> None:
    """A part standing 7 cm from the bin's wall (taller than the part): the wall's inner face
    crosses the rim's height band inside the search radius and once pulled the fit off."""
    from drivers.layout import CellLayout

    part = load_catalogue().get("bushing")
    layout = CellLayout(bin_inner_size=(0.50, 0.44))  # walls at y = +-0.22, 80 mm tall
    with SimWorld(seed=3) as world:
        build_cell(world, layout)
        true_xy = np.array([0.405, 0.150])
        spawn_part(world, part, upright_pose(part, *true_xy))
        for _ in range(50):
            world.step()
        guess = true_xy + [-0.008, -0.003]
        cam, tool = look(world, guess, part.length + 0.2)
        found = locate_upright_part(
            cam.capture(), cam.intrinsics(), tool @ cam.tool_T_camera(), part, guess
        )
    assert found is not None
    assert np.linalg.norm(found.center - true_xy) < 0.0015
