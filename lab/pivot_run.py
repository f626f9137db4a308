"""Pivot trials in the twin: spawn a part, run Grasp -> Tilt -> Align, judge from the physics.

Each trial perturbs the world away from what the skills are told: the part's position +-3 mm and
yaw +-3 deg, and a real cell's uncertainty (:mod:`sim.uncertainty`: hand-eye error, floor
height, part tolerances, mass, frictions, the FT300's rate, resolution and noise, the arm's
command lag; ``TrialSetup.uncertainty``, ``Uncertainty.ideal()`` for the twin without them:
frictions +-20 %, mass +-10 %). The skills get the part's *nominal* pose (or what the wrist
camera saw before the Grasp), the catalogue part, the configured floor and camera mount, and
the planner's ``(l_a, alpha)``, never the true pose. The
outcome comes from the simulated state: :func:`sim.judge.judge` after the lift, and
:class:`sim.judge.PivotWatch` every control step from the closed Grasp to the end of the lift
(finger in the hole all along, no long free interval, a hole grasp at the end, no camera frame),
and :class:`sim.judge.ForceWatch` measures what the twin's forces did over the same steps (the
grip the fingers applied in the Tilt, the peak wrist force of each phase, how far the Grasp's
close shoved the part): ``grip_force_n``, ``peak_force_n`` and ``shove_mm`` of a result.

When the in-hand Align fails, the recovery (:class:`skills.pivot.PickFromAbove`: let go, look,
pick from above) may still save the part; the trial then counts as ``recovered``, not a success.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cell.reach import reach_from, reach_from_or_home, ur5_reach
from drivers.devices import Devices
from drivers.gripper_spec import GripperSpec, default_gripper
from drivers.layout import CellLayout
from drivers.parts import Part
from drivers.pose import Pose
from lab.stats import wilson_interval
from sim.camera import SimCamera
from sim.cell_layout import build_cell
from sim.judge import ForceWatch, PivotWatch, WatchSample, judge
from sim.part_body import lying_pose, spawn_part
from sim.robot import SimRobot
from sim.robot_model import FINGER_WIDTH
from sim.scenes import random_floor_pose
from sim.uncertainty import Draws, Uncertainty
from sim.world import PhysicsSettings, SimWorld
from skills.home import HomeParams, go_home
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import PivotPlan
from skills.perception.bin_parts import Detection
from skills.perception.look import Look, LookParams, tool_yaw
from skills.pivot import Align, Grasp, PickFromAbove, PivotFrame, PivotParams, Tilt
from skills.pivot.clearance import EndChoice, bin_walls, choose_end, reach_problem
from skills.reposition import Reposition, RepositionParams, plan_reposition
from skills.status import Failure, Status, StepResult


@dataclass(frozen=True)
class Perturbation:
    """Half-widths of the uniform trial perturbations of the pose; ``friction`` and ``mass``
    are the spreads :meth:`sim.uncertainty.Uncertainty.ideal` keeps (``--ideal``), where the
    uncertainty model does not draw them."""

    position: float = 0.003  # m
    yaw: float = math.radians(3.0)  # rad
    friction: float = 0.20  # relative
    mass: float = 0.10  # relative


#: Fingertips to the back of the gripper body along the tool axis (m), for keeping clear of walls.
GRIPPER_REACH = 0.17


@dataclass(frozen=True)
class TrialSetup:
    part: Part
    plan: PivotPlan
    frictions: Frictions = Frictions()
    perturbation: Perturbation = field(default_factory=Perturbation)
    #: Where the lying part's open end (rim centre) is expected, m in the world; the part lies
    #: along ``nominal_yaw`` from there, its far end nearer the robot.
    open_end_xy: tuple[float, float] | None = None  # None: see :meth:`nominal_center`
    nominal_yaw: float = 0.0  # open end away from the robot: the gripper swings back over G
    max_time: float = 40.0  # s of simulated time for the whole maneuver
    params: dict[str, float] = field(default_factory=dict)  # PivotParams overrides

    layout: CellLayout = field(default_factory=CellLayout)
    mu_ground: float | None = None  # part-floor friction, exact (None: frictions.mu_g +- 20 %)
    mu_pad: float | None = None  # pad-part friction at S and H, exact (None: drawn)
    perceive: bool = True  # the pick starts from the wrist camera's view, not the nominal pose
    #: "nominal": near the nominal pose, perturbed; "random": anywhere on the bin floor where the
    #: part fits, up against the walls, any yaw, either end towards the robot.
    pose: str = "nominal"
    physics: PhysicsSettings = field(default_factory=PhysicsSettings)
    #: servoj's (lookahead s, gain) by which the arm follows the streamed targets (sim.servoj
    #: with devices.arm); None: each target within the control step
    servo: tuple[float, float] | None = None
    #: what the real cell does not know exactly, drawn per trial (:mod:`sim.uncertainty`);
    #: ``Uncertainty.ideal()`` turns it off (``--ideal``)
    uncertainty: Uncertainty = field(default_factory=Uncertainty)
    #: the look's and the drag's parameters (``skills.perceive``, ``skills.reposition`` and the
    #: safety limits of a configuration; None: the skills' defaults)
    look: LookParams | None = None
    reposition: RepositionParams | None = None
    #: the joint move home a plan out of reach from the look's pose goes through first
    #: (``skills.go_home``; None: the skill's defaults)
    home: HomeParams | None = None
    #: the gripper's description the twin's gripper is built from (``gripper`` of a
    #: configuration; the shipped 2F-85 by default)
    gripper: GripperSpec = field(default_factory=default_gripper)

    def frame(self) -> PivotFrame:
        """The pivot frame the skills are given: the part's nominal pose."""
        cx, cy = self.nominal_center()
        section = self.part.section(FINGER_WIDTH)
        return PivotFrame(section, np.array([cx, cy, 0.5 * self.part.outer]), self.nominal_yaw)

    def reach_problem(self) -> str | None:
        """Why the nominal pick cannot work in this cell, or None: the part must lie inside the
        bin and the grasp and its approach must be inside the UR5's reach."""
        x0, x1, y0, y1 = self.layout.bin_interior()
        u = np.array([math.cos(self.nominal_yaw), math.sin(self.nominal_yaw)])
        c = np.array(self.nominal_center())
        for end in (c + 0.5 * self.part.length * u, c - 0.5 * self.part.length * u):
            if not (x0 <= end[0] <= x1 and y0 <= end[1] <= y1):
                return (
                    f"the {self.part.name} would lie at ({end[0]:.3f}, {end[1]:.3f}) m, outside "
                    f"the bin's inside x {x0:.3f}..{x1:.3f}, y {y0:.3f}..{y1:.3f} m"
                )
        assert self.plan.l_a is not None and self.plan.alpha is not None
        params = PivotParams(l_a=self.plan.l_a, alpha=self.plan.alpha, **self.params)
        frame = self.frame()
        grasp = frame.grasp_pose(params.l_a, params.alpha, params.tip_offset)
        z = grasp.rotation[:, 2]
        pre = Pose(grasp.position - params.approach_distance * z, grasp.rotation)
        for name, pose in (("grasp", grasp), ("approach", pre)):
            if ur5_reach([pose]) is not None:
                p = pose.position
                return (
                    f"the {name} pose at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is out of the "
                    "UR5's reach"
                )
        return None

    def physics_json(self) -> dict[str, float]:
        s = self.physics
        return {
            "control_hz": s.control_hz,
            "substeps": s.substeps,
            "physics_dt_s": s.physics_dt,
            "solver_iterations": s.solver_iterations,
            "solver_residual": s.solver_residual,
        }

    def nominal_center(self) -> tuple[float, float]:
        """The part's centre (m, world) the skills are told.

        By default the open end lies 0.555 m in front of the robot (further when the bin is), or
        nearer when the gripper, tilted by alpha over the open end, would otherwise reach over
        the bin's far wall.
        """
        if self.open_end_xy is not None:
            xo, yo = self.open_end_xy
        else:
            assert self.plan.alpha is not None
            x_min, x_max = self.layout.bin_interior()[:2]
            reach = GRIPPER_REACH * math.sin(self.plan.alpha) + 0.03
            xo = min(max(0.555, x_min + self.part.length + 0.04), x_max - reach)
            yo = self.layout.bin_center[1]
        half = 0.5 * self.part.length
        return (xo - half * math.cos(self.nominal_yaw), yo - half * math.sin(self.nominal_yaw))


