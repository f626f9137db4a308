"""``cell calibrate``: hand-eye calibration of the eye-in-hand camera in the PyBullet twin.

Form::

    cell calibrate [--cell FILE] [--views N] [--seed S] [--true-xyz X Y Z] [--true-rpy R P Y]

The cell is built from ``--cell`` (default layout when the option is absent or the file does not
exist yet), an AprilTag board (:class:`skills.perception.calibration.TagBoard`) is laid on the
floor at the bin's centre, and the twin's camera is mounted at a *true* mount that differs from
the configured one (``camera_xyz`` / ``camera_rpy`` of the layout): by default the configured
mount perturbed by a random offset drawn from ``--seed`` (up to 4 mm per axis and 1.5 deg per
angle); with ``--true-xyz`` (m) and/or ``--true-rpy`` (rad; roll-pitch-yaw as in
:class:`drivers.layout.CellLayout`) exactly those, a half not given staying as configured. The
arm then looks at the board from ``--views`` poses aimed with the configured mount
(:func:`skills.perception.calibration.calibration_views`), the routine
(:class:`skills.perception.calibration.HandEyeRoutine`) estimates the mount, and the command prints
it with its error against the true mount. With ``--cell`` the estimate is written to that YAML
file as ``camera_xyz`` / ``camera_rpy`` (created if missing; its other keys are kept, comments are
not). Bad input, or a board seen in too few views, ends with one line and exit status 2.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from cell.errors import UserError

#: Views allowed (the calibration needs 3; more than this adds time, not accuracy).
MIN_VIEWS, MAX_VIEWS = 3, 32
#: Half-widths of the default random offset of the true mount from the configured one.
OFFSET_MM, OFFSET_DEG = 4.0, 1.5
#: Simulated seconds the routine may take per view before the command gives up.
SECONDS_PER_VIEW = 30.0


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "calibrate",
        help="hand-eye calibration of the camera with an AprilTag board, in the twin",
        description="Lay an AprilTag 36h11 board in the simulated cell, mount the camera off its "
        "configured place, look at the board from N poses, estimate the camera-to-tool "
        "transform (cv2 hand-eye, Park-Martin), print it with its error against the true mount "
        "and write camera_xyz/camera_rpy into the --cell YAML.",
    )
    p.add_argument(
        "--layout",
        "--cell",
        dest="cell",
        type=Path,
        default=None,
        help="cell layout YAML: read (if it exists) and updated with the estimate; comments "
        "are not kept (default: the default layout, nothing written)",
    )
    p.add_argument("--views", type=int, default=8, help="poses to look from (8)")
    p.add_argument("--seed", type=int, default=0, help="seed of the true mount's offset (0)")
    p.add_argument(
        "--true-xyz",
        type=float,
        nargs=3,
        default=None,
        metavar=("X", "Y", "Z"),
        help="true camera position in the tool frame, m (default: configured + random offset)",
    )
    p.add_argument(
        "--true-rpy",
        type=float,
        nargs=3,
        default=None,
        metavar=("R", "P", "Y"),
        help="true camera roll-pitch-yaw in the tool frame, rad (default: configured + offset)",
    )
    p.set_defaults(func=cmd_calibrate)


def _read_cell(path: Path | None) -> tuple[dict[str, Any], Any]:
    """The raw mapping of the YAML file (empty if none) and its validated layout."""
    import yaml

    from drivers.layout import CellLayout

    if path is None or not path.exists():
        return {}, CellLayout().validate()
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the cell layout: {exc.strerror}") from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid YAML: {' '.join(str(exc).split())}") from None
    data = {} if data is None else data
    layout = CellLayout.from_dict(data, source=str(path))  # a non-mapping is refused here
    return dict(data), layout


def _check_triple(name: str, values: list[float] | None) -> None:
    if values is not None and not all(math.isfinite(v) for v in values):
        raise ValueError(f"{name}: must be finite numbers, got {values}")


def _mount_text(xyz: Any, rpy: Any) -> str:
    x = np.asarray(xyz, float) * 1e3
    r = np.degrees(np.asarray(rpy, float))
    return (
        f"xyz [{x[0]:8.3f} {x[1]:8.3f} {x[2]:8.3f}] mm   "
        f"rpy [{r[0]:7.3f} {r[1]:7.3f} {r[2]:7.3f}] deg"
    )


def cmd_calibrate(args: argparse.Namespace) -> int:
    import yaml
    from scipy.spatial.transform import Rotation

    from drivers.layout import CellLayout
    from drivers.pose import Pose
    from drivers.tag_board import TagBoard
    from sim.camera import SimCamera
    from sim.cell_layout import build_cell
    from sim.robot import SimRobot
    from sim.tag_board import place_tag_board
    from sim.world import SimWorld
    from skills.perception.calibration import HandEyeRoutine, calibration_views
    from skills.status import Status

    if not MIN_VIEWS <= args.views <= MAX_VIEWS:
        raise UserError(f"--views: must lie in [{MIN_VIEWS}, {MAX_VIEWS}], got {args.views}")
    _check_triple("--true-xyz", args.true_xyz)
    _check_triple("--true-rpy", args.true_rpy)
    if args.cell is not None and args.cell.is_dir():
        raise UserError(f"--cell {args.cell}: is a directory, not a YAML file")
    data, layout = _read_cell(args.cell)
    source = str(args.cell) if args.cell is not None else "the default cell layout"

    board = TagBoard()
    bx0, bx1, by0, by1 = layout.bin_interior()
    if board.size[0] > bx1 - bx0 or board.size[1] > by1 - by0:
        raise UserError(
            f"{source}: bin_inner_size: the {board.size[0]:g} x {board.size[1]:g} m calibration "
            f"board does not fit in the bin"
        )
    configured = layout.tool_T_camera()
    rng = np.random.default_rng(args.seed)
    offset_xyz = rng.uniform(-OFFSET_MM, OFFSET_MM, 3) * 1e-3
    offset_rpy = np.radians(rng.uniform(-OFFSET_DEG, OFFSET_DEG, 3))
    true_xyz = (
        np.asarray(args.true_xyz, float)
        if args.true_xyz is not None
        else np.asarray(layout.camera_xyz) + (offset_xyz if args.true_rpy is None else 0.0)
    )
    true_rpy = (
        np.asarray(args.true_rpy, float)
        if args.true_rpy is not None
        else np.asarray(layout.camera_rpy) + (offset_rpy if args.true_xyz is None else 0.0)
    )
    true_mount = Pose(true_xyz, Rotation.from_euler("xyz", true_rpy).as_matrix())

    with SimWorld(seed=args.seed) as world:
        build_cell(world, layout)
        _, base_T_board = place_tag_board(world, board, layout.bin_center, surface_z=0.0)
        robot = SimRobot(world)  # base at the world origin: world = base frame
        camera = SimCamera(
            world, lambda: robot.world_pose(robot.arm.tool_pose()), tool_T_camera=true_mount
        )
        views = calibration_views(base_T_board.position, configured, args.views)
        routine = HandEyeRoutine(robot.arm, camera, world.clock, board, views)
        limit = SECONDS_PER_VIEW * args.views
        result = routine.tick()
        while not result.done:
            if world.clock.now() > limit:
                routine.halt()
                raise UserError(f"calibration: not finished after {limit:g} s simulated")
            world.step()
            result = routine.tick()

    for i, s in enumerate(routine.samples):
        seen = (
            f"{s.markers:2d} markers, {s.rms_px:.3f} px rms"
            if s.camera_T_board is not None
            else f"no board pose: {s.note}"
        )
        print(f"view {i + 1:2d}  {seen}")
    if result.status is not Status.SUCCESS or routine.tool_T_camera is None:
        raise UserError(result.message)
    estimate = routine.tool_T_camera
    est_rpy = Rotation.from_matrix(estimate.rotation).as_euler("xyz")
    err_mm, err_rad = estimate.distance(true_mount)
    cfg_mm, cfg_rad = configured.distance(true_mount)
    print(f"configured  {_mount_text(layout.camera_xyz, layout.camera_rpy)}")
    print(f"true        {_mount_text(true_xyz, true_rpy)}")
    print(f"estimate    {_mount_text(estimate.position, est_rpy)}")
    print(
        f"error       {err_mm * 1e3:.3f} mm, {math.degrees(err_rad):.3f} deg "
        f"(configured mount: {cfg_mm * 1e3:.3f} mm, {math.degrees(cfg_rad):.3f} deg)"
    )
    print(result.message)
    if args.cell is None:
        print("no --cell given: nothing written")
        return 0
    data["camera_xyz"] = [round(float(v), 6) for v in estimate.position]
    data["camera_rpy"] = [round(float(v), 6) for v in est_rpy]
    CellLayout.from_dict(data, source=str(args.cell))  # what is written must read back
    try:
        args.cell.parent.mkdir(parents=True, exist_ok=True)
        args.cell.write_text(
            yaml.safe_dump(data, sort_keys=False, default_flow_style=None), encoding="utf-8"
        )
    except OSError as exc:
        raise UserError(f"--cell {args.cell}: cannot write: {exc.strerror}") from None
    print(f"wrote camera_xyz, camera_rpy to {args.cell}")
    return 0
