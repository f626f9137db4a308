"""Judging a pivot from the simulated state only, never from the plan.

:func:`judge` looks at the end state after the lift: the part's axis within 10 deg of vertical
with its open end up, no point of it on the floor, held by the fingers, a fingertip inside its
hole. That alone cannot tell the paper's method from a regrasp (let go, look, pick from above
ends in the same state), so :class:`PivotWatch` also watches every control step from the moment
the Grasp has closed to the end of the lift: whether the inner finger stayed in the hole, the
longest time no finger touched the part, the kind of grasp at the end and how many camera frames
were taken after the Grasp began. :meth:`PivotWatch.verdict` combines them.

:class:`ForceWatch` measures, over the same control steps, what the twin's forces did: the peak
force at the wrist in each phase, the grip the fingers' motors applied during the Tilt, and how
far the Grasp's close moved the part on the floor.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from sim.part_body import PartBody, hull_vertices
from sim.world import matrix_from_quaternion


class JudgeFailure(StrEnum):
    """Why the twin judges a pick or a pivot not done: the codes the reports count by."""

    ON_FLOOR = "on_floor"  #: the part lies on the floor after the lift
    NOT_LIFTED = "not_lifted"  #: held, but still touching the floor
    NOT_HELD = "not_held"
    NOT_UPRIGHT = "not_upright"
    NO_FINGER_IN_HOLE = "no_finger_in_hole"
    LEFT_HOLE = "left_hole"  #: the inner finger left the hole during the maneuver
    UNTOUCHED = "untouched"  #: no finger touched the part for longer than allowed
    NOT_HOLE_GRASP = "not_hole_grasp"  #: the final grasp is a pinch or another
    CAMERA_USED = "camera_used"  #: a camera frame steered after the Grasp began


@dataclass(frozen=True)
class Verdict:
    success: bool
    failure: str | None
    tilt_deg: float
    height_m: float
    held: bool
    finger_in_hole: str | None
    code: JudgeFailure | None = None


def finger_in_hole(part_body: PartBody, tip: np.ndarray, margin: float = 0.0) -> bool:
    """Whether the world point ``tip`` lies inside the part's hole (part frame test)."""
    part = part_body.part
    local = part_body.pose().inverse().transform(tip)
    if abs(local[0]) > 0.5 * part.length:
        return False
    r = 0.5 * part.hole - margin
    if part.hole_shape == "circle":
        return math.hypot(local[1], local[2]) < r
    return abs(local[1]) < r and abs(local[2]) < r


#: m: a finger closer to the part than this touches it (PyBullet's contact distance; negative
#: is penetration)
TOUCH = 0.0005


def hook_in_hole(part_body: PartBody, point: np.ndarray) -> tuple[bool, float]:
    """Whether ``point`` (a pad's tip, world, m) lies in the hole's volume, and its depth (m)
    below the open end's face along the axis (negative: beyond the end).

    A pad pressed flat on a rectangular hole's inner wall has its face on the wall itself and,
    by the contact's penetration, a fraction of a millimetre into it: the volume reaches
    :data:`TOUCH` into the wall (no wall is that thin; an outer pad stays outside)."""
    return _hook_in_hole_local(part_body, part_body.pose().inverse().transform(point))


def _hook_in_hole_local(part_body: PartBody, local: np.ndarray) -> tuple[bool, float]:
    """:func:`hook_in_hole` for a point already in the part frame (the watch moves both pad
    tips into the part frame with one pose read per control step)."""
    part = part_body.part
    depth = 0.5 * part.length - float(local[0])
    r = 0.5 * part.hole + TOUCH
    if part.hole_shape == "circle":
        radial = math.hypot(local[1], local[2]) < r
    else:
        radial = abs(local[1]) < r and abs(local[2]) < r
    return bool(radial and 0.0 <= depth <= part.length), depth


class GraspKind(StrEnum):
    """What holds the part at the end (values are the JSON strings)."""

    HOLE = "hole"  #: one pad tip inside the hole touching the part, the other finger outside
    PINCH = "pinch"  #: both fingers touch the part, neither inside the hole
    OTHER = "other"  #: touched some other way (one finger only, both inside, ...)
    NONE = "none"  #: no finger touches the part