@dataclass
class TrialResult:
    seed: int
    success: bool
    failure: str | None
    phase: str
    tilt_deg: float
    height_m: float
    sim_time: float
    wall_time: float
    true_pose: dict[str, float]
    frictions: dict[str, float]
    mass: float
    perceived_pose: dict[str, float] | None = None  #: what Look reported (None: nominal used)
    end_state_ok: bool = False  #: the end-state test alone (upright, held, finger in the hole)
    inner_in_hole_all_along: bool = False
    longest_free_s: float = 0.0  #: longest time no finger touched the part, closed Grasp to lift
    #: where that run began: {"s", "phase", "step", "after_phase_start_s"} (None: always touched)
    longest_free: dict[str, Any] | None = None
    final_grasp: str = "none"  #: "hole" | "pinch" | "other" | "none"
    camera_frames_steering: int = 0  #: frames taken after the Grasp began
    recovered: bool = False  #: the in-hand Align failed and the pick from above saved the part
    phase_times_s: dict[str, float] = field(default_factory=dict)
    l_a_trace: dict[str, float | None] = field(default_factory=dict)
    #: what the reports count failures by: a skill's Failure or the judge's JudgeFailure code
    failure_code: str | None = None
    #: the closest the planned sweep of the tool comes to a bin wall (mm; negative: into it)
    clearance_mm: float | None = None
    #: the tube was pivoted from the other end than the one the camera's yaw pointed to
    other_end: bool = False
    #: no end cleared where the part lay: it was dragged first (counted apart, not the pivot)
    repositioned: bool = False
    #: how it was moved: "drag" or "roll" (:class:`skills.reposition.MoveKind`; None: not)
    moved_by: str | None = None
    #: N per finger the gripper's motors applied during the Tilt, the median over its control
    #: steps (PyBullet's applied joint motor force; None: no Tilt) -- :class:`ForceWatch`
    grip_force_n: float | None = None
    #: N, the peak force at the wrist in each phase (the sensor joint's noise- and offset-free
    #: reaction less the tool's weight; None: the phase was never reached) -- :class:`ForceWatch`
    peak_force_n: dict[str, float | None] = field(
        default_factory=lambda: dict.fromkeys(("grasp", "tilt", "align", "lift"))
    )
    #: what the trial drew of the cell's uncertainty (:meth:`sim.uncertainty.Draws.to_json`)
    draws: dict[str, float] = field(default_factory=dict)
    #: mm the Grasp's close moved the part's centre in the floor plane, from the start of its
    #: "close onto H" step to the Grasp's end (None: the close never began)
    shove_mm: float | None = None
    #: mm the inner pad's tip (the judge's point, 2 mm from its end) lay past the open end's
    #: face at the judge's first sample after the Grasp closed; negative: short of the face
    #: (None: the Grasp never closed)
    hook_depth_mm: float | None = None

    @property
    def failure_key(self) -> str:
        """A failure counted as one kind: its phase and code (never the message's numbers)."""
        key = f"{self.phase}: {self.failure_code or 'uncoded'}"
        return f"{key}, recovered" if self.recovered else key

    def to_json(self) -> dict[str, object]:
        return dataclasses.asdict(self)


