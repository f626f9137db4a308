"""Regrasp trials in the twin, and what ``cell compare`` measures on any trial: tact time and the
volume swept by the gripper.

:func:`run_regrasp_trial` is :func:`lab.pivot_run.run_trial` with the baseline in
place of the pivot: the same :class:`TrialSetup`, the same seeded perturbation drawn in the same
order (so a seed gives both methods the same true pose, frictions and mass), the same finger
frictions, the same pose given to the skills (what the wrist camera's Look saw, or the nominal
pose when ``setup.perceive`` is off), the same 0.3 s hold before the same judge
(:func:`sim.judge.judge`) looks at the simulated state. Physics decides: nothing is welded or
moved by hand.

:class:`GripperProbe` is called after every control step (``on_frame`` with ``frame_every=1``) and
observes only the robot:

* **tact time**: from the first control step in which the arm or the gripper executes a command
  to the end of the step in which the arm last reported a motion DONE (for a successful trial,
  the lift of the hole grasp: nothing moves after it);
* **swept volume**: the gripper's collision geometry as the twin's URDF defines it -- the FT300
  puck (cylinder), the gripper body (box) and both fingers (boxes) -- placed at each step's link
  poses and voxelized on a fixed 5 mm world grid; a voxel counts when its centre lies inside a
  shape at some sampled step. A shape is re-sampled once any of its corners has moved
  ``min_step`` (1 mm) since its last sample, which keeps the union continuous to within that
  and skips the many steps where nothing moves. The wrist and arm links are not counted.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.arm import MotionState
from drivers.pose import Pose
from drivers.tool import FINGER_LENGTH, FT_HEIGHT, FT_RADIUS, GRIPPER_BODY_SIZE
from lab.pivot_run import (
    TrialResult,
    TrialSetup,
    judge_trial,
    look_near,
    open_trial_world,
    run_skill,
)
from sim.robot import SimRobot
from sim.robot_model import FINGER_THICKNESS, FINGER_WIDTH
from sim.world import SimWorld
from skills.pivot import PickFromAbove
from skills.regrasp import Regrasp, RegraspOptions
from skills.status import StepResult

VOXEL = 0.005  #: m, edge of the swept-volume grid's voxels
#: m, the dense grid's extent in the world (the UR5 reaches 0.85 m); beyond it a set takes over.
GRID_BOUNDS = ((-1.0, 1.0), (-1.0, 1.0), (-0.2, 1.2))


# ------------------------------------------------------------------------ swept volume
@dataclass(frozen=True)
class Solid:
    """A box (``half`` = half extents) or a cylinder along its local z (``half`` = (r, r, half
    length)), centred at ``offset`` in the frame it is attached to (m)."""

    kind: str
    half: tuple[float, float, float]
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def corners(self) -> NDArray[np.float64]:
        """The 8 corners of its local bounding box, in the attached frame (m)."""
        h = np.asarray(self.half, float)
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return np.asarray(self.offset, float) + signs * h

    def contains(self, local: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which points (N x 3, attached frame) lie inside."""
        d = local - np.asarray(self.offset, float)
        h = self.half
        if self.kind == "box":
            return np.all(np.abs(d) <= np.asarray(h), axis=1)
        if self.kind == "cylinder":
            return (np.abs(d[:, 2]) <= h[2]) & (d[:, 0] ** 2 + d[:, 1] ** 2 <= h[0] ** 2)
        raise ValueError(f"unknown solid kind {self.kind!r}")


