"""The Look skill: bring the wrist camera over the bin, find the parts, and, for a cup or bottle
whose open end the first view could not tell, look again from beyond one of its ends."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from drivers.devices import Devices
from drivers.parts import Part
from drivers.pose import Pose
from skills.motion import Guard, GuardedMotion, Sequence
from skills.params import si
from skills.perception.bin_parts import Detection, detect_parts
from skills.status import Failure, Status, StepResult

DOWN = np.diag([1.0, -1.0, -1.0])


def camera_over(xy: tuple[float, float], height: float, dev: Devices) -> Pose:
    """Tool pose (pointing down) with the optical centre ``height`` above ``xy`` (m)."""
    assert dev.camera is not None
    offset = DOWN @ dev.camera.tool_T_camera().position
    return Pose(np.array([xy[0], xy[1], height]) - offset, DOWN)


@dataclass(frozen=True)
class LookParams:
    """The ``skills.perceive`` section of a cell's configuration (SI)."""

    view_height: float = si(0.5, "m", 0.2, 1.0, "of the camera over the bin, the wide view")
    second_height: float = si(0.35, "m", 0.15, 1.0, "of the camera for the look at an end")
    second_offset: float = si(
        0.10, "m", 0.0, 0.3, "beyond the part's end the second view looks from"
    )
    speed: float = si(0.25, "m/s", 0.01, 1.0, "of the TCP between views")
    acceleration: float = si(1.0, "m/s^2", 0.05, 3.0, "of the TCP between views")
    guard: Guard = field(default_factory=Guard)


def second_view_xy(d: Detection, offset: float) -> tuple[float, float]:
    """Where the camera looks from to see an end face of ``d``: ``offset`` beyond one of its
    ends on its axis. From there that end's face (and, through an open end, the inside) is in
    sight; the end nearer the robot, where the arm reaches."""
    u = np.array([math.cos(d.yaw), math.sin(d.yaw)])
    ends = [d.center[:2] + s * (0.5 * d.length + offset) * u for s in (1.0, -1.0)]
    xy = min(ends, key=lambda e: float(np.hypot(e[0], e[1])))
    return float(xy[0]), float(xy[1])


def same_part(d: Detection, later: list[Detection], gate: float = 0.02) -> Detection | None:
    """The detection in a later view that is ``d`` again (same kind, centre within ``gate``)."""
    near = [x for x in later if x.part == d.part and math.dist(x.center[:2], d.center[:2]) < gate]
    return min(near, key=lambda x: math.dist(x.center[:2], d.center[:2])) if near else None


class Look:
    """``result``: the detection to pick (nearest ``near_xy``), or a failure.

    Steps: camera over the bin, find the parts; camera beyond the chosen part's end, look at
    its end (for a part whose open end is decided, the second look is from the first view)."""

    def __init__(
        self,
        dev: Devices,
        catalogue: list[Part],
        roi: tuple[float, float, float, float],
        view_xy: tuple[float, float],
        near_xy: tuple[float, float],
        params: LookParams | None = None,
    ) -> None:
        self.params = params if params is not None else LookParams()
        self.dev, self.catalogue, self.roi = dev, catalogue, roi
        self._view_xy, self._near_xy = view_xy, near_xy
        self.result: Detection | None = None
        self.detections: list[Detection] = []
        g = self.params.guard
        self.sequence = Sequence(
            "look",
            [
                dev.move("camera over the bin", g, self._over_bin),
                self._detect_step("find the parts"),
                dev.move("camera beyond its end", g, self._beyond_end),
                self._detect_step("look at its end"),
            ],
        )

    def _detect_step(self, name: str) -> GuardedMotion:
        """Take a frame and find the parts in it; fails NOTHING_FOUND while no part is chosen."""
        dev = self.dev
        return GuardedMotion(
            name, self._detect, lambda: True, dev.arm, dev.ft, dev.clock, self.params.guard,
            self._none_found, Failure.NOTHING_FOUND,
        )

    # --- the steps' commands and checks ------------------------------------------------------
    def _over_bin(self) -> None:
        p = self.params
        target = camera_over(self._view_xy, p.view_height, self.dev)
        self.dev.arm.move_to(target, p.speed, p.acceleration)

    def _beyond_end(self) -> None:
        p = self.params
        target = camera_over(self._second_view_xy(), p.second_height, self.dev)
        self.dev.arm.move_to(target, p.speed, p.acceleration)

    def _detect(self) -> None:
        camera = self.dev.camera
        assert camera is not None
        frame = camera.capture()
        pose = self.dev.arm.tool_pose() @ camera.tool_T_camera()
        dets = detect_parts(frame, camera.intrinsics(), pose, self.catalogue, self.roi)
        self._choose(dets)
        self._remember(dets)

    def _choose(self, dets: list[Detection]) -> None:
        """The part nearest ``near_xy``; a later view replaces the choice only when it decided
        the open end."""
        if dets:
            best = min(dets, key=lambda d: math.dist(d.center[:2], self._near_xy))
            if self.result is None or best.open_end_seen:
                self.result = best

    def _remember(self, dets: list[Detection]) -> None:
        """The second, closer view sees less of the bin: it refines the parts it sees again
        and adds any new ones, but never forgets what the wide view found."""
        merged = list(dets)
        for old in self.detections:
            if all(math.dist(old.center[:2], d.center[:2]) > 0.02 for d in dets):
                merged.append(old)
        self.detections = merged

    def _none_found(self) -> str | None:
        return None if self.result is not None else "no part found in the bin"

    def _second_view_xy(self) -> tuple[float, float]:
        d = self.result
        if d is None or d.open_end_seen:  # decided: look again from where it is
            return float(self._view_xy[0]), float(self._view_xy[1])
        return second_view_xy(d, self.params.second_offset)

    def tick(self) -> StepResult:
        result = self.sequence.tick()
        if result.status is Status.FAILURE:
            return result.failed(f"look: {result.message}")
        return result

    def halt(self) -> None:
        self.sequence.halt()
