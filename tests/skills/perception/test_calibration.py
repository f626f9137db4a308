"""Hand-eye calibration with an AprilTag board: the board, one view, the calibration, the CLI."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from cell.cli import main
from drivers.camera import Intrinsics
from drivers.layout import CellLayout
from drivers.pose import Pose
from drivers.tag_board import TagBoard, render_board
from sim.camera import SimCamera, default_tool_T_camera
from sim.cell_layout import build_cell
from sim.robot import SimRobot
from sim.tag_board import place_tag_board
from sim.world import SimWorld
from skills.perception.calibration import (
    HandEyeRoutine,
    board_pose_from_frame,
    calibrate_hand_eye,
    calibration_views,
    detect_board,
    hand_eye_residuals,
    park_martin,
)
from skills.status import Status

BOARD = TagBoard()
#: A mount well away from the default one (12 mm, about 4 deg).
TRUE_MOUNT = Pose(
    np.array([0.006, -0.088, -0.042]),
    Rotation.from_euler("xyz", [0.03, -0.025, 0.05]).as_matrix(),
)
MM, DEG = 1e-3, math.radians(1.0)


def _rpy(pose: Pose) -> list[float]:
    return list(Rotation.from_matrix(pose.rotation).as_euler("xyz"))


# ------------------------------------------------------------------------------ the board
def test_board_geometry() -> None:
    b = BOARD
    assert b.count == 12 and list(b.ids) == list(range(12))
    assert b.grid_size == pytest.approx((4 * 0.04 + 3 * 0.01, 3 * 0.04 + 2 * 0.01))
    assert b.size == pytest.approx((0.21, 0.16))
    c = b.marker_corners()
    assert c.shape == (12, 4, 3)
    assert np.all(c[..., 2] == 0.0)
    assert c.reshape(-1, 3).mean(axis=0) == pytest.approx([0, 0, 0], abs=1e-12)  # centred
    # Marker 0 is at the top left (+y is up in the image); corners TL, TR, BR, BL.
    assert c[0, 0] == pytest.approx([-0.095, 0.07, 0.0])
    edges = np.roll(c, -1, axis=1) - c
    for k, direction in enumerate([[1, 0, 0], [0, -1, 0], [-1, 0, 0], [0, 1, 0]]):
        assert edges[:, k] == pytest.approx(np.tile(0.04 * np.array(direction), (12, 1)))
    assert c[1, 0] - c[0, 0] == pytest.approx([0.05, 0.0, 0.0])  # next id: one pitch right
    assert c[4, 0] - c[0, 0] == pytest.approx([0.0, -0.05, 0.0])  # next row: one pitch down
    assert b.corners_of(5) == pytest.approx(c[5])
    with pytest.raises(KeyError):
        b.corners_of(12)
    assert TagBoard(first_id=100).corners_of(100) == pytest.approx(c[0])
    for bad in ({"marker_size": 0.0}, {"columns": 0}, {"first_id": 580}, {"margin": -0.01}):
        with pytest.raises(ValueError, match="board"):
            TagBoard(**bad)


def test_rendered_board_is_seen_where_its_geometry_says() -> None:
    """The printed image, taken as a fronto-parallel pinhole view, gives the exact pose."""
    ppm = 2000.0
    image = render_board(BOARD, ppm)
    assert image.shape == (320, 420) and image.dtype == np.uint8
    assert image[:20].min() == 255 and image[:, :20].min() == 255  # white margin all round
    assert image[20:100, 20:100].min() == 0
    # The image of a board at distance z, seen face on: f = ppm * z.
    z = 0.3
    intr = Intrinsics(420, 320, ppm * z, ppm * z, 0.5 * 420 - 0.5, 0.5 * 320 - 0.5)
    rgb = np.repeat(image[..., None], 3, axis=2)
    found = detect_board(rgb, intr, BOARD)
    assert found is not None and found.ids == tuple(range(12))
    assert found.rms_px < 0.1
    truth = Pose(np.array([0.0, 0.0, z]), np.diag([1.0, -1.0, -1.0]))
    dp, dr = found.camera_T_board.distance(truth)
    assert dp < 0.05 * MM and dr < 0.02 * DEG
    assert board_pose_from_frame(np.full_like(rgb, 255), intr, BOARD) is None


def test_detection_in_the_twin_recovers_the_board_pose() -> None:
    """Texture mapped the right way round, and the pose to 2 mm / 0.5 deg from tilted views."""
    with SimWorld(seed=1) as world:
        build_cell(world)
        _, base_T_board = place_tag_board(world, BOARD, (0.45, 0.02), yaw=0.4)
        assert base_T_board.position == pytest.approx([0.45, 0.02, 0.003])
        camera = SimCamera(world, lambda: Pose(), tool_T_camera=Pose(), noise=None)
        views = calibration_views(base_T_board.position, Pose(), 4)
        for view in views:  # the camera itself at each view (identity mount)
            rgb, _ = camera.render(view)
            found = detect_board(rgb, camera.intrinsics(), BOARD)
            assert found is not None and len(found.ids) >= 10
            dp, dr = (view @ found.camera_T_board).distance(base_T_board)
            assert dp < 2 * MM and dr < 0.5 * DEG, (dp, dr)


# ----------------------------------------------------------------------- the calibration
def _synthetic(n: int, mount: Pose, seed: int = 0) -> tuple[list[Pose], list[Pose]]:
    """Tool poses turning about varied axes and the exact board poses they would see."""
    rng = np.random.default_rng(seed)
    base_T_board = Pose(np.array([0.45, 0.0, 0.0]))
    tools, boards = [], []
    for _ in range(n):
        rot = Rotation.from_rotvec(rng.normal(0, 0.3, 3)).as_matrix() @ np.diag([1.0, -1, -1])
        tool = Pose(np.array([0.45, 0.0, 0.35]) + rng.normal(0, 0.05, 3), rot)
        tools.append(tool)
        boards.append((tool @ mount).inverse() @ base_T_board)
    return tools, boards


def test_calibration_is_exact_on_exact_data() -> None:
    tools, boards = _synthetic(6, TRUE_MOUNT)
    for estimate in (calibrate_hand_eye(tools, boards), park_martin(tools, boards)):
        dp, dr = estimate.distance(TRUE_MOUNT)
        assert dp < 1e-9 and dr < 1e-9
    assert hand_eye_residuals(tools, boards, TRUE_MOUNT) == pytest.approx((0, 0), abs=1e-12)
    # Views where the board was not seen are skipped.
    partial = calibrate_hand_eye(tools, boards[:3] + [None] * 3)
    assert partial.distance(TRUE_MOUNT)[0] < 1e-9


def test_fewer_than_three_views_or_one_axis_is_refused() -> None:
    tools, boards = _synthetic(4, TRUE_MOUNT)
    with pytest.raises(ValueError, match="at least 3 views"):
        calibrate_hand_eye(tools[:2], boards[:2])
    with pytest.raises(ValueError, match="got 2 of 4"):
        calibrate_hand_eye(tools, [boards[0], None, boards[2], None])
    with pytest.raises(ValueError, match="2 board poses"):
        calibrate_hand_eye(tools, boards[:2])
    # Turning only about the tool's z: the offset along z is unobservable.
    spin = [Pose(np.array([0.45, 0, 0.3]), np.diag([1.0, -1, -1]) @ _rz(a)) for a in (0, 0.3, 0.7)]
    seen = [(t @ TRUE_MOUNT).inverse() for t in spin]
    with pytest.raises(ValueError, match="two different axes"):
        calibrate_hand_eye(spin, seen)


def _rz(angle: float) -> np.ndarray:
    return Rotation.from_euler("z", angle).as_matrix()


@pytest.mark.skipif(not hasattr(cv2, "calibrateHandEye"), reason="cv2 without calibrateHandEye")
def test_opencv_and_the_fallback_agree() -> None:
    tools, boards = _synthetic(6, TRUE_MOUNT, seed=3)
    noisy = [Pose(b.position + 1e-4, b.rotation) for b in boards]
    a, b = calibrate_hand_eye(tools, noisy), park_martin(tools, noisy)
    assert a.distance(b)[0] < 1e-6


def test_calibration_in_the_twin_recovers_the_mount() -> None:
    """8 views plus one the arm cannot reach (skipped): the true mount to 2 mm and 0.5 deg."""
    with SimWorld(seed=2) as world:
        build_cell(world)
        _, base_T_board = place_tag_board(world, BOARD, (0.45, 0.0))
        robot = SimRobot(world)
        camera = SimCamera(
            world, lambda: robot.world_pose(robot.arm.tool_pose()), tool_T_camera=TRUE_MOUNT
        )
        views = calibration_views(base_T_board.position, default_tool_T_camera(), 8)
        views.insert(3, Pose(np.array([2.0, 0.0, 0.3]), np.diag([1.0, -1.0, -1.0])))
        routine = HandEyeRoutine(robot.arm, camera, world.clock, BOARD, views)
        result = routine.tick()
        while not result.done:
            assert world.clock.now() < 120.0
            world.step()
            result = routine.tick()
    assert result.status is Status.SUCCESS, result.message
    samples = routine.samples
    assert len(samples) == 9
    assert samples[3].camera_T_board is None and "arm fault" in samples[3].note
    assert sum(s.camera_T_board is not None for s in samples) == 8
    assert routine.tool_T_camera is not None and routine.residuals is not None
    dp, dr = routine.tool_T_camera.distance(TRUE_MOUNT)
    assert dp < 2 * MM and dr < 0.5 * DEG, (dp / MM, dr / DEG)
    assert routine.residuals[0] < 0.5 * MM and routine.residuals[1] < 0.2 * DEG
    assert default_tool_T_camera().distance(TRUE_MOUNT)[0] > 10 * MM  # it had to move


# ------------------------------------------------------------------------ the layout fields
def test_layout_camera_mount_fields() -> None:
    layout = CellLayout().validate()
    dp, dr = layout.tool_T_camera().distance(default_tool_T_camera())
    assert dp == 0.0 and dr == 0.0
    moved = dataclasses.replace(layout, camera_xyz=(-0.1, 0.0, -0.2), camera_rpy=(-3.0, 0.0, 1.0))
    moved.validate()  # negative and zero values are not sizes
    assert _rpy(moved.tool_T_camera()) == pytest.approx([-3.0, 0.0, 1.0])
    # scipy's extrinsic "xyz": R = Rz(yaw) Ry(pitch) Rx(roll)
    r = dataclasses.replace(layout, camera_rpy=(0.1, 0.2, 0.3)).tool_T_camera().rotation
    rx, ry, rz = (
        Rotation.from_euler(a, v).as_matrix() for a, v in zip("xyz", (0.1, 0.2, 0.3), strict=True)
    )
    assert r == pytest.approx(rz @ ry @ rx)
    with pytest.raises(ValueError, match="camera_rpy: must be finite"):
        dataclasses.replace(layout, camera_rpy=(0.0, math.nan, 0.0)).validate()
    with pytest.raises(ValueError, match=r"c.yaml: camera_rpy: expected a list of 3 numbers \(rad"):
        CellLayout.from_dict({"camera_rpy": [0.0, 0.0]}, source="c.yaml")


# ---------------------------------------------------------------------------------- the CLI
def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_writes_the_mount_and_keeps_other_keys(tmp_path: Path, capsys) -> None:
    cell = tmp_path / "cell.yaml"
    cell.write_text("bin_center: [0.47, 0.01]\nslot_clearance: 0.004\n", encoding="utf-8")
    xyz, rpy = [0.005, -0.09, -0.045], [0.02, -0.01, 0.04]
    code, out, err = _run(
        ["calibrate", "--cell", str(cell), "--views", "5", "--true-xyz", *map(str, xyz)]
        + ["--true-rpy", *map(str, rpy)],
        capsys,
    )
    assert code == 0, err
    assert "error" in out and f"wrote camera_xyz, camera_rpy to {cell}" in out
    data = yaml.safe_load(cell.read_text(encoding="utf-8"))
    assert data["bin_center"] == [0.47, 0.01] and data["slot_clearance"] == 0.004
    assert data["camera_xyz"] == pytest.approx(xyz, abs=2 * MM)
    assert data["camera_rpy"] == pytest.approx(rpy, abs=0.5 * DEG)
    layout = CellLayout.from_yaml(cell)  # reads back
    assert layout.camera_xyz == tuple(data["camera_xyz"])


def test_cli_creates_the_file_by_default(tmp_path: Path, capsys) -> None:
    cell = tmp_path / "new" / "cell.yaml"
    code, out, err = _run(["calibrate", "--cell", str(cell), "--views", "4"], capsys)
    assert code == 0, err
    assert set(yaml.safe_load(cell.read_text(encoding="utf-8"))) == {"camera_xyz", "camera_rpy"}
    line = next(x for x in out.splitlines() if x.startswith("error"))
    mm, deg = float(line.split()[1]), float(line.split()[3])
    assert mm < 2.0 and deg < 0.5


@pytest.mark.parametrize(
    ("text", "argv", "message"),
    [
        ("slot_depth: [1\n", [], "cell.yaml: not valid YAML"),
        ("- 1\n", [], "cell.yaml: expected a mapping"),
        ("camera_xyz: [0.0, 0.1]\n", [], "cell.yaml: camera_xyz: expected a list of 3"),
        ("slot_clearance: -1\n", [], "cell.yaml: slot_clearance:"),
        ("", ["--views", "2"], "--views: must lie in [3, 32]"),
        ("", ["--true-rpy", "1.2", "0", "0"], "board was seen in 0 of 3 views"),
    ],
)
def test_cli_bad_input_exits_2_in_one_line(
    tmp_path: Path, capsys, text: str, argv: list[str], message: str
) -> None:
    cell = tmp_path / "cell.yaml"
    cell.write_text(text, encoding="utf-8")
    code, _, err = _run(["calibrate", "--cell", str(cell), "--views", "3", *argv], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and message in err, err
    assert cell.read_text(encoding="utf-8") == text  # nothing written