@dataclass(frozen=True)
class WatchSample:
    t: float  #: s, simulation time
    phase: str
    touch: dict[str, bool]  #: finger name -> touching the part
    in_hole: dict[str, bool]  #: finger name -> pad tip inside the hole's volume
    depth: dict[str, float]  #: finger name -> pad tip depth below the open end (m)
    beta_deg: float  #: the part's axis above the floor
    l_a: float | None  #: where the outer finger touches along the part, l / length
    step: str | None = None  #: the running skill's step (its sequence's current name), if known


class PivotWatch:
    """Samples the contact state after every control step while :attr:`active`.

    ``pad_tip(name)`` gives a finger's pad-face tip (world, m): the point that is in the hole
    when the finger is caught in it. ``frames()`` counts the camera frames taken so far.
    ``inner`` names the finger meant for the hole, ``outer`` the one on the outer wall.
    """

    def __init__(
        self,
        world,  # type: ignore[no-untyped-def]
        part_body: PartBody,
        gripper_body: int,
        finger_links: dict[str, int],
        pad_tip: Callable[[str], np.ndarray],
        frames: Callable[[], int],
        inner: str,
        outer: str,
    ) -> None:
        self.world, self.part_body, self.gripper_body = world, part_body, gripper_body
        self.finger_links, self.pad_tip, self.frames = finger_links, pad_tip, frames
        self.inner, self.outer = inner, outer
        self.samples: list[WatchSample] = []
        self.phase = ""
        self.active = False
        self.phase_starts: dict[str, float] = {}
        self.step: str | None = None  #: set by the caller as the skill's steps change
        self._frames0: int | None = None
        self._frames1: int | None = None
        world.after_step(self._sample)

    def grasp_began(self) -> None:
        """Camera frames are counted from here; the grasp phase's time too."""
        self._frames0 = self.frames()
        self.phase_starts.setdefault("grasp", self.world.clock.now())

    def enter(self, phase: str) -> None:
        """Start watching (if not yet) and name the phase the samples belong to."""
        self.phase = phase
        self.active = True
        self.phase_starts.setdefault(phase, self.world.clock.now())

    def stop(self) -> None:
        self.active = False
        self._frames1 = self.frames()

    def _touching(self, name: str) -> list:  # type: ignore[type-arg]
        """Contact points of a finger on the part closer than :data:`TOUCH` (PyBullet also
        reports points up to its breaking threshold apart, centimetres away)."""
        return self._touching_all()[name]

    def _touching_all(self) -> dict[str, list]:  # type: ignore[type-arg]
        """:meth:`_touching` for every finger from one contact query: PyBullet lists the
        gripper's points manifold by manifold whether or not a link is named, so each finger's
        points come in the same order as from a query of its own link."""
        points = self.world.p.getContactPoints(
            bodyA=self.part_body.body_id, bodyB=self.gripper_body
        )
        return {
            name: [c for c in points if c[4] == link and c[8] <= TOUCH]
            for name, link in self.finger_links.items()
        }

    def _sample(self) -> None:
        """One :class:`WatchSample` of the state after this control step.

        The part's pose is read once and every point is moved into its frame with it: the same
        numbers as :func:`hook_in_hole` and :meth:`PartBody.tilt` on each point, for a sixth of
        the cost (this runs every control step of a trial; each pose read and ``Pose`` built
        cost more than PyBullet's step of a resting cell)."""
        if not self.active:
            return
        part_body = self.part_body
        position, rotation = part_body.frame()
        # Pose.inverse() and its transform(), written out on the arrays.
        rt = rotation.T
        origin = -rt @ position

        def to_part(point: Any) -> np.ndarray:
            return np.asarray(point, float) @ rt.T + origin

        touch, in_hole, depth = {}, {}, {}
        contacts = self._touching_all()
        for name in self.finger_links:
            touch[name] = bool(contacts[name])
            in_hole[name], depth[name] = _hook_in_hole_local(part_body, to_part(self.pad_tip(name)))
        l_a = None
        if contacts[self.outer]:
            pts = np.array([to_part(c[5]) for c in contacts[self.outer]])
            length = part_body.part.length
            l_a = float((0.5 * length - pts[:, 0].mean()) / length)
        # PartBody.tilt() of this pose: the axis is the rotation's first column.
        beta = float(math.asin(min(1.0, abs(rotation[:, 0].copy()[2]))))
        self.samples.append(
            WatchSample(
                self.world.clock.now(),
                self.phase,
                touch,
                in_hole,
                depth,
                math.degrees(beta),
                l_a,
                self.step,
            )
        )

    # --- what was seen ----------------------------------------------------------------------
    def inner_in_hole_all_along(self) -> bool:
        return bool(self.samples) and all(s.in_hole[self.inner] for s in self.samples)

    def first_exit(self) -> float | None:
        """s (simulation time) of the first sample with the inner pad tip out of the hole."""
        return next((s.t for s in self.samples if not s.in_hole[self.inner]), None)

    def longest_free_s(self) -> float:
        """The longest run of samples in which no finger touched the part (s)."""
        dt = self.world.settings.control_dt
        longest = run = 0
        for s in self.samples:
            run = 0 if any(s.touch.values()) else run + 1
            longest = max(longest, run)
        return longest * dt

    def longest_free(self) -> dict[str, Any] | None:
        """Where the longest untouched run was: its length (s), the phase and step it began in,
        and when (s after that phase began) -- the diagnosis of a part left standing alone."""
        dt = self.world.settings.control_dt
        best: tuple[int, int] = (0, -1)  # (length, index of its first sample)
        run = 0
        for i, s in enumerate(self.samples):
            run = 0 if any(s.touch.values()) else run + 1
            if run > best[0]:
                best = (run, i - run + 1)
        if best[0] == 0:
            return None
        first = self.samples[best[1]]
        start = self.phase_starts.get(first.phase, first.t)
        return {"s": round(best[0] * dt, 3), "phase": first.phase, "step": first.step,
                "after_phase_start_s": round(first.t - start, 3)}

    def camera_frames_steering(self) -> int:
        if self._frames0 is None:
            return 0
        end = self._frames1 if self._frames1 is not None else self.frames()
        return end - self._frames0

    def final_grasp(self) -> GraspKind:
        if not self.samples:
            return GraspKind.NONE
        last = self.samples[-1]
        touching = [n for n, t in last.touch.items() if t]
        if not touching:
            return GraspKind.NONE
        inside = [n for n in touching if last.in_hole[n]]
        others = [n for n in last.touch if n not in inside]
        if len(touching) == 2 and len(inside) == 1 and last.touch[others[0]]:
            outside = others[0]
            if last.depth[outside] >= 0.0 and not last.in_hole[outside]:
                return GraspKind.HOLE
        if len(touching) == 2 and not inside:
            return GraspKind.PINCH
        return GraspKind.OTHER

    def l_a_trace(self) -> dict[str, float | None]:
        """l_a = l / length where the outer finger touches S during the Tilt, at beta = 0, 30
        and 60 deg (the first touching sample at or past each angle, None if S was not touched
        within 10 deg of it) and ``upright``: the last touch of S before the part stands (the
        Tilt's last touching sample; later the outer finger is moved to the outer wall)."""
        tilt = [s for s in self.samples if s.phase == "tilt" and s.l_a is not None]
        trace: dict[str, float | None] = {}
        for key, beta in {"0": 0.0, "30": 30.0, "60": 60.0}.items():
            hit = next((s for s in tilt if s.beta_deg >= beta - 1.0), None)
            trace[key] = None if hit is None or hit.beta_deg > beta + 10.0 else hit.l_a
        trace["upright"] = tilt[-1].l_a if tilt else None
        return trace

    def phase_times(self, end: float) -> dict[str, float]:
        """s spent in each phase, up to ``end`` (simulation time)."""
        names = list(self.phase_starts)
        times = {}
        for i, name in enumerate(names):
            stop = self.phase_starts[names[i + 1]] if i + 1 < len(names) else end
            times[name] = stop - self.phase_starts[name]
        return times

    def failure(self, max_free_s: float = 1.0) -> str | None:
        """Why the watched maneuver is not the paper's in-hand pivot, or None."""
        found = self.failure_with_code(max_free_s)
        return None if found is None else found[1]

    def failure_with_code(self, max_free_s: float = 1.0) -> tuple[JudgeFailure, str] | None:
        """:meth:`failure` with its code."""
        if not self.inner_in_hole_all_along():
            t = self.first_exit()
            at = f" at {t:.2f} s" if t is not None else ""
            return JudgeFailure.LEFT_HOLE, f"the inner finger left the hole{at}"
        free = self.longest_free_s()
        if free > max_free_s:
            return (
                JudgeFailure.UNTOUCHED,
                f"no finger touched the part for {free:.2f} s (max {max_free_s:g} s)",
            )
        kind = self.final_grasp()
        if kind is not GraspKind.HOLE:
            return JudgeFailure.NOT_HOLE_GRASP, f"final grasp: {kind.value}, not a hole grasp"
        frames = self.camera_frames_steering()
        if frames:
            return JudgeFailure.CAMERA_USED, f"{frames} camera frame(s) used after the Grasp began"
        return None


