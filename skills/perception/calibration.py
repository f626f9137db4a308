"""Hand-eye calibration of the eye-in-hand camera with an AprilTag board.

Backend-agnostic: frames, intrinsics and poses only (OpenCV and numpy do the work), so the same
code calibrates the twin's rendered camera and the real D435 on the UR5.

**The board** (:class:`TagBoard`) is a grid of AprilTag 36h11 markers printed on a flat plate
(see :func:`render_board` for a printable image). Its frame: origin at the centre of the marker
grid, ``x`` to the right and ``y`` up as the image is seen (marker ``first_id`` is at the top
left, ids run along rows), ``z`` out of the printed face. A board lying face up on a table has its
``z`` up.

**One view** (:func:`board_pose_from_frame`): the markers are found by
``cv2.aruco.ArucoDetector``; the pose of the board in the optical frame (``camera_T_board``) is
started from one marker by ``SOLVEPNP_IPPE_SQUARE`` (both of its solutions are tried against all
corners seen) and refined by Levenberg-Marquardt over every corner of every marker seen.

**The calibration** (:func:`calibrate_hand_eye`) solves ``A X = X B`` with
``cv2.calibrateHandEye`` for ``X = tool_T_camera`` from pairs ``(base_T_tool, camera_T_board)``
taken with the board fixed and the tool in several poses; the rotations between the poses must
turn about at least two different axes. :func:`hand_eye_residuals` says how well the views agree
(the board's pose in the base seen from each view), the figure to check on hardware, where no
true mount is known.

**The routine** (:class:`HandEyeRoutine`) drives the arm through a list of tool poses (see
:func:`calibration_views`), one non-blocking ``tick()`` per control step: move, settle, capture,
detect; then calibrates.
"""

from __future__ import annotations

import functools
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from drivers.arm import Arm, MotionState
from drivers.camera import Camera, Intrinsics
from drivers.clock import Clock
from drivers.pose import Pose
from drivers.tag_board import TagBoard, tag_dictionary
from skills.axes import Z
from skills.params import si
from skills.status import Status, StepResult

#: Fewest views :func:`calibrate_hand_eye` accepts (two relative motions).
MIN_VIEWS = 3
#: rad: a rotation between two views smaller than this gives no axis to the check that the
#: views turn about two different ones (its axis is then mostly noise).
MIN_TURN = math.radians(2.0)
#: The second singular value of the unit rotation axes between the views must reach this: below
#: it they all lie close to one axis (0: exactly one), and the mount's offset along it is
#: poorly observed.
MIN_AXES_SPREAD = 0.1
#: The floor under the eigenvalues of M^T M in Park and Martin's inverse square root: no
#: division by zero for a degenerate set of motions (calibrate_hand_eye refuses those first).
EIGEN_FLOOR = 1e-300
#: Views :func:`calibration_views` plans when not told how many: the rotations between 8 views
#: turn about many axes, and a view or two lost (board not seen) leaves enough.
VIEW_COUNT = 8
#: Board markers a view must see to be used by :class:`HandEyeRoutine`: two markers' corners
#: (eight points over the board) pin its pose down better than one marker's four.
MIN_MARKERS = 2
#: px: a view whose corners miss the fitted board pose by more than this (rms) holds a misread
#: corner and is skipped; a good view is a few hundredths of a pixel off on the twin.
MAX_RMS_PX = 2.0
#: px: the synthetic image :func:`_corner_offset` measures the detector's convention on: its
#: side, where the tag starts (rows and columns) and the tag's side, margins on every side so
#: the tag is whole and its quiet zone white.
PROBE_IMAGE, PROBE_AT, PROBE_TAG = 200, 60, 80
#: Low-discrepancy sequences of the views' tilt, distance and turn: start and step of each
#: (the golden ratio's, sqrt(2)'s and the plastic number's fractional steps, which spread any
#: number of views evenly and differently from one another), and the azimuth's offset (rad)
#: so the first view is not along the base's x axis.
TILT_START, TILT_STEP = 0.5, 0.6180339887
DIST_START, DIST_STEP = 0.25, 0.4142135624  #: sqrt(2) - 1
YAW_START, YAW_STEP = 0.1, 0.7548776662  #: 1 / the plastic number
AZIMUTH_OFFSET = 0.3  #: rad