class SweptVolume:
    """The union of solids placed at poses, voxelized on a world grid of ``voxel`` m."""

    def __init__(
        self,
        voxel: float = VOXEL,
        bounds: tuple[tuple[float, float], ...] = GRID_BOUNDS,
    ) -> None:
        self.voxel = voxel
        self._lo = np.array([math.floor(b[0] / voxel) for b in bounds], dtype=np.int64)
        hi = np.array([math.ceil(b[1] / voxel) for b in bounds], dtype=np.int64)
        self._shape = tuple(int(v) for v in hi - self._lo)
        self._grid = np.zeros(self._shape, dtype=bool)
        self._outside: set[tuple[int, int, int]] = set()

    def add(self, solid: Solid, pose: Pose) -> None:
        """Mark every voxel whose centre lies inside ``solid`` placed at ``pose`` (world)."""
        v = self.voxel
        corners = pose.transform(solid.corners())
        lo = np.ceil(corners.min(axis=0) / v - 0.5).astype(np.int64)
        hi = np.floor(corners.max(axis=0) / v - 0.5).astype(np.int64)
        if np.any(hi < lo):
            return
        axes = [np.arange(lo[k], hi[k] + 1) for k in range(3)]
        idx = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        centres = (idx + 0.5) * v
        local = (centres - pose.position) @ pose.rotation
        idx = idx[solid.contains(local)]
        rel = idx - self._lo
        inside = np.all((rel >= 0) & (rel < np.array(self._shape)), axis=1)
        r = rel[inside]
        self._grid[r[:, 0], r[:, 1], r[:, 2]] = True
        if not np.all(inside):
            self._outside.update(map(tuple, idx[~inside].tolist()))

    @property
    def count(self) -> int:
        """Voxels marked."""
        return int(np.count_nonzero(self._grid)) + len(self._outside)

    @property
    def volume_cm3(self) -> float:
        return self.count * (self.voxel * 100.0) ** 3


def gripper_solids() -> dict[str, tuple[Solid, ...]]:
    """The gripper's collision shapes per twin link (as :mod:`sim.robot_model` builds them),
    in each link's frame."""
    body = GRIPPER_BODY_SIZE
    finger = (0.5 * FINGER_THICKNESS, 0.5 * FINGER_WIDTH, 0.5 * FINGER_LENGTH)
    return {
        "ft_sensor": (
            Solid("cylinder", (FT_RADIUS, FT_RADIUS, 0.5 * FT_HEIGHT), (0, 0, 0.5 * FT_HEIGHT)),
        ),
        "gripper_body": (
            Solid("box", (0.5 * body[0], 0.5 * body[1], 0.5 * body[2]), (0, 0, 0.5 * body[2])),
        ),
        "finger_a": (Solid("box", finger, (0.5 * FINGER_THICKNESS, 0, 0.5 * FINGER_LENGTH)),),
        "finger_b": (Solid("box", finger, (-0.5 * FINGER_THICKNESS, 0, 0.5 * FINGER_LENGTH)),),
    }


class GripperProbe:
    """Tact time and swept volume of one trial, from the robot's state after each control step
    (pass :meth:`__call__` as ``on_frame`` with ``frame_every=1``)."""

    def __init__(self, voxel: float = VOXEL, min_step: float = 0.001) -> None:
        self.sweep = SweptVolume(voxel)
        self.min_step = min_step
        self.t_start: float | None = None  #: s, start of the first step that executed a command
        self.t_done: float | None = None  #: s, end of the step where a motion last became DONE
        self._was_moving = False
        self._last: dict[tuple[str, int], NDArray[np.float64]] = {}
        self._solids = gripper_solids()

    def __call__(self, world: Any, robot: SimRobot) -> None:
        now = world.clock.now()
        state = robot.arm.status().state
        if self.t_start is None and (
            state is not MotionState.IDLE or robot.gripper.moving()
        ):
            self.t_start = now - world.settings.control_dt
        if state is MotionState.MOVING:
            self._was_moving = True
        elif state is MotionState.DONE and self._was_moving:
            self._was_moving = False
            self.t_done = now
        else:
            self._was_moving = False
        self.sample(robot)

    def sample(self, robot: SimRobot) -> None:
        """Add the gripper's shapes where they are now (those that moved ``min_step``)."""
        for link, solids in self._solids.items():
            pose = robot.link_pose(link)
            for k, solid in enumerate(solids):
                corners = pose.transform(solid.corners())
                last = self._last.get((link, k))
                if last is not None and float(np.max(np.abs(corners - last))) < self.min_step:
                    continue
                self._last[(link, k)] = corners
                self.sweep.add(solid, pose)

    @property
    def tact_time(self) -> float | None:
        """s from the first motion to the last motion that ended DONE; None if none did."""
        if self.t_start is None or self.t_done is None:
            return None
        return self.t_done - self.t_start