#: The pivot's phases a trial reports forces for, in order.
PIVOT_PHASES = ("grasp", "tilt", "align", "lift")


class ForceWatch:
    """The forces the twin applied and how the part moved, phase by phase, read from the
    simulated state after every control step (the steps :class:`PivotWatch` sees), never from
    what the skills commanded or read.

    * **Wrist** (:meth:`peaks`): the load on the twin's wrist sensor before its stream, noise
      and power-up offset (:meth:`sim.ft_sensor.SimForceTorqueSensor.sampled_true_load`, read
      once per control step by the sensor itself), less the tool's own weight: that weight is
      the force read at rest when the watch is made (nothing touched) and is turned with the
      tool since.
      What remains is the force the part, the floor and the tool's accelerations put on the
      wrist; its peak magnitude (N) in each phase.
    * **Grip** (:meth:`grip_force`): the force each finger's motor applied in the last physics
      step (PyBullet's applied joint motor force, ``getJointState(...)[3]``), N per finger,
      positive closing: the grip the gripper actually exerts -- the commanded force only while
      the motor saturates against the part, less when its position target is near (the Tilt's
      squeeze) and negative while it opens (the Tilt's ease). The mean of the two fingers is
      kept for every control step of the Tilt.
    * **Part** (:meth:`mark`, :meth:`moved_mm`): the part frame's centre in the floor plane at
      named moments. Entering a phase marks ``"<previous phase> end"``; :meth:`stop` marks the
      end of the last one.
    """

    def __init__(
        self,
        world,  # type: ignore[no-untyped-def]
        robot_body: int,
        ft: Any,
        finger_joints: tuple[int, ...],
        part_body: PartBody,
        grip_phase: str = "tilt",
    ) -> None:
        self.world, self.p = world, world.p
        self.robot_body, self.ft, self.finger_joints = robot_body, ft, finger_joints
        self.part_body, self.grip_phase = part_body, grip_phase
        self.phase: str | None = None
        self.peak: dict[str, float] = {}  #: phase -> N, largest wrist force magnitude
        self.grip: list[float] = []  #: N per finger, each control step of ``grip_phase``
        self.marks: dict[str, np.ndarray] = {}  #: name -> the part's (x, y), m
        # The tool's own weight, as a world vector: the sensor frame's reading at rest, turned.
        self._weight = self._rotation() @ self._force()
        world.after_step(self._sample)

    @classmethod
    def for_robot(cls, world, robot: Any, part_body: PartBody) -> ForceWatch:  # type: ignore[no-untyped-def]
        """The watch of a :class:`sim.robot.SimRobot` (its wrist sensor and two fingers), made
        while the tool rests touching nothing (after the sensor's first sample)."""
        fingers = tuple(robot.gripper.finger_link(n) for n in ("finger_a", "finger_b"))
        return cls(world, robot.body_id, robot.ft, fingers, part_body)

    def _force(self) -> np.ndarray:
        """The load of the tool on the sensor (N, sensor frame), noise- and offset-free, as the
        sensor sampled it this control step (its hook runs before this watch's)."""
        return np.asarray(self.ft.sampled_true_load()[:3], float)

    def _rotation(self) -> np.ndarray:
        state = self.p.getLinkState(self.robot_body, self.ft.joint)
        return matrix_from_quaternion(state[5])

    def wrist_force(self) -> np.ndarray:
        """The force (N, sensor frame) on the wrist now, the tool's own weight taken out."""
        return self._force() - self._rotation().T @ self._weight

    def enter(self, phase: str) -> None:
        """Measure into ``phase`` from now on (marks the part where the previous one ended)."""
        if self.phase is not None:
            self.mark(f"{self.phase} end")
        self.phase = phase
        self.peak.setdefault(phase, 0.0)

    def stop(self) -> None:
        if self.phase is not None:
            self.mark(f"{self.phase} end")
        self.phase = None

    def mark(self, name: str) -> None:
        """Remember where the part's centre is now (the first mark of a name stays)."""
        if name not in self.marks:
            self.marks[name] = np.asarray(self.part_body.frame()[0][:2], float).copy()

    def _sample(self) -> None:
        phase = self.phase
        if phase is None:
            return
        magnitude = float(np.linalg.norm(self.wrist_force()))
        if magnitude > self.peak[phase]:
            self.peak[phase] = magnitude
        if phase == self.grip_phase:
            states = self.p.getJointStates(self.robot_body, self.finger_joints)
            # The fingers' joints open towards +q: a closing motor force is negative.
            self.grip.append(-sum(float(s[3]) for s in states) / len(states))

    # --- what was measured -----------------------------------------------------------------
    def peaks(self, phases: Sequence[str] = PIVOT_PHASES) -> dict[str, float | None]:
        """N, the peak wrist force of each phase (None: the trial never reached it)."""
        return {ph: (round(self.peak[ph], 2) if ph in self.peak else None) for ph in phases}

    def grip_force(self) -> float | None:
        """N per finger, the median over ``grip_phase`` (None: never reached)."""
        return round(float(np.median(self.grip)), 2) if self.grip else None

    def moved_mm(self, start: str, end: str) -> float | None:
        """mm the part's centre moved in the floor plane from mark ``start`` to ``end``."""
        if start not in self.marks or end not in self.marks:
            return None
        return round(1e3 * float(np.linalg.norm(self.marks[end] - self.marks[start])), 2)