@dataclass(frozen=True)
class HandEyeParams:
    """The hand-eye routine's motions (SI): the views it plans and the moves between them."""

    speed: float = si(
        0.2, "m/s", 0.01, 1.0,
        "of the TCP between the views: free-space moves above the board",
    )
    acceleration: float = si(0.5, "m/s^2", 0.05, 3.0, "of the TCP between the views")
    settle: float = si(
        0.3, "s", 0.0, 5.0, "wait once a move is done, before the capture: the arm at rest"
    )
    move_timeout: float = si(
        20.0, "s", 1.0, 120.0,
        "a move to a view not done after this stops the arm and fails the routine",
    )
    near: float = si(
        0.28, "m", 0.1, 1.0,
        "the nearest the camera looks at the board from: the whole board in view",
    )
    far: float = si(
        0.40, "m", 0.1, 1.0,
        "the farthest the camera looks at the board from: its markers still large enough",
    )
    min_tilt: float = si(
        math.radians(10.0), "rad", 0.0, math.radians(45.0),
        "the least tilt of the optical axis from the vertical: the rotations between the "
        "views must turn about two different axes",
    )
    max_tilt: float = si(
        math.radians(25.0), "rad", 0.0, math.radians(45.0),
        "the most tilt of the optical axis from the vertical: the markers still read",
    )
    max_yaw: float = si(
        math.radians(20.0), "rad", 0.0, math.radians(90.0),
        "the most the camera is turned about its axis from image x along base x",
    )


# ----------------------------------------------------------------------------- one view
@dataclass(frozen=True)
class BoardDetection:
    """The board seen in one image."""

    camera_T_board: Pose  #: board frame in the optical frame (m, rad)
    ids: tuple[int, ...]  #: markers of the board used
    rms_px: float  #: rms reprojection error of their corners (pixels)


def _detector() -> cv2.aruco.ArucoDetector:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
    return cv2.aruco.ArucoDetector(tag_dictionary(), params)


@functools.cache
def _corner_offset() -> float:
    """What the detector adds to every corner coordinate (px), measured once on a synthetic tag.

    OpenCV's AprilTag corner refinement (the most precise here: a few hundredths of a pixel on
    the twin's images against about 0.25 px for ``CORNER_REFINE_SUBPIX``) keeps the AprilTag
    library's convention of pixel centres at ``+0.5``, so its corners come out half a pixel right
    and down of OpenCV's (pixel centres at integers, the convention of the intrinsics and of
    ``solvePnP``). A tag whose border edge lies on the pixel boundary ``59.5`` is detected at
    ``60.0``. Measured rather than assumed, rounded to 0.5 px, so a future OpenCV that changes
    the convention needs no edit here.
    """
    dictionary = tag_dictionary()
    image = np.full((PROBE_IMAGE, PROBE_IMAGE), 255, np.uint8)
    end = PROBE_AT + PROBE_TAG
    image[PROBE_AT:end, PROBE_AT:end] = cv2.aruco.generateImageMarker(
        dictionary, 0, PROBE_TAG, borderBits=1
    )
    corners, ids, _ = _detector().detectMarkers(image)
    if ids is None or len(ids) != 1:
        return 0.0
    lo, hi = PROBE_AT - 0.5, end - 0.5  # exact: a pixel's edge is half a pixel before its centre
    true = np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]])
    offset = float(np.mean(corners[0].reshape(4, 2) - true))
    return round(2.0 * offset) / 2.0  # exact: to the half pixel the conventions differ by


def _pose(rvec: NDArray[np.float64], tvec: NDArray[np.float64]) -> Pose:
    return Pose(np.asarray(tvec, float).reshape(3), cv2.Rodrigues(np.asarray(rvec, float))[0])


