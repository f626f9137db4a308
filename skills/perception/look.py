"""The Look skill: bring the wrist camera over the bin, find the parts, and, for a cup or bottle
whose open end the first view could not tell, look again from beyond its ends."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.camera import Frame, Intrinsics
from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose, rot_z
from skills.axes import XY, Z
from skills.frames import frame_step
from skills.motion import Guard, GuardedMotion, Sequence
from skills.params import si
from skills.perception.bin_parts import (
    Detection,
    combine_end_views,
    detect_parts,
    open_end_from_view,
)
from skills.status import Failure, Status, StepResult

DOWN = np.diag([1.0, -1.0, -1.0])
#: m: a part an earlier view found within this of one a later view found is that same part (the
#: later view refines it); farther away, a part the later, closer view did not see, kept. About
#: five times the shift between the views that a 0.5 deg hand-eye error makes (4 mm from the
#: wide view, see LookParams.close_height).
SAME_PART_DISTANCE = 0.02
#: a closing line whose horizontal part is shorter than this (of a unit vector: within 0.6 deg of
#: vertical) has no yaw to turn the camera to
VERTICAL_X = 0.01
#: ``turn_view_to_grasp`` at or above this turns the last view (the key is 0 or 1)
TURN_VIEW = 0.5
#: m of path a straight move counts per radian of its turn (the UR5's moveL and its twin's):
#: a move that turns more than it travels is timed by its turn at this rate
TURN_PATH = 0.1


def camera_over(
    xy: tuple[float, float], height: float, dev: Devices, yaw: float = 0.0
) -> Pose:
    """Tool pose (pointing down, turned ``yaw`` rad about the vertical) with the optical centre
    ``height`` above ``xy`` (m)."""
    assert dev.camera is not None
    return mounted_over(xy, height, dev.camera.tool_T_camera(), yaw)


def mounted_over(xy: tuple[float, float], height: float, tool_T_camera: Pose, yaw: float = 0.0
                 ) -> Pose:
    """:func:`camera_over` for a camera mounted at ``tool_T_camera``."""
    rotation = rot_z(yaw) @ DOWN
    offset = rotation @ tool_T_camera.position
    return Pose(np.array([xy[0], xy[1], height]) - offset, rotation)


def _in_image(intr: Intrinsics, view: Pose, points: NDArray[np.float64]) -> bool:
    """All ``points`` (world, m) in front of the camera at ``view`` and inside its image."""
    local = (points - view.position) @ view.rotation  # the points in the camera frame
    if not np.all(local[:, Z] > 0.0):
        return False
    u = intr.fx * local[:, 0] / local[:, Z] + intr.cx
    v = intr.fy * local[:, 1] / local[:, Z] + intr.cy
    return bool(np.all((u >= 0) & (u <= intr.width) & (v >= 0) & (v <= intr.height)))


def _box(roi: tuple[float, float, float, float], z: float) -> NDArray[np.float64]:
    x0, x1, y0, y1 = roi
    return np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1)])


#: m, steps of the search for where the wide views stand apart
COVER_STEP = 0.005


def wide_views(
    intr: Intrinsics,
    tool_T_camera: Pose,
    xy: tuple[float, float],
    roi: tuple[float, float, float, float],
    top_z: float,
    height: float,
) -> list[tuple[float, float]]:
    """Where the wide views stand (camera ``height`` m up, :func:`camera_over`) so that they take
    in all of the bin's inside ``roi`` at ``top_z``, the height of the lying parts' tops: over
    ``xy`` when one view does; else two, each over half the bin, as close to ``xy`` as that
    allows (a bin wider than one view: a part along a wall outside the frame is half seen,
    not fitted, and never picked -- and a camera raised to see it all is out of the UR5's
    reach over the shipped cell's bin)."""
    def sees(at: tuple[float, float], part: tuple[float, float, float, float]) -> bool:
        view = mounted_over(at, height, tool_T_camera) @ tool_T_camera
        return _in_image(intr, view, _box(part, top_z))

    if sees(xy, roi):
        return [xy]
    x0, x1, y0, y1 = roi
    cx, cy = xy
    halves = (  # (the two halves, the direction the views move apart in)
        (((x0, x1, y0, cy), (x0, x1, cy, y1)), (0.0, 1.0)),
        (((x0, cx, y0, y1), (cx, x1, y0, y1)), (1.0, 0.0)),
    )
    reach = max(x1 - x0, y1 - y0)
    for (low, high), (dx, dy) in halves:
        shift = COVER_STEP
        while shift < reach:
            a = (cx - shift * dx, cy - shift * dy)
            b = (cx + shift * dx, cy + shift * dy)
            if sees(a, low) and sees(b, high):
                return [a, b]
            shift += COVER_STEP
    return [xy]  # no pair does: the one view, as before


def merge_views(earlier: list[Detection], later: list[Detection]) -> list[Detection]:
    """What two views found: the later view's parts, and the earlier's it did not see again
    (a part within SAME_PART_DISTANCE of one it found)."""
    merged = list(later)
    for old in earlier:
        if all(math.dist(old.center[XY], d.center[XY]) > SAME_PART_DISTANCE for d in later):
            merged.append(old)
    return merged


def wholly_in_view(d: Detection, intr: Intrinsics, world_T_camera: Pose) -> bool:
    """Whether all of ``d``'s outline (its box, up to its top) lies in the frame: a part the
    frame's edge cuts is fitted from a piece (too short, its centre off)."""
    r = 0.5 * d.outer  # exact: the radius
    top = float(d.center[Z]) + (0.5 * d.length if d.standing else r)  # exact: halves
    if d.standing:
        along, across = np.array([r, 0.0]), np.array([0.0, r])
    else:
        u = np.array([math.cos(d.yaw), math.sin(d.yaw)])
        along, across = 0.5 * d.length * u, r * np.array([-u[1], u[0]])  # exact: half length
    c = np.asarray(d.center[XY], float)
    corners = [c + sa * along + sb * across for sa in (1, -1) for sb in (1, -1)]
    pts = np.array([[p[0], p[1], top] for p in corners])
    return _in_image(intr, world_T_camera, pts)


def tool_yaw(rotation: np.ndarray) -> float:
    """The yaw (rad) :func:`camera_over` takes for a tool whose closing line (x) points as in
    ``rotation``'s, seen from above: the look's last view turned to it leaves the next skill
    only the tilt to make. A closing line that is vertical has no yaw: 0."""
    x = rotation[:, 0]
    if math.hypot(float(x[0]), float(x[1])) < VERTICAL_X:
        return 0.0
    return math.atan2(float(x[1]), float(x[0]))


@dataclass(frozen=True)
class LookParams:
    """The ``skills.perceive`` section of a cell's configuration (SI)."""

    view_height: float = si(
        0.5, "m", 0.2, 1.0,
        "of the camera over the bin, the wide view (two, over each half, where one does not "
        "take in the whole bin at the lying parts' top)",
    )
    second_height: float = si(0.35, "m", 0.15, 1.0, "of the camera for the look at an end")
    second_offset: float = si(
        0.10, "m", 0.0, 0.3, "beyond the part's end the second view looks from"
    )
    close_height: float = si(
        0.25, "m", 0.15, 1.0,
        "of the camera over the chosen part for the last view, which refines its centre and "
        "yaw: a hand-eye rotation error shifts what the camera sees by that error times the "
        "distance (0.5 deg: 4 mm from the wide view, 2 mm from here)",
    )
    speed: float = si(0.25, "m/s", 0.01, 1.0, "of the TCP between views")
    turn_speed: float = si(
        0.25, "m/s", 0.01, 1.0,
        "of the TCP, at most, in the move to the close view when it turns the tool to the next "
        "skill's yaw: a straight move turns the tool along with its path (0.1 m of path a "
        "radian on the UR5 and its twin), so this bounds the wrist's turn (2.5 rad/s, under "
        "the UR5's 3.1 rad/s joint speed)",
    )
    #: the path per radian of turn differs with the move (0.09 m/rad over a part at the bin's
    #: near edge, where the base joint turned too: the wrist's last joint then ran past its
    #: pi rad/s and the arm stopped), so the turn's own rate is bounded as well
    turn_rate: float = si(
        1.5, "rad/s", 0.1, 3.0,
        "of the tool's turn, at most, in every move between views that turns the tool (the "
        "close view turned to the next skill's yaw; the wide view after a drag)",
    )
    acceleration: float = si(1.0, "m/s^2", 0.05, 3.0, "of the TCP between views")
    #: 1 by default: the pivot's own trials take the view turned (`cell pivot`, `cell compare`:
    #: the same success, 1-2 s less tact). The shipped cell example sets 0: with the turned view
    #: its cell packed 36 of 41 parts judged home on seeds 62401-62405 against 45 of 45
    #: (docs/pivot_in_hand.md); why is not found.
    turn_view_to_grasp: float = si(
        1.0, "1", 0.0, 1.0,
        "1: the last view is taken with the tool turned to the yaw the next skill holds it at "
        "(the wrist's turn happens in the look's faster move); 0: the views keep one yaw",
    )
    guard: Guard = field(default_factory=Guard)


def end_views(
    d: Detection,
    offset: float,
    roi: tuple[float, float, float, float] | None = None,
    others: list[Detection] | tuple[Detection, ...] = (),
) -> list[tuple[float, float]]:
    """Where the camera looks from to see each end face of ``d``: ``offset`` beyond the end on
    its axis, the better place first. From there that end's face (and, through an open end, the
    inside) is in sight, unless the end is against a wall (the place is then over the wall or
    outside the bin) or a neighbour stands in front of it: the place deeper inside the bin
    ``roi`` and farther from the other parts comes first."""
    u = np.array([math.cos(d.yaw), math.sin(d.yaw)])
    reach = 0.5 * d.length + offset  # exact: the end is half the length from the centre
    places = [d.center[XY] + s * reach * u for s in (1.0, -1.0)]

    def room(xy: np.ndarray) -> float:
        inside = math.inf
        if roi is not None:
            x0, x1, y0, y1 = roi
            inside = min(xy[0] - x0, x1 - xy[0], xy[1] - y0, y1 - xy[1])
        near = [
            math.dist(xy, o.center[XY]) - 0.5 * o.outer  # exact: the radius is half the size
            for o in others
            if o is not d
        ]
        return min([inside, *near, 1.0])

    places.sort(key=room, reverse=True)
    return [(float(xy[0]), float(xy[1])) for xy in places]


class Look:
    """``result``: the detection to pick (nearest ``near_xy``), or a failure.

    Steps: camera over the bin, find the parts; for a cup or bottle whose open end that view
    did not decide, the camera beyond the end with more room in front of it, its open end
    judged from there, and, still undecided, the same from beyond its other end (for a part
    decided, one closer look from above instead)."""

    def __init__(
        self,
        dev: Devices,
        catalogue: list[Part],
        roi: tuple[float, float, float, float],
        view_xy: tuple[float, float],
        near_xy: tuple[float, float],
        params: LookParams | None = None,
        grip_yaw: Callable[[Detection], float] | None = None,
        reach: Callable[[list[Pose]], int | None] | None = None,
        floor_z: float = 0.0,
        wanted_top: float | None = None,
    ) -> None:
        """``grip_yaw``: the yaw (rad, as :func:`tool_yaw` gives it) the next skill holds the tool
        at over the chosen part. The close view is taken turned to it, so the wrist turns during
        the look's fast move between views rather than in the next skill's slower approach (a
        tube's pivot from its outer end turns the wrist by half a turn). ``reach``: the arm's
        reach from where it stands (index of the first pose it cannot reach, or None); a close
        view turned out of reach (near the robot's base, after a drag) is taken unturned.
        ``floor_z``: the bin floor's height, under the lying parts' tops the wide view must
        take in (:func:`wide_views`); ``wanted_top``: how high (m, over the floor) the
        parts the cell wants to find reach lying (default: the catalogue's tallest)."""
        self.params = params if params is not None else LookParams()
        self._grip_yaw = grip_yaw
        self._reach = reach
        self.dev, self.catalogue, self.roi = dev, catalogue, roi
        self.floor_z = floor_z  #: m, the bin floor's height (the wide view's cover)
        self.wanted_top = (
            wanted_top
            if wanted_top is not None
            else max((part.outer for part in catalogue), default=0.0)
        )
        self._view_xy, self._near_xy = view_xy, near_xy
        self.result: Detection | None = None
        self.detections: list[Detection] = []
        self._undecided: Detection | None = None  #: the part the end views are for
        self._judged: list[Detection] = []  #: what each end view said of it
        self._looked_again = False  #: the closer look from above taken (a part decided)
        self._out_of_reach = False  #: the last end view asked for was out of the arm's reach
        self._wide = [view_xy]  #: where the wide views stand
        if dev.camera is not None:
            self._wide = wide_views(
                dev.camera.intrinsics(), dev.camera.tool_T_camera(), view_xy, roi,
                floor_z + self.wanted_top, self.params.view_height,
            )
        g = self.params.guard
        self.sequence = Sequence(
            "look",
            [
                dev.move("camera over the bin", g, lambda: self._over_bin(0)),
                self._wide_step("find the parts", self._none_yet, lambda: True),
                dev.move("camera over the rest of the bin", g, lambda: self._over_bin(1)),
                self._wide_step("find the parts there", self._none_found, self._two_views),
                dev.move("camera beyond its end", g, lambda: self._beyond_end(0)),
                self._detect_step("look at its end", judge_end=True),
                dev.move("camera beyond its other end", g, lambda: self._beyond_end(1)),
                self._detect_step("look at its other end", judge_end=True),
                dev.move("camera over the part", g, self._over_part),
                frame_step("refine its pose", dev, g, self._detect_work, self._refine),
            ],
        )

    def _two_views(self) -> bool:
        return len(self._wide) > 1

    def _none_yet(self) -> str | None:
        """After the first wide view: nothing found fails only when no second view follows."""
        return None if self._two_views() else self._none_found()

    def _wide_step(
        self, name: str, failed: Callable[[], str | None], wanted: Callable[[], bool]
    ) -> GuardedMotion:
        """Take a wide view's frame and find the parts wholly in it (a part its edge cuts is
        left to the other wide view, which sees it whole)."""
        return frame_step(
            name, self.dev, self.params.guard, self._detect_whole, self._use_wide,
            failed, Failure.NOTHING_FOUND, wanted=wanted,
        )

    def _use_wide(self, dets: list[Detection]) -> None:
        """The wide views add up: the choice is made among all they found."""
        self._remember(dets)
        self.result = None
        self._choose(self.detections)

    def _detect_whole(self, frame: Frame, pose: Pose) -> list[Detection]:
        dets = self._detect_work(frame, pose)
        camera = self.dev.camera
        if not self._two_views() or camera is None:
            return dets
        return [d for d in dets if wholly_in_view(d, camera.intrinsics(), pose)]

    def _detect_step(self, name: str, judge_end: bool = False) -> GuardedMotion:
        """Take a frame and find the parts in it (or, ``judge_end``, judge the chosen part's end
        from it); fails NOTHING_FOUND while no part is chosen. The frame and the detection run
        off the tick where the camera streams in real time (:mod:`skills.frames`)."""
        return frame_step(
            name, self.dev, self.params.guard,
            self._judge_work if judge_end else self._detect_work,
            self._use_judged if judge_end else self._use_detections,
            self._none_found, Failure.NOTHING_FOUND,
            wanted=self._end_view_wanted if judge_end else None,
        )

    def _end_view_wanted(self) -> bool:
        """An end to judge, or the closer look from above not taken yet."""
        d = self._undecided
        if self._out_of_reach:
            return False  # the camera never went there: nothing seen of that end
        if d is None:
            return not self._judged and self._looked_again is False
        return any(p.name == d.part for p in self.catalogue)

    # --- the steps' commands and checks ------------------------------------------------------
    def _over_bin(self, which: int) -> None:
        """The camera over the bin for wide view ``which`` (none asked for past the last)."""
        if which >= len(self._wide):
            return
        p = self.params
        target = camera_over(self._wide[which], p.view_height, self.dev)
        self._move_turning(target, p.speed)

    def _move_turning(self, target: Pose, speed: float) -> None:
        """A straight move to ``target`` at ``speed``, slower where the tool turns: the path's
        length over the time the turn needs at ``turn_rate``. After a drag or a roll the tool
        starts turned to the part; turned back at the look's speed on the way up to the wide
        view, the wrist ran into the UR5's joint speed limit (the twin's arm faulted), and the
        wrist's own swing read 91-97 N at the sensor."""
        p = self.params
        distance, angle = self.dev.arm.tool_pose().distance(target)
        if angle > 0.0:
            speed = min(speed, max(distance, TURN_PATH * angle) * p.turn_rate / angle)
        self.dev.arm.move_to(target, speed, p.acceleration)

    def _beyond_end(self, which: int) -> None:
        """The camera beyond the chosen part's ``which`` end (0: the better place); where the
        open end is decided, the part leans or nothing is chosen: one closer look from above."""
        self._out_of_reach = False
        r = self.result
        if (
            self._undecided is None
            and r is not None
            and not r.open_end_seen
            and not r.tilted
            and not r.standing  # its top was seen: a closed end up, no end view tells more
        ):
            self._undecided = r  # a leaning part's end is never judged: no view of its ends
        p, d = self.params, self._undecided
        if d is None:
            if which == 0:  # decided (or leaning): look again, closer, from above it
                target = camera_over(self._view_xy, p.second_height, self.dev)
                self._move_turning(target, p.speed)
            return
        xy = end_views(d, p.second_offset, self.roi, self.detections)[which]
        target = camera_over(xy, p.second_height, self.dev)
        # beyond an end at the edge of the arm's reach (a far corner): that end is not seen,
        # as one against a wall is not; the other end's view may still decide it
        self._out_of_reach = self._reach is not None and self._reach([target]) is not None
        if not self._out_of_reach:
            self._move_turning(target, p.speed)

    def _over_part(self) -> None:
        r, p = self.result, self.params
        assert r is not None  # the wide view's step fails while nothing is chosen
        yaw, speed = 0.0, p.speed
        if self._grip_yaw is not None and p.turn_view_to_grasp >= TURN_VIEW:
            yaw, speed = self._grip_yaw(r), min(p.speed, p.turn_speed)
        xy = (float(r.center[0]), float(r.center[1]))
        target = camera_over(xy, p.close_height, self.dev, yaw)
        if yaw != 0.0 and self._reach is not None and self._reach([target]) is not None:
            target, speed = camera_over(xy, p.close_height, self.dev), p.speed
        self._move_turning(target, speed)

    def _refine(self, dets: list[Detection]) -> None:
        """The chosen part's centre and axis as the close view saw them; what the earlier views
        decided of it (its open end, leaning or not, its size) stays. A part not found again
        within half its outer size keeps the earlier pose."""
        r = self.result
        assert r is not None
        radius = 0.5 * r.outer  # exact: half the outer size; a centre inside the earlier part
        near = [d for d in dets if math.dist(d.center[XY], r.center[XY]) < radius]
        if not near:
            return
        d = min(near, key=lambda d: math.dist(d.center[XY], r.center[XY]))
        if r.standing:  # its axis moves, its top stays straight above it
            if not d.standing:
                return  # a lying part's flank, not its top
            centre = np.array([d.center[0], d.center[1], r.center[Z]])
            top = np.array([d.center[0], d.center[1], r.open_end[Z]])
            self.result = dataclasses.replace(r, center=centre, open_end=top)
            return
        yaw = d.yaw if math.cos(d.yaw - r.yaw) >= 0.0 else d.yaw + math.pi
        yaw = math.atan2(math.sin(yaw), math.cos(yaw))
        u = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        centre = np.array([d.center[0], d.center[1], r.center[Z]])
        end = centre + 0.5 * r.length * u  # exact: the end is half the length from the centre
        self.result = dataclasses.replace(r, center=centre, yaw=yaw,
                                          open_end=np.array([end[0], end[1], r.open_end[Z]]))

    def _detect_work(self, frame: Frame, pose: Pose) -> list[Detection]:
        camera = self.dev.camera
        assert camera is not None
        return detect_parts(frame, camera.intrinsics(), pose, self.catalogue, self.roi)

    def _use_detections(self, dets: list[Detection]) -> None:
        self._choose(dets)
        self._remember(dets)

    def _judge_work(self, frame: Frame, pose: Pose) -> tuple[str, Any]:
        """A view beyond an end of the chosen cup or bottle whose open end the wide view did
        not decide: what that end shows (:func:`open_end_from_view`). For a part decided (or
        leaning), the closer look from above, once: it refines what the wide view saw."""
        d = self._undecided  # set by the move beyond the end
        if d is None:
            if not self._judged and self._looked_again is False:
                return "detect", self._detect_work(frame, pose)
            return "none", None
        part = next((p for p in self.catalogue if p.name == d.part), None)
        if part is None:
            return "none", None
        camera = self.dev.camera
        assert camera is not None
        return "end", open_end_from_view(d, part, frame, camera.intrinsics(), pose, self.roi)

    def _use_judged(self, judged: tuple[str, Any]) -> None:
        """After both end views, the end they agree on (:func:`combine_end_views`)."""
        kind, value = judged
        if kind == "detect":
            self._looked_again = True
            self._use_detections(value)
        elif kind == "end":
            assert self._undecided is not None
            self._judged.append(value)
            self.result = combine_end_views(self._undecided, self._judged)

    def _choose(self, dets: list[Detection]) -> None:
        """The part nearest ``near_xy``; a later view replaces the choice only when it decided
        the open end."""
        if dets:
            best = min(dets, key=lambda d: math.dist(d.center[XY], self._near_xy))
            if self.result is None or best.open_end_seen:
                self.result = best

    def _remember(self, dets: list[Detection]) -> None:
        """The second, closer view sees less of the bin: it refines the parts it sees again
        and adds any new ones, but never forgets what the wide view found."""
        self.detections = merge_views(self.detections, dets)

    def _none_found(self) -> str | None:
        return None if self.result is not None else "no part found in the bin"

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if result.status is Status.FAILURE:
            return result.failed(f"look: {result.message}")
        return result

    def halt(self) -> None:
        self.sequence.halt()