@dataclass
class TrialWorld:
    """A trial's world, built and perturbed: what both the pivot and the regrasp trials use."""

    world: SimWorld
    cell: Any
    robot: SimRobot
    body: Any  #: the part's body
    params: PivotParams
    dev: Devices
    true_pose: dict[str, float]
    frictions: dict[str, float]
    mass: float
    wall0: float
    draws: Draws | None = None  #: the trial's uncertainty draws (:mod:`sim.uncertainty`)
    floor_z: float = 0.0  #: m, the true bin floor's height (the layout's, off by the draw)


def bin_obstacles(layout: CellLayout) -> list:
    """The bin's walls as the configured layout places them (what the cell knows, not the
    simulator's bodies)."""
    return bin_walls(
        layout.bin_interior(),
        layout.bin_floor_z,
        layout.bin_wall_height,
        layout.bin_wall_thickness,
    )


def open_trial_world(setup: TrialSetup, seed: int) -> TrialWorld:
    """Draw the trial's perturbation from ``seed`` (always in the same order, so every method
    meets the same part) and build the world; the caller closes ``world``."""
    wall0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    pert = setup.perturbation
    # The cell's uncertainty (frictions, mass, hand-eye, floor height, tolerances, FT300, lag),
    # then the pose: a seed's pose is the same with the uncertainty model and without it.
    draws = setup.uncertainty.draw(rng, setup.frictions, setup.physics.control_hz)
    if setup.mu_ground is not None:
        draws = dataclasses.replace(draws, mu_g=setup.mu_ground)
    if setup.mu_pad is not None:
        draws = dataclasses.replace(draws, mu_s=setup.mu_pad, mu_h=setup.mu_pad)
    mu_s, mu_h, mu_g = draws.mu_s, draws.mu_h, draws.mu_g
    true_part = draws.true_part(setup.part)
    if setup.pose == "random":
        x, y, yaw = random_floor_pose(setup.layout, true_part, rng)
    else:
        nominal = setup.nominal_center()
        x = nominal[0] + rng.uniform(-pert.position, pert.position)
        y = nominal[1] + rng.uniform(-pert.position, pert.position)
        yaw = setup.nominal_yaw + rng.uniform(-pert.yaw, pert.yaw)

    world = SimWorld(seed=seed, settings=setup.physics)
    try:
        cell = build_cell(world, setup.layout, floor_friction=mu_g, z_offset=draws.floor_dz_m)
        robot = SimRobot(world, gripper=setup.gripper, servo=setup.servo)
        robot.arm.set_command_lag(draws.lag_steps)
        robot.ft.configure(
            draws.ft_rate_hz, draws.ft_force_noise_n, draws.ft_torque_noise_nm,
            draws.ft_force_resolution_n, draws.ft_torque_resolution_nm,
        )
        # finger_a (tool +x) is the outer finger on S; finger_b goes into the hole (H).
        robot.gripper.set_finger_friction(mu_s, mu_h)
        floor = setup.layout.bin_floor_z + draws.floor_dz_m  # the true floor
        body = spawn_part(
            world, true_part, lying_pose(true_part, x, y, yaw, floor), lateral_friction=1.0
        )
        for _ in range(int(0.3 / world.settings.control_dt)):  # let the part settle
            world.step()
        robot.ft.bias()
        assert setup.plan.l_a is not None and setup.plan.alpha is not None
        params = PivotParams(l_a=setup.plan.l_a, alpha=setup.plan.alpha, **setup.params)
        camera = SimCamera(
            world,
            lambda: robot.world_pose(robot.arm.tool_pose()),
            tool_T_camera=setup.layout.tool_T_camera(),  # the configured (calibrated) mount
            mount_error=draws.mount_error(),  # where the camera really is against it
        )
        dev = Devices(robot.arm, robot.gripper, robot.ft, world.clock, camera)
    except Exception:
        world.close()
        raise
    return TrialWorld(
        world,
        cell,
        robot,
        body,
        params,
        dev,
        {"x": x, "y": y, "yaw": yaw},
        {"S": mu_s, "H": mu_h, "G": mu_g},
        true_part.mass,
        wall0,
        draws,
        floor,
    )