def detect_board(
    rgb: NDArray[np.uint8],
    intrinsics: Intrinsics,
    board: TagBoard,
    dist_coeffs: ArrayLike | None = None,
    min_markers: int = 1,
) -> BoardDetection | None:
    """Find ``board`` in an RGB (H, W, 3) or grey (H, W) image; ``None`` if fewer than
    ``min_markers`` of its markers are seen.

    ``dist_coeffs``: OpenCV distortion coefficients of the image (none: a pinhole image, as the
    twin renders and the D435 colour stream is close to).
    """
    image = np.asarray(rgb)
    colour = image.ndim == 3  # exact: (H, W, channels), not a grey (H, W)
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if colour else image
    corners, ids, _ = _detector().detectMarkers(np.ascontiguousarray(gray, np.uint8))
    if ids is None:
        return None
    on_board = [
        (int(i), c.reshape(4, 2).astype(np.float64) - _corner_offset())
        for i, c in zip(ids.ravel(), corners, strict=True)
        if board.first_id <= int(i) < board.first_id + board.count
    ]
    if len(on_board) < max(1, min_markers):
        return None
    on_board.sort(key=lambda item: item[0])
    k = intrinsics.matrix
    dist = np.zeros(5) if dist_coeffs is None else np.asarray(dist_coeffs, float)
    obj = np.concatenate([board.corners_of(i) for i, _ in on_board])
    img = np.concatenate([c for _, c in on_board])

    # Start from the marker seen largest: IPPE_SQUARE's two solutions, judged on every corner.
    areas = [cv2.contourArea(c.astype(np.float32)) for _, c in on_board]
    best_id, best_corners = on_board[int(np.argmax(areas))]
    half = 0.5 * board.marker_size  # exact: the centre to a side of a square
    square = np.array([[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]])
    board_T_marker = Pose(board.corners_of(best_id).mean(axis=0), np.eye(3))
    n, rvecs, tvecs, _ = cv2.solvePnPGeneric(
        square, best_corners, k, dist, flags=cv2.SOLVEPNP_IPPE_SQUARE
    )
    best: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None
    for rvec, tvec in zip(rvecs[:n], tvecs[:n], strict=True):
        guess = _pose(rvec, tvec) @ board_T_marker.inverse()
        r0 = cv2.Rodrigues(guess.rotation)[0]
        err = _rms(obj, img, r0, guess.position, k, dist)
        if best is None or err < best[0]:
            best = (err, r0, guess.position.reshape(3, 1).copy())
    if best is None:
        return None
    _, rvec0, tvec0 = best
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, dist, rvec0, tvec0)
    pose = _pose(rvec, tvec)
    if pose.position[Z] <= 0:
        return None
    return BoardDetection(pose, tuple(i for i, _ in on_board), _rms(obj, img, rvec, tvec, k, dist))


def _rms(
    obj: NDArray[np.float64],
    img: NDArray[np.float64],
    rvec: NDArray[np.float64],
    tvec: NDArray[np.float64],
    k: NDArray[np.float64],
    dist: NDArray[np.float64],
) -> float:
    """Rms distance (px) between ``img`` and the projections of ``obj`` at pose (rvec, tvec)."""
    proj, _ = cv2.projectPoints(obj, np.asarray(rvec, float), np.asarray(tvec, float), k, dist)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))


def board_pose_from_frame(
    rgb: NDArray[np.uint8],
    intrinsics: Intrinsics,
    board: TagBoard,
    dist_coeffs: ArrayLike | None = None,
) -> Pose | None:
    """``camera_T_board`` (m, rad) from one RGB image, or ``None`` when the board is not seen."""
    found = detect_board(rgb, intrinsics, board, dist_coeffs)
    return None if found is None else found.camera_T_board


# ------------------------------------------------------------------------- the calibration
def calibrate_hand_eye(
    base_T_tool: Sequence[Pose],
    camera_T_board: Sequence[Pose | None],
    method: int = cv2.CALIB_HAND_EYE_PARK,
) -> Pose:
    """``tool_T_camera`` (m, rad) from views of a fixed board (eye in hand).

    ``base_T_tool[i]`` is the tool pose when view ``i`` was taken, ``camera_T_board[i]`` the board
    seen in it (``None``: not seen; such views are skipped). Solved by ``cv2.calibrateHandEye``
    (``gripper2base = base_T_tool``, ``target2cam = camera_T_board``) with ``method`` (default
    Park and Martin's). The OpenCV 5.0.0 wheels do not export that function to Python
    (opencv/opencv#29565, fixed after 5.0.0 by #29584); without it the same Park-Martin solution
    is computed here (:func:`park_martin`), whatever ``method`` says.

    Raises ``ValueError`` with fewer than :data:`MIN_VIEWS` usable views, or when the tool's
    rotations between them all turn about one axis (the mount's offset along that axis is then
    unobservable).
    """
    if len(base_T_tool) != len(camera_T_board):
        raise ValueError(
            f"hand-eye calibration: {len(base_T_tool)} tool poses but "
            f"{len(camera_T_board)} board poses"
        )
    pairs = [(t, c) for t, c in zip(base_T_tool, camera_T_board, strict=True) if c is not None]
    if len(pairs) < MIN_VIEWS:
        raise ValueError(
            f"hand-eye calibration: needs at least {MIN_VIEWS} views with the board seen, "
            f"got {len(pairs)} of {len(base_T_tool)}"
        )
    axes = []
    for i, (a, _) in enumerate(pairs):
        for b, _ in pairs[i + 1 :]:
            rel = Rotation.from_matrix(a.rotation.T @ b.rotation).as_rotvec()
            if np.linalg.norm(rel) > MIN_TURN:
                axes.append(rel / np.linalg.norm(rel))
    two = len(axes) >= 2  # exact: two axes at least
    if not two or np.linalg.svd(np.array(axes), compute_uv=False)[1] < MIN_AXES_SPREAD:
        raise ValueError(
            "hand-eye calibration: the tool must turn about at least two different axes "
            "between the views (tilt it about x and about y by 10 deg or more)"
        )
    tools = [t for t, _ in pairs]
    boards = [c for _, c in pairs]
    solver = getattr(cv2, "calibrateHandEye", None)
    if solver is None:
        return park_martin(tools, boards)
    rot, trans = solver(
        [t.rotation for t in tools],
        [t.position.reshape(3, 1) for t in tools],
        [c.rotation for c in boards],
        [c.position.reshape(3, 1) for c in boards],
        method=method,
    )
    return Pose(np.asarray(trans, float).reshape(3), np.asarray(rot, float))