# ------------------------------------------------------------------------ regrasp trial
#: m, horizontally, from the TCP back to the far side of the UR5's wrist links when the tool
#: points forward and 20 deg down (the twin's UR5: TCP 0.1775 m past the flange, wrist 1 about
#: 0.2 m further). Below about 40 deg the wrist hangs at the TCP's height, under the bin's wall.
WRIST_BEHIND = 0.373
LOW_WRIST_TILT = math.radians(40.0)


def place_for_wrist(setup: TrialSetup, regrasp: Regrasp) -> tuple[float, float] | None:
    """Where to stand the part so that the low wrist stays inside the bin (None: where it was
    pinched is fine). Only a shallow pinch (long, wide parts) needs it: the wrist of a steep
    one rides above the wall."""
    if regrasp.tilt >= LOW_WRIST_TILT:
        return None
    x_min = setup.layout.bin_interior()[0]
    u = regrasp.frame.u[:2]
    need = x_min + WRIST_BEHIND * math.cos(regrasp.tilt) / math.cos(math.radians(20.0)) + 0.02
    axis = regrasp.standing_axis
    if axis[0] >= need or abs(u[0]) < 1e-6:
        return None
    shift = (need - axis[0]) / u[0]
    x_max = setup.layout.bin_interior()[1]
    if axis[0] + shift * u[0] + 0.5 * setup.part.outer > x_max:
        return None
    return (float(axis[0] + shift * u[0]), float(axis[1] + shift * u[1]))


@dataclass
class RegraspResult(TrialResult):
    """A :class:`TrialResult` of the baseline; ``grip_offset``: m of the pinch off centre."""

    grip_offset: float = 0.0


def run_regrasp_trial(
    setup: TrialSetup,
    seed: int,
    on_frame: Callable[[SimWorld, SimRobot], None] | None = None,
    frame_every: int = 6,
    options: RegraspOptions | None = None,
) -> RegraspResult:
    """One perturbed regrasp trial (Regrasp, then Align), judged from the simulated state.

    The perturbation is drawn exactly as :func:`lab.pivot_run.run_trial` draws it, in
    the same order from ``numpy.random.default_rng(seed)``; the skills get the pose the wrist
    camera's Look reports near the nominal one (as the pivot's trial looks), or the nominal pose
    when ``setup.perceive`` is off.
    """
    tw = open_trial_world(setup, seed)
    world, robot, params, dev = tw.world, tw.robot, tw.params, tw.dev
    try:
        t_end = world.clock.now() + setup.max_time + (4.0 if setup.perceive else 0.0)
        frame = setup.frame()
        seen: dict[str, float] = {}
        if setup.perceive:
            failed, looked = look_near(
                setup, tw, frame, setup.nominal_center(), t_end, on_frame, frame_every, seen
            )
            if failed is not None:
                fields = judge_trial(tw, seed, failed, "look", on_frame, frame_every)
                return RegraspResult(**fields, perceived_pose=None)
            frame = looked or frame
        regrasp = Regrasp(frame, setup.part, params, dev, options)
        if options is None or options.place_xy is None:
            place = place_for_wrist(setup, regrasp)
            if place is not None:
                opts = dataclasses.replace(options or RegraspOptions(), place_xy=place)
                regrasp = Regrasp(frame, setup.part, params, dev, opts)
        phases = [
            ("regrasp", regrasp),
            ("align", PickFromAbove(regrasp.standing_frame, setup.part, params, dev)),
        ]
        failure: StepResult | None = None
        phase_name = "done"
        for phase_name, skill in phases:
            failure = run_skill(phase_name, skill, world, robot, t_end, on_frame, frame_every)
            if failure is not None:
                break
        else:
            phase_name = "done"
        fields = judge_trial(tw, seed, failure, phase_name, on_frame, frame_every)
        return RegraspResult(
            **fields, perceived_pose=seen or None, grip_offset=regrasp.grip_offset
        )
    finally:
        world.close()


__all__ = [
    "GripperProbe",
    "RegraspResult",
    "Solid",
    "SweptVolume",
    "gripper_solids",
    "run_regrasp_trial",
]