def judge_trial(
    tw: TrialWorld,
    seed: int,
    failure: StepResult | None,
    phase: str,
    on_frame: Callable[[SimWorld, SimRobot], None] | None = None,
    frame_every: int = 6,
) -> dict[str, Any]:
    """Hold still, then judge the hole grasp from the simulated state: the fields of a
    :class:`TrialResult` (the caller adds its own)."""
    world, robot = tw.world, tw.robot
    for _ in range(int(0.3 / world.settings.control_dt)):  # hold still, then judge
        world.step()
        if on_frame is not None and world.steps % frame_every == 0:
            on_frame(world, robot)
    tips = {name: robot.fingertip(name) for name in ("finger_a", "finger_b")}
    verdict = judge(
        world,
        tw.body,
        tw.cell.floor,
        robot.body_id,
        {n: robot.gripper.finger_link(n) for n in ("finger_a", "finger_b")},
        tips,
        floor_z=tw.floor_z,
    )
    success = failure is None and verdict.success
    if failure is not None:
        text, code = failure.message, failure.code
    else:
        text, code = verdict.failure, verdict.code
    return {
        "seed": seed,
        "success": success,
        "failure": None if success else text,
        "failure_code": None if success or code is None else str(code),
        "phase": phase,
        "tilt_deg": verdict.tilt_deg,
        "height_m": verdict.height_m,
        "sim_time": world.clock.now(),
        "wall_time": time.perf_counter() - tw.wall0,
        "true_pose": tw.true_pose,
        "frictions": tw.frictions,
        "mass": tw.mass,
        "draws": tw.draws.to_json() if tw.draws is not None else {},
    }