def park_martin(base_T_tool: Sequence[Pose], camera_T_board: Sequence[Pose]) -> Pose:
    """Park and Martin's closed-form ``AX = XB`` (as ``cv2.CALIB_HAND_EYE_PARK``), all pairs.

    For views ``i < j``: ``A = tool_i_T_tool_j``, ``B = camera_i_T_camera_j`` (the board is
    fixed), ``X = tool_T_camera``. Rotation: with ``a``, ``b`` the rotation vectors of ``A``,
    ``B`` and ``M = sum b a^T``, ``R_X = (M^T M)^(-1/2) M^T``. Translation: least squares of
    ``(R_A - I) t_X = R_X t_B - t_A``. No checks: see :func:`calibrate_hand_eye`.
    """
    motions = []
    for i in range(len(base_T_tool)):
        for j in range(i + 1, len(base_T_tool)):
            a = base_T_tool[i].inverse() @ base_T_tool[j]
            b = camera_T_board[i] @ camera_T_board[j].inverse()
            motions.append((a, b))
    m = np.zeros((3, 3))
    for a, b in motions:
        m += np.outer(Rotation.from_matrix(b.rotation).as_rotvec(), a.rotvec)
    w, v = np.linalg.eigh(m.T @ m)
    rot = v @ np.diag(1.0 / np.sqrt(np.maximum(w, EIGEN_FLOOR))) @ v.T @ m.T
    u, _, vt = np.linalg.svd(rot)  # the nearest rotation (guards round-off)
    rot = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    lhs = np.concatenate([a.rotation - np.eye(3) for a, _ in motions])
    rhs = np.concatenate([rot @ b.position - a.position for a, b in motions])
    trans = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return Pose(trans, rot)


def hand_eye_residuals(
    base_T_tool: Sequence[Pose],
    camera_T_board: Sequence[Pose | None],
    tool_T_camera: Pose,
) -> tuple[float, float]:
    """How well the views agree under ``tool_T_camera``: rms ``(m, rad)`` of the board's pose in
    the base (``base_T_tool @ tool_T_camera @ camera_T_board``) about their mean, over the
    views where the board was seen. A few tenths of a millimetre on a good calibration."""
    seen = [
        t @ tool_T_camera @ c
        for t, c in zip(base_T_tool, camera_T_board, strict=True)
        if c is not None
    ]
    if not seen:
        raise ValueError("hand-eye residuals: no view with the board seen")
    positions = np.array([s.position for s in seen])
    mean_rot = Rotation.from_matrix(np.array([s.rotation for s in seen])).mean()
    angles = Rotation.from_matrix(np.array([s.rotation for s in seen])) * mean_rot.inv()
    pos = float(np.sqrt(np.mean(np.sum((positions - positions.mean(axis=0)) ** 2, axis=1))))
    return pos, float(np.sqrt(np.mean(angles.magnitude() ** 2)))