def judge(
    world,
    part_body: PartBody,
    floor_id: int,
    gripper_body: int,
    finger_links: dict[str, int],
    finger_tips: dict[str, np.ndarray],
    floor_z: float = 0.0,
    max_tilt_deg: float = 10.0,
    min_height: float = 0.01,
) -> Verdict:
    """Judge the hole grasp. ``finger_tips``: world positions of each fingertip centre."""
    p = world.p
    axis = part_body.axis()
    # A tube (two open ends) held upright by a finger in its hole is upright either end up; a
    # cup or a bottle only with its open end up.
    up = abs(float(axis[2])) if part_body.part.open_ends == 2 else float(axis[2])
    tilt = math.degrees(math.acos(float(np.clip(up, -1.0, 1.0))))
    height = part_body.lowest_z() - floor_z
    on_floor = len(p.getContactPoints(bodyA=part_body.body_id, bodyB=floor_id)) > 0
    held_by = [
        name
        for name, link in finger_links.items()
        if p.getContactPoints(bodyA=part_body.body_id, bodyB=gripper_body, linkIndexB=link)
    ]
    inside = [name for name, tip in finger_tips.items() if finger_in_hole(part_body, tip)]
    code: JudgeFailure | None = None
    failure: str | None = None
    if on_floor or height < min_height:
        code = JudgeFailure.ON_FLOOR if not held_by else JudgeFailure.NOT_LIFTED
        failure = "on the floor after the lift" if not held_by else "not lifted off the floor"
    elif not held_by:
        code, failure = JudgeFailure.NOT_HELD, "not held"
    elif tilt > max_tilt_deg:
        code, failure = JudgeFailure.NOT_UPRIGHT, f"not upright: axis {tilt:.1f} deg from vertical"
    elif not inside:
        code, failure = JudgeFailure.NO_FINGER_IN_HOLE, "no finger inside the hole"
    return Verdict(
        success=failure is None,
        failure=failure,
        tilt_deg=tilt,
        height_m=height,
        held=bool(held_by),
        finger_in_hole=inside[0] if inside else None,
        code=code,
    )