def run_trial(
    setup: TrialSetup,
    seed: int,
    on_frame: Callable[[SimWorld, SimRobot], None] | None = None,
    frame_every: int = 6,
    close_gripper_anyway: bool = True,
    trace: Callable[[list[WatchSample], dict[str, float]], None] | None = None,
    make_align: Callable[[Tilt, TrialSetup, PivotParams, Devices], Any] | None = None,
) -> TrialResult:
    """One perturbed trial, judged from the simulated state. ``trace`` receives the watched
    samples and the phase start times (for the contact-trace figure); ``make_align`` builds
    another skill in Align's place (the judge's tests give it skills that cheat)."""
    tw = open_trial_world(setup, seed)
    world, robot, params, dev = tw.world, tw.robot, tw.params, tw.dev
    camera = dev.camera
    assert isinstance(camera, SimCamera)
    fingers = ("finger_a", "finger_b")  # finger_a on S (outer), finger_b into the hole (H)
    watch = PivotWatch(
        world,
        tw.body,
        robot.body_id,
        {n: robot.gripper.finger_link(n) for n in fingers},
        robot.pad_tip,
        lambda: camera.frames_taken,
        inner="finger_b",
        outer="finger_a",
    )
    forces = ForceWatch.for_robot(world, robot, tw.body)  # made at rest: the tool's weight
    try:
        failure: StepResult | None = None
        phase_name = "done"
        recovered_by: StepResult | None = None
        t_end = world.clock.now() + setup.max_time + (4.0 if setup.perceive else 0.0)
        seen: dict[str, float] = {}
        frame = setup.frame()
        if setup.pose == "random":  # no nominal pose: without a look, the skills get the drawn one
            t = tw.true_pose
            frame = dataclasses.replace(
                frame, center=np.array([t["x"], t["y"], 0.5 * setup.part.outer]), yaw=t["yaw"]
            )
        early = "look"  #: the phase a failure before the Grasp is counted in
        walls = bin_obstacles(setup.layout)
        width = dev.gripper.finger_width

        here = reach_from(dev.arm.joint_positions)  #: from where the arm stands when asked
        home = robot.arm.home_joints
        assert home is not None  # the trial's robot is built at home
        # a plan out of reach from where the look left the arm goes home first, as the cell's
        reach = reach_from_or_home(dev.arm.joint_positions, home)

        def choose(f: PivotFrame) -> EndChoice:
            return choose_end(f, params, walls, width, setup.part.open_ends, reach=reach)

        def grasp_rotation(f: PivotFrame) -> NDArray[np.float64]:
            """The Grasp's rotation at the end the plan will choose, sweeps and all: a view
            turned to the other end's yaw left the Grasp a wrist turn past its joint limit
            after a drag against a wall (target unreachable)."""
            return choose(f).frame.grasp_rotation(params.alpha)

        if setup.perceive:
            failure, looked = look_near(
                setup, tw, frame, setup.nominal_center(), t_end, on_frame, frame_every, seen,
                grasp_rotation,
            )
            frame = looked or frame

        choice = choose(frame)
        repositioned, moved_by = False, None
        if failure is None and not choice.clearance.clear:
            # No end clears where the part lies: drag (or roll) it to where one does, look again.
            move = plan_reposition(
                frame, setup.part, params, setup.reposition or RepositionParams(), walls, [],
                setup.layout.bin_interior(), width, reach=reach,
            )
            if move is not None:
                early, repositioned, moved_by = "reposition", True, move.kind.value
                t_end += setup.max_time
                skill = Reposition(move, setup.part, dev, setup.reposition)
                failure = run_skill("reposition", skill, world, robot, t_end, on_frame, frame_every)
                frame = move.target
                if failure is None and setup.perceive:
                    early = "look"
                    target_xy = (float(move.target.center[0]), float(move.target.center[1]))
                    failure, looked = look_near(
                        setup, tw, frame, target_xy, t_end, on_frame, frame_every, seen,
                        grasp_rotation,
                    )
                    frame = looked or frame
                choice = choose(frame)
        if (failure is None and choice.clearance.clear
                and reach_problem(choice.frame, params, width, here) is not None):
            early = "plan"
            failure = run_skill("home", go_home(dev, home, setup.home or HomeParams()),
                                world, robot, t_end, on_frame, frame_every)
        other_end = choice.frame is not frame
        frame = choice.frame
        if failure is None and not choice.clearance.clear:
            early = "plan"
            failure = StepResult(
                Status.FAILURE, f"plan: {choice.clearance.reason()}", Failure.NO_CLEAR_PIVOT
            )
        grasp = Grasp(frame, params, dev)
        tilt = Tilt(lambda: grasp.frame, params, dev)
        if make_align is None:
            align = Align(lambda: tilt.frame, setup.part, params, dev)
        else:
            align = make_align(tilt, setup, params, dev)

        def step_of(skill: Any) -> None:
            sequence = getattr(skill, "sequence", None)
            watch.step = getattr(sequence, "current", None)

        def align_phase() -> None:
            step_of(align)
            if getattr(align, "lifting", False) and watch.phase != "lift":
                watch.enter("lift")
                forces.enter("lift")

        def close_began() -> None:
            step_of(grasp)
            if getattr(grasp, "sequence", None) and grasp.sequence.current == Grasp.close_step:
                forces.mark("close")

        phases = [("grasp", grasp), ("tilt", tilt), ("align", align)]
        for phase_name, skill in phases if failure is None else []:
            if phase_name == "grasp":
                watch.grasp_began()
            else:
                watch.enter(phase_name)
            forces.enter(phase_name)
            failure = run_skill(
                phase_name,
                skill,
                world,
                robot,
                t_end,
                on_frame,
                frame_every,
                align_phase if skill is align else close_began if skill is grasp
                else (lambda s=skill: step_of(s)),
            )
            if failure is not None:
                break
        else:
            phase_name = early if failure is not None else "done"
        if phase_name == "align" and failure is not None and not robot.arm.status().protective_stop:
            # The in-hand Align failed: the old way (let go, look, pick from above) may still
            # save the part, counted apart.
            watch.enter("recovery")
            forces.enter("recovery")
            recovery = PickFromAbove(lambda: tilt.frame, setup.part, params, dev)
            t_rec = world.clock.now() + setup.max_time
            if run_skill("recovery", recovery, world, robot, t_rec, on_frame, frame_every) is None:
                recovered_by = failure
                failure = None
        watch.stop()
        forces.stop()
        fields = judge_trial(tw, seed, failure, phase_name, on_frame, frame_every)
        end_ok = bool(fields["success"])
        strict = watch.failure_with_code()
        recovered = recovered_by is not None and end_ok
        if recovered:
            assert recovered_by is not None
            fields["failure"] = f"{recovered_by.message}; recovered by the pick from above"
            fields["failure_code"] = str(recovered_by.code) if recovered_by.code else None
        elif end_ok and strict is not None:
            fields["failure_code"], fields["failure"] = str(strict[0]), strict[1]
        fields["success"] = end_ok and strict is None and recovered_by is None
        ends = watch.phase_starts
        phase_times = watch.phase_times(world.clock.now())
        phase_times.pop("recovery", None)
        if trace is not None:
            trace(watch.samples, dict(ends))
        return TrialResult(
            **fields,
            perceived_pose=seen or None,
            end_state_ok=end_ok,
            inner_in_hole_all_along=watch.inner_in_hole_all_along(),
            longest_free_s=watch.longest_free_s(),
            longest_free=watch.longest_free(),
            final_grasp=watch.final_grasp().value,
            camera_frames_steering=watch.camera_frames_steering(),
            recovered=recovered,
            phase_times_s={k: phase_times.get(k, 0.0) for k in ("grasp", "tilt", "align", "lift")},
            l_a_trace=watch.l_a_trace(),
            clearance_mm=round(1e3 * choice.clearance.distance, 1),
            other_end=other_end,
            repositioned=repositioned,
            moved_by=moved_by,
            grip_force_n=forces.grip_force(),
            peak_force_n=forces.peaks(),
            shove_mm=forces.moved_mm("close", "grasp end"),
            hook_depth_mm=(round(1e3 * watch.samples[0].depth[watch.inner], 2)
                           if watch.samples else None),
        )
    finally:
        world.close()