# ------------------------------------------------------------------------------ the routine
def calibration_views(
    target: ArrayLike,
    tool_T_camera: Pose,
    count: int = VIEW_COUNT,
    params: HandEyeParams | None = None,
) -> list[Pose]:
    """``count`` tool poses (base frame, m, rad) from which the camera looks at ``target``.

    ``target`` (3,): the board's centre in the base frame; ``tool_T_camera``: the mount as
    configured (it only aims the views: a few millimetres or degrees off still see the board).
    The optical axis points at ``target`` from between ``params.near`` and ``params.far`` (m),
    tilted from the vertical by ``params.min_tilt`` to ``params.max_tilt`` (rad) towards azimuths
    spread evenly around it, and the camera is turned about its axis by up to
    ``params.max_yaw`` (rad) from "image x along base x" (the tool pointing down as at the
    robot's home). Tilt, distance and turn vary from view to view along low-discrepancy
    sequences, so the motions between views turn about many axes, as the calibration needs.
    """
    p = params if params is not None else HandEyeParams()
    distance, tilt, max_yaw = (p.near, p.far), (p.min_tilt, p.max_tilt), p.max_yaw
    if count < 1:
        raise ValueError(f"count: must be >= 1, got {count}")
    centre = np.asarray(target, float).reshape(3)
    down = np.diag([1.0, -1.0, -1.0])  # optical z along base -z, optical x along base x
    views = []
    for i in range(count):
        azimuth = 2.0 * math.pi * i / count + AZIMUTH_OFFSET  # exact: a full turn, evenly
        g_tilt = (TILT_START + i * TILT_STEP) % 1.0
        g_dist = (DIST_START + i * DIST_STEP) % 1.0
        g_yaw = (YAW_START + i * YAW_STEP) % 1.0
        t = tilt[0] + (tilt[1] - tilt[0]) * g_tilt
        d = distance[0] + (distance[1] - distance[0]) * g_dist
        yaw = max_yaw * (2.0 * g_yaw - 1.0)  # exact: [0, 1) onto [-1, 1)
        axis = np.array([-math.sin(azimuth), math.cos(azimuth), 0.0])
        rot = (
            Rotation.from_rotvec(t * axis).as_matrix()
            @ down
            @ Rotation.from_euler("z", yaw).as_matrix()
        )
        camera = Pose(centre - d * rot[:, Z], rot)
        views.append(camera @ tool_T_camera.inverse())
    return views


@dataclass(frozen=True)
class CalibrationSample:
    """One view of the routine."""

    base_T_tool: Pose  #: measured tool pose at the capture (or where the arm stopped)
    camera_T_board: Pose | None  #: ``None``: board not seen, or the view was skipped
    markers: int = 0  #: board markers seen
    rms_px: float = math.nan  #: reprojection rms of their corners (px)
    note: str = ""  #: why the view has no board pose


@dataclass
class _ViewState:
    index: int = 0
    phase: str = "start"  # start -> moving -> settling -> (capture) -> start of the next view
    since: float = 0.0
    samples: list[CalibrationSample] = field(default_factory=list)