# ------------------------------------------------------------------ slot and packing judges
def _tilt_deg(part_body: PartBody) -> float:
    """Angle (deg) of the part's axis from vertical, either end up."""
    return math.degrees(math.acos(min(1.0, abs(float(part_body.axis()[2])))))


def _touching(world, a: int, b: int) -> bool:  # type: ignore[no-untyped-def]
    return len(world.p.getContactPoints(bodyA=a, bodyB=b)) > 0


@dataclass(frozen=True)
class SlotVerdict:
    """The part in the machine's slot, from the simulated state (m, deg)."""

    success: bool
    failure: str | None
    tilt_deg: float  #: axis from vertical
    offset_m: float  #: horizontal distance of the part's bottom centre from the slot's centre
    bottom_m: float  #: lowest point of the part above the slot floor
    held: bool  #: touching the gripper


def judge_in_slot(
    world,  # type: ignore[no-untyped-def]
    part_body: PartBody,
    slot_center: np.ndarray,
    slot_width: float,
    gripper_body: int,
    max_tilt_deg: float = 10.0,
    floor_tolerance: float = 0.002,
) -> SlotVerdict:
    """Judge a part fed into the slot: upright, its bottom inside the pocket's square
    (``slot_width`` m, centred on ``slot_center``, the pocket floor's centre), resting on the
    floor (lowest point within ``floor_tolerance`` m of it) and not touching the gripper."""
    tilt = _tilt_deg(part_body)
    bottom = part_body.closed_end_center() if part_body.axis()[2] > 0 else (
        part_body.open_end_center()
    )
    centre = np.asarray(slot_center, float)
    d = bottom[:2] - centre[:2]
    height = part_body.lowest_z() - float(centre[2])
    held = _touching(world, part_body.body_id, gripper_body)
    half_free = 0.5 * (slot_width - part_body.part.outer)
    if held:
        failure = "still held by the gripper"
    elif float(np.max(np.abs(d))) > half_free + 1e-3 or height > 0.5 * part_body.part.length:
        failure = (
            f"not in the slot: bottom {1e3 * float(np.linalg.norm(d)):.1f} mm from its centre, "
            f"{1e3 * height:.1f} mm above its floor"
        )
    elif tilt > max_tilt_deg:
        failure = f"not upright: axis {tilt:.1f} deg from vertical"
    elif height > floor_tolerance:
        failure = f"not on the slot floor: {1e3 * height:.1f} mm above it"
    else:
        failure = None
    return SlotVerdict(failure is None, failure, tilt, float(np.linalg.norm(d)), height, held)