def look_near(
    setup: TrialSetup,
    tw: TrialWorld,
    frame: PivotFrame,
    near: tuple[float, float],
    t_end: float,
    on_frame: Callable[[SimWorld, SimRobot], None] | None,
    frame_every: int,
    seen: dict[str, float],
    grip: Callable[[PivotFrame], NDArray[np.float64]] | None = None,
) -> tuple[StepResult | None, PivotFrame | None]:
    """The wrist camera's look for the part near ``near`` (the pivot's and the regrasp's trials
    alike): the look's failure, or ``frame`` moved to what it saw (``seen`` gets x, y, yaw);
    (None, None) when it saw nothing. ``grip``: the rotation the next skill holds the tool at
    over a part lying in a frame; the look's close view is turned to its yaw."""

    def seen_frame(d: Detection) -> PivotFrame:
        centre = np.array([d.center[0], d.center[1], 0.5 * setup.part.outer])
        return dataclasses.replace(frame, center=centre, yaw=d.yaw)

    look = Look(
        tw.dev,
        [setup.part],
        setup.layout.bin_interior(),
        (setup.layout.bin_center[0], setup.layout.bin_center[1]),
        near,
        setup.look,
        grip_yaw=None if grip is None else (lambda d: tool_yaw(grip(seen_frame(d)))),
        reach=reach_from(tw.dev.arm.joint_positions),
        floor_z=setup.layout.bin_floor_z,
    )
    result = run_skill("look", look, tw.world, tw.robot, t_end, on_frame, frame_every)
    if result is not None or look.result is None:
        return result, None
    d = look.result
    seen.update({"x": float(d.center[0]), "y": float(d.center[1]), "yaw": d.yaw})
    return None, seen_frame(d)


def run_skill(  # type: ignore[no-untyped-def]
    name, skill, world, robot, t_end, on_frame, frame_every, on_tick=None
) -> StepResult | None:
    """Tick ``skill`` with the world until it ends; its failure (message and code), or None."""
    result = skill.tick()
    while not result.done and world.clock.now() < t_end:
        if on_tick is not None:
            on_tick()
        world.step()
        if on_frame is not None and world.steps % frame_every == 0:
            on_frame(world, robot)
        result = skill.tick()
    if not result.done:
        skill.halt()
        return StepResult(Status.FAILURE, f"{name}: out of time", Failure.TIMEOUT)
    return result if result.status is Status.FAILURE else None


def summarize(part: str, results: list[TrialResult]) -> dict[str, object]:
    k, n = sum(r.success for r in results), len(results)
    lo, hi = wilson_interval(k, n)
    return {
        "part": part,
        "trials": n,
        "successes": k,
        "recovered": sum(r.recovered for r in results),
        "end_state_ok": sum(r.end_state_ok for r in results),
        "wilson95": [lo, hi],
        "per_trial": [r.to_json() for r in results],
    }


__all__ = ["Perturbation", "Pose", "TrialResult", "TrialSetup", "run_trial", "summarize"]