class HandEyeRoutine:
    """Move through ``views`` (tool poses, base frame), capture the board at each, calibrate.

    Non-blocking: each :meth:`tick` is one control step (start a move, poll it, wait
    ``params.settle`` s once it is done, capture and detect). A view the arm cannot reach (its
    motion faults or stops), where the camera times out, sees fewer than ``min_markers`` markers,
    or where their corners miss the fitted pose by more than ``max_rms_px`` (a misread corner) is
    recorded with a note and skipped; a move that takes longer than ``params.move_timeout`` s
    stops the arm and fails the routine. At the end :func:`calibrate_hand_eye` runs on the views
    that saw the board: SUCCESS leaves ``tool_T_camera`` and ``residuals`` (see
    :func:`hand_eye_residuals`); too few views or a degenerate set is a FAILURE saying so.
    Free-space moves above the board, at ``params.speed`` and ``params.acceleration``
    (:class:`HandEyeParams`): clear the space between the views first.
    """

    def __init__(
        self,
        arm: Arm,
        camera: Camera,
        clock: Clock,
        board: TagBoard,
        views: Sequence[Pose],
        params: HandEyeParams | None = None,
        min_markers: int = MIN_MARKERS,
        max_rms_px: float = MAX_RMS_PX,
        dist_coeffs: ArrayLike | None = None,
    ) -> None:
        if not views:
            raise ValueError("hand-eye routine: no views given")
        self.arm, self.camera, self.clock, self.board = arm, camera, clock, board
        self.views = list(views)
        self.params = p = params if params is not None else HandEyeParams()
        self.speed, self.acceleration, self.settle = p.speed, p.acceleration, p.settle
        self.move_timeout, self.min_markers = p.move_timeout, min_markers
        self.max_rms_px = max_rms_px
        self.dist_coeffs = dist_coeffs
        self._state = _ViewState()
        self._result: StepResult | None = None
        self.tool_T_camera: Pose | None = None
        self.residuals: tuple[float, float] | None = None

    @property
    def samples(self) -> list[CalibrationSample]:
        return list(self._state.samples)

    def tick(self) -> StepResult:
        if self._result is not None:
            return self._result
        st = self._state
        if st.index >= len(self.views):
            self._result = self._finish()
            return self._result
        now = self.clock.now()
        label = f"hand-eye view {st.index + 1}/{len(self.views)}"
        if st.phase == "start":
            self.arm.move_to(self.views[st.index], self.speed, self.acceleration)
            st.phase, st.since = "moving", now
            return StepResult(Status.RUNNING, f"{label}: moving")
        if st.phase == "moving":
            state = self.arm.status()
            if state.state is MotionState.DONE:
                st.phase, st.since = "settling", now
            elif state.state in (MotionState.FAULT, MotionState.STOPPED, MotionState.IDLE):
                reason = state.message or state.state.value
                self._skip(f"arm {state.state.value}: {reason}")
            elif now - st.since > self.move_timeout:
                self.arm.stop()
                self._result = StepResult(
                    Status.FAILURE,
                    f"{label}: move not done after {now - st.since:.1f} s; arm stopped",
                )
                return self._result
            return StepResult(Status.RUNNING, f"{label}: moving")
        if now - st.since < self.settle:
            return StepResult(Status.RUNNING, f"{label}: settling")
        self._capture()
        return StepResult(Status.RUNNING, f"{label}: captured")

    def halt(self) -> None:
        """Stop the arm (idempotent); the routine does not resume."""
        self.arm.stop()
        if self._result is None:
            self._result = StepResult(Status.FAILURE, "hand-eye calibration: halted")

    def _next(self, sample: CalibrationSample) -> None:
        self._state.samples.append(sample)
        self._state.index += 1
        self._state.phase = "start"

    def _skip(self, note: str) -> None:
        self._next(CalibrationSample(self.arm.tool_pose(), None, note=note))

    def _capture(self) -> None:
        try:
            frame = self.camera.capture()
        except TimeoutError as exc:
            self._skip(f"no camera frame: {exc}")
            return
        tool = self.arm.tool_pose()
        found = detect_board(
            frame.rgb,
            self.camera.intrinsics(),
            self.board,
            self.dist_coeffs,
            min_markers=self.min_markers,
        )
        if found is None:
            self._next(
                CalibrationSample(tool, None, note=f"fewer than {self.min_markers} markers seen")
            )
        elif found.rms_px > self.max_rms_px:
            note = f"corners off their fit by more than {self.max_rms_px:g} px rms"
            self._next(CalibrationSample(tool, None, len(found.ids), found.rms_px, note))
        else:
            self._next(CalibrationSample(tool, found.camera_T_board, len(found.ids), found.rms_px))

    def _finish(self) -> StepResult:
        samples = self._state.samples
        tools = [s.base_T_tool for s in samples]
        boards = [s.camera_T_board for s in samples]
        seen = sum(b is not None for b in boards)
        if seen < MIN_VIEWS:
            missed = Counter(s.note for s in samples if s.camera_T_board is None)
            notes = "; ".join(f"{n} x {note}" for note, n in missed.items())
            return StepResult(
                Status.FAILURE,
                f"hand-eye calibration: the board was seen in {seen} of {len(samples)} views, "
                f"needs at least {MIN_VIEWS} ({notes})",
            )
        try:
            estimate = calibrate_hand_eye(tools, boards)
        except (ValueError, cv2.error) as exc:
            return StepResult(Status.FAILURE, str(exc))
        self.tool_T_camera = estimate
        self.residuals = hand_eye_residuals(tools, boards, estimate)
        return StepResult(
            Status.SUCCESS,
            f"hand-eye calibration: {seen} of {len(samples)} views; the board's pose in the base "
            f"agrees to {self.residuals[0] * 1e3:.2f} mm, "
            f"{math.degrees(self.residuals[1]):.3f} deg rms",
        )