@dataclass(frozen=True)
class PackedPart:
    """One packed part: tilt (deg), lowest point above the tray floor (m), gaps (m) to each
    tray wall (keys ``+x``, ``-x``, ``+y``, ``-y``) and to each neighbour (by index)."""

    index: int
    center: tuple[float, float]
    tilt_deg: float
    height_m: float
    wall_gaps: dict[str, float]
    neighbour_gaps: dict[int, float]
    home: dict[str, float]  #: gap (m) on the +x and +y sides to whatever stops it there


@dataclass(frozen=True)
class PackVerdict:
    success: bool
    failure: str | None
    parts: list[PackedPart]
    max_neighbour_gap_m: float  #: largest gap between adjacent packed parts (0 for one part)
    max_home_gap_m: float  #: largest gap on a part's +x / +y side to a wall or a neighbour


def judge_packed(
    world,  # type: ignore[no-untyped-def]
    part_bodies: list[PartBody],
    tray_roi: tuple[float, float, float, float],
    tray_floor_z: float,
    gripper_body: int,
    max_gap: float = 0.002,
    max_tilt_deg: float = 5.0,
    floor_tolerance: float = 0.002,
) -> PackVerdict:
    """Judge parts packed in the tray, from the simulated state.

    ``tray_roi``: ``(xmin, xmax, ymin, ymax)`` of the tray's inside (m). Each part must stand
    upright (within ``max_tilt_deg``) on the tray floor (lowest point within ``floor_tolerance``),
    inside the tray, free of the gripper. Gaps are true shortest distances: between two parts
    PyBullet's closest points of their collision shapes, to a wall the envelope's vertices.
    Parts are neighbours when their axes are closer than 1.25 outer diameters (adjacent, not
    diagonal). Packed tight means: every pair of neighbours within ``max_gap``, and every part
    within ``max_gap`` of a wall or a neighbour on its ``+x`` and on its ``+y`` side (the sides
    it was pushed towards).
    """
    p = world.p
    x0, x1, y0, y1 = tray_roi
    centres = [b.pose().position[:2] for b in part_bodies]
    parts: list[PackedPart] = []
    failure: str | None = None
    max_pair, max_home = 0.0, 0.0
    for i, body in enumerate(part_bodies):
        hull = body.pose().transform(hull_vertices(body.part, body.staves))
        walls = {
            "+x": float(x1 - hull[:, 0].max()),
            "-x": float(hull[:, 0].min() - x0),
            "+y": float(y1 - hull[:, 1].max()),
            "-y": float(hull[:, 1].min() - y0),
        }
        neighbours: dict[int, float] = {}
        for j, other in enumerate(part_bodies):
            if j == i or np.linalg.norm(centres[j] - centres[i]) > 1.25 * other.part.outer:
                continue
            pts = p.getClosestPoints(body.body_id, other.body_id, distance=0.05)
            neighbours[j] = float(min(pt[8] for pt in pts)) if pts else 0.05
        home = {"+x": walls["+x"], "+y": walls["+y"]}
        for j, gap in neighbours.items():
            dx, dy = centres[j] - centres[i]
            side = "+x" if abs(dx) >= abs(dy) and dx > 0 else "+y" if dy > abs(dx) else None
            if side is not None:
                home[side] = min(home[side], gap)
        tilt = _tilt_deg(body)
        height = body.lowest_z() - tray_floor_z
        parts.append(
            PackedPart(i, (float(centres[i][0]), float(centres[i][1])), tilt, height, walls,
                       neighbours, home)
        )
        max_pair = max([max_pair, *neighbours.values()])
        max_home = max(max_home, *home.values())
        if failure is not None:
            continue
        if _touching(world, body.body_id, gripper_body):
            failure = f"part {i}: still held by the gripper"
        elif min(walls.values()) < -0.001 or height > 0.5 * body.part.length:
            failure = f"part {i}: not in the tray"
        elif tilt > max_tilt_deg:
            failure = f"part {i}: not upright: axis {tilt:.1f} deg from vertical"
        elif height > floor_tolerance:
            failure = f"part {i}: not on the tray floor: {1e3 * height:.1f} mm above it"
        elif any(g > max_gap for g in neighbours.values()):
            j, g = max(neighbours.items(), key=lambda kv: kv[1])
            failure = f"part {i}: {1e3 * g:.1f} mm from part {j} (max {1e3 * max_gap:.1f} mm)"
        elif any(g > max_gap for g in home.values()):
            side, g = max(home.items(), key=lambda kv: kv[1])
            failure = (
                f"part {i}: not pushed home: {1e3 * g:.1f} mm free on its {side} side "
                f"(max {1e3 * max_gap:.1f} mm)"
            )
    return PackVerdict(failure is None, failure, parts, max_pair, max_home)
