"""The classical bin pipeline on rendered, noisy frames (ground truth only scores)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.camera import Frame
from drivers.layout import CellLayout
from sim.camera import SimCamera, default_tool_T_camera
from sim.cell_layout import build_cell
from sim.scenes import look_down_pose, random_bin_scene
from sim.world import SimWorld
from skills.perception.bin_parts import detect_parts
from skills.perception.heightmap import PerceptionInputError
from skills.perception.scoring import Truth, score

CATALOGUE = load_catalogue()
PARTS = [p for p in CATALOGUE.parts.values() if p.rigid]
LAYOUT = CellLayout()


def render(seed: int, n_parts: int | None):
    rng = np.random.default_rng(seed)
    with SimWorld(seed=seed) as world:
        build_cell(world, LAYOUT)
        n = int(rng.integers(1, 7)) if n_parts is None else n_parts
        scene = random_bin_scene(world, LAYOUT, PARTS, rng, n) if n else []
        tool = look_down_pose(LAYOUT.bin_center, 0.5, default_tool_T_camera())
        cam = SimCamera(world, lambda: tool)
        frame = cam.capture()
    truths = [Truth(t.name, t.center, t.yaw, CATALOGUE.get(t.name).open_ends) for _, t in scene]
    return frame, cam.intrinsics(), tool @ cam.tool_T_camera(), truths


@pytest.mark.parametrize("seed", [1, 3, 9])
def test_fixed_scenes_are_found_to_tolerance(seed: int) -> None:
    frame, intr, pose, truths = render(seed, None)
    dets = detect_parts(frame, intr, pose, PARTS, LAYOUT.bin_interior())
    matches, missed, false_pos = score(truths, dets)
    assert missed == 0 and false_pos == 0
    for m in matches:
        assert m.pos_err < 0.003, m.truth.name
        assert m.yaw_err < math.radians(3.0), m.truth.name
        assert m.detection.part == m.truth.name


def test_an_empty_bin_gives_no_detections() -> None:
    frame, intr, pose, _ = render(5, 0)
    assert detect_parts(frame, intr, pose, PARTS, LAYOUT.bin_interior()) == []


def test_touching_parts_are_separated() -> None:
    for seed in range(40):  # the first scene with two parts touching side by side
        rng = np.random.default_rng(seed)
        frame, intr, pose, truths = render(seed, None)
        close = [
            (a, b)
            for i, a in enumerate(truths)
            for b in truths[i + 1 :]
            if np.linalg.norm(a.center[:2] - b.center[:2])
            < 0.55 * (CATALOGUE.get(a.name).outer + CATALOGUE.get(b.name).outer) + 0.002
        ]
        if close and all(t.name != "mounting_rail" for t in truths):
            break
    else:
        pytest.skip("no touching pair rendered")
    _ = rng
    dets = detect_parts(frame, intr, pose, PARTS, LAYOUT.bin_interior())
    _, missed, false_pos = score(truths, dets)
    assert missed == 0 and false_pos == 0


def _found(seed: int) -> tuple[list, int, int]:
    frame, intr, pose, truths = render(seed, None)
    dets = detect_parts(frame, intr, pose, PARTS, LAYOUT.bin_interior())
    return score(truths, dets)


@pytest.mark.parametrize(
    "seed",
    [
        10062,  # against a duct's side wall: the watershed let the rail climb the wall
        10015,  # between a bushing and a bottle, and one beside a bottle
        10193,  # alone, its noisy top seeded in pieces that were never joined
    ],
)
def test_rails_beside_tall_parts_and_alone_are_found(seed: int) -> None:
    matches, missed, false_pos = _found(seed)
    assert missed == 0 and false_pos == 0
    rails = [m for m in matches if m.truth.name == "mounting_rail"]
    assert rails
    for m in rails:
        assert m.detection.part == "mounting_rail"
        assert m.pos_err < 0.003 and m.yaw_err < math.radians(3.0)


def test_a_rail_running_under_a_cup_is_placed_from_its_free_end() -> None:
    matches, missed, false_pos = _found(10211)  # half of it under a cup, a duct beside it
    assert missed == 0 and false_pos == 0
    (rail,) = [m for m in matches if m.truth.name == "mounting_rail"]
    assert rail.pos_err < 0.004 and rail.detection.confidence <= 0.2


def test_two_rails_side_by_side_one_under_a_can_are_both_found() -> None:
    # One segment 10.7 mm wide (a rail and 3 mm of a second one beside it, the rest of that
    # one under a can's overhang): it was fitted as one rail between the two.
    matches, missed, false_pos = _found(10173)
    assert missed == 0 and false_pos == 0
    rails = [m for m in matches if m.truth.name == "mounting_rail"]
    assert len(rails) == 2
    for m in rails:
        assert m.detection.part == "mounting_rail"
        assert m.pos_err < 0.003 and m.yaw_err < math.radians(3.0)
    assert min(m.detection.confidence for m in rails) <= 0.2  # the clipped one's centre is
    # placed from the catalogue width


@pytest.mark.parametrize(
    "seed",
    [
        10079,  # 11 mm of it out from under a cup's end (118 pixels)
        pytest.param(
            10176,  # a stub beside a cup, 111 pixels of it seen
            marks=pytest.mark.xfail(
                strict=True, reason="placed 8.2 mm and 13 deg off: not solved for this stub"
            ),
        ),
    ],
)
def test_a_rail_stub_out_from_under_a_cup_is_found(seed: int) -> None:
    matches, missed, false_pos = _found(seed)
    assert missed == 0 and false_pos == 0
    (rail,) = [m for m in matches if m.truth.name == "mounting_rail"]
    assert rail.detection.part == "mounting_rail"
    assert rail.pos_err < 0.004 and rail.yaw_err < math.radians(5.0)
    assert rail.detection.confidence <= 0.2


@pytest.mark.parametrize(
    "seed",
    [
        10067,  # a strip of a can's flank was reported as a cup
        10190,  # two ducts touching end to side, one flat segment shaped like a Z
    ],
)
def test_touching_big_parts_give_each_part_once(seed: int) -> None:
    _, missed, false_pos = _found(seed)
    assert missed == 0 and false_pos == 0


def test_bad_frames_are_refused_by_name() -> None:
    frame, intr, pose, _ = render(1, 1)
    no_depth = Frame(rgb=frame.rgb, depth=np.zeros_like(frame.depth), stamp=0.0)
    with pytest.raises(PerceptionInputError, match="no valid pixel"):
        detect_parts(no_depth, intr, pose, PARTS)
    wrong_shape = Frame(rgb=frame.rgb, depth=frame.depth[::2], stamp=0.0)
    with pytest.raises(PerceptionInputError, match="intrinsics say"):
        detect_parts(wrong_shape, intr, pose, PARTS)
    wrong_type = Frame(rgb=frame.rgb, depth=(frame.depth * 1000).astype(np.uint16), stamp=0.0)
    with pytest.raises(PerceptionInputError, match="dtype"):
        detect_parts(wrong_type, intr, pose, PARTS)
    with pytest.raises(PerceptionInputError, match="intrinsics"):
        detect_parts(frame, None, pose, PARTS)  # type: ignore[arg-type]


def test_dot_last_is_the_matrix_product() -> None:
    from skills.perception.heightmap import dot_last

    a = np.random.default_rng(0).standard_normal((50, 40, 3)).astype(np.float32)
    w = np.array([0.3, -1.2, 2.0])
    assert np.allclose(dot_last(a, w), a @ w.astype(np.float32), atol=1e-5)


OWN = load_catalogue(Path(__file__).parents[2] / "data" / "own_parts.yaml")
OWN_PARTS = [p for p in OWN.parts.values() if p.rigid]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_short_wide_sleeve_lying_is_placed_along_its_axis(seed: int) -> None:
    """The short sleeve (50 mm long, 60 mm across) shows a top wider than long: its axis is
    the crest's direction, not the top's principal one (the Grasp came 64-90 deg off)."""
    sleeve = OWN.get("short_sleeve")
    rng = np.random.default_rng(seed)
    with SimWorld(seed=seed) as world:
        build_cell(world, LAYOUT)
        scene = random_bin_scene(world, LAYOUT, [sleeve], rng, 1)
        tool = look_down_pose(LAYOUT.bin_center, 0.5, default_tool_T_camera())
        cam = SimCamera(world, lambda: tool)
        frame = cam.capture()
    ((_, truth),) = scene
    pose = tool @ cam.tool_T_camera()
    dets = detect_parts(frame, cam.intrinsics(), pose, OWN_PARTS, LAYOUT.bin_interior())
    assert [d.part for d in dets] == ["short_sleeve"]
    off = (dets[0].yaw - truth.yaw) % math.pi  # a tube: either end
    assert min(off, math.pi - off) < math.radians(3.0)
