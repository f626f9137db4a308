"""``cell pivot``: randomized pivot trials of one part in the PyBullet twin.

Contract (scripts rely on it)::

    cell pivot --part NAME --trials N --seed S [--mu-ground X] [--record FILE.gif] --json FILE
        [--config FILE] [--set KEY.PATH=VALUE]...

``--record FILE.gif`` also writes ``FILE_trace.png``, the first trial's contact trace. Each
``per_trial`` entry carries the stricter verdict in ``success`` and what it was built from
(``inner_in_hole_all_along``, ``longest_free_s``, ``final_grasp``, ``camera_frames_steering``,
``recovered``), ``phase_times_s`` and ``l_a_trace``, and what the twin's forces did, measured
from the simulated state by :class:`sim.judge.ForceWatch` (never from the plan):

* ``grip_force_n``: N per finger the gripper's motors applied while the pivot held the part:
  PyBullet's applied joint motor force of the two finger joints (``getJointState(...)[3]``,
  positive closing), their mean each control step of the Tilt, the median over the Tilt; null
  when the trial never reached the Tilt;
* ``peak_force_n``: ``{"grasp", "tilt", "align", "lift"}``: the peak force magnitude at the
  wrist in each phase, N: the wrist sensor joint's reaction as PyBullet computes it (the
  ground truth the sim sensor reads before its noise and power-up offset), less the tool's own
  weight (read at rest before the trial, turned with the tool); null for a phase never reached;
* ``shove_mm``: how far the Grasp's close moved the part: its centre in the floor plane when the
  "close onto H" step starts against when the Grasp ends (mm); null when the close never began;
* ``hook_depth_mm``: how far the inner pad's tip (the judge's point, 2 mm from its end) lay past
  the open end's face at the judge's first sample after the Grasp closed (mm; negative: short of
  the face, the pad on the lip); null when the Grasp never closed.

The top level's ``pose_source`` says where the Grasp's pose came from: ``camera`` (default: the
twin's wrist camera and the Look skill) or ``nominal`` (``--nominal``).

Every trial draws a real cell's uncertainty from its seed (:mod:`sim.uncertainty`): each
``per_trial`` entry's ``draws`` says what (plain numbers named with their units), the top
level's ``ideal`` whether ``--ideal`` turned it off.

``--config FILE`` runs the trials with a cell configuration, loaded, validated and ``--set``
exactly as ``cell sim`` does it: every section a trial has a use for (skills.pivot,
skills.perceive, skills.reposition, the safety force and torque limits, sim.mu_ground,
cell.control_hz, cell.layout, cell.catalogue; see ``--help`` for the sections it has none for).
``--set KEY.PATH=VALUE`` (repeatable) changes one key on top of the file, or of the defaults
without one.

Trial ``i`` runs with seed ``S + i``; the same seed gives the same trial. Everything the user
gives is checked before anything is simulated: an unknown part, a part the planner declines
(hole narrower than the finger, deformable, ...), a cell YAML that fails validation or puts the
pick out of the arm's reach, a bad ``--set`` key or value all end with one line naming the file
(or the ``--set``), key and reason, exit 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import multiprocessing
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cell.catalogue import load_catalogue
from cell.errors import UserError
from cell.output import write_json
from drivers.gripper_spec import default_gripper
from drivers.parts import Gripper
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import PivotPlan, jaw_opening, plan_pivot
from skills.pivot import PivotParams

if TYPE_CHECKING:  # the twin (pybullet) is imported only when a pivot runs
    from lab.pivot_run import TrialResult, TrialSetup


class PivotInputError(ValueError):
    """Bad input for ``cell pivot`` (reported in one line, exit 2)."""


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "pivot",
        help="randomized Grasp/Tilt/Align trials of one part in the PyBullet twin",
        description="Run N perturbed pivot trials of a catalogue part in the simulated cell, "
        "judged from the simulated state, and write the success rate with its Wilson 95 % "
        "interval as JSON. Each trial draws from its seed the part's position (+-3 mm) and yaw "
        "(+-3 deg) and a real cell's uncertainty: the camera's hand-eye error (+-1 mm, +-0.5 "
        "deg per axis), the bin floor's height (+-1.5 mm), the part's outer diameter, hole and "
        "length (+-0.3 mm each) and mass (+-10 %), the pad frictions mu_S, mu_H (0.2-1.0) and "
        "the floor's mu_G (0.25-0.6), the FT300's noise (its 100 Hz stream, 0.01 N "
        "resolution), and the arm's command lag (1-3 control periods); each trial's draws are "
        "in its JSON entry ('draws'). --ideal turns the uncertainty off.",
    )
    p.add_argument("--part", required=True, help="part name from the catalogue")
    p.add_argument("--trials", type=int, default=30, help="number of trials (30)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first trial; trial i: S+i")
    p.add_argument(
        "--mu-ground",
        type=float,
        default=None,
        help="part-floor friction coefficient, used exactly (not drawn); default drawn from "
        "0.25-0.6 (0.4 +-20 %% with --ideal)",
    )
    p.add_argument(
        "--mu-pad",
        type=float,
        default=None,
        help="pad-part friction at S and H, used exactly (not drawn); default drawn from "
        "0.2-1.0. With --mu-ground 0 it tests the paper's claim that G needs stiction where "
        "its Eq. 8 says so (docs/pivot_in_hand.md)",
    )
    p.add_argument("--record", type=Path, default=None, help="GIF of the first trial")
    p.add_argument("--json", type=Path, required=True, help="where to write the results")
    p.add_argument(
        "--layout", "--cell", dest="cell", type=Path, default=None, metavar="FILE",
        help="cell layout YAML (default: the default layout)",
    )
    p.add_argument("--catalogue", type=Path, default=None, help="part catalogue YAML")
    add_config_argument(p)
    p.add_argument(
        "--workers", "--jobs", dest="jobs", type=int, default=1, metavar="K",
        help="trials run in parallel processes (1)",
    )
    p.add_argument(
        "--nominal",
        action="store_true",
        help="give the skills the part's nominal pose instead of looking with the wrist camera "
        "(where the part lies is --pose's)",
    )
    p.add_argument(
        "--pose",
        choices=("nominal", "random"),
        default="nominal",
        help="where the part lies (what the skills are told is --nominal's). nominal: near its "
        "nominal pose (+-3 mm, +-3 deg); random: anywhere on "
        "the bin floor, any yaw, either end towards the robot, up against the walls",
    )
    add_ideal_argument(p)
    p.add_argument(
        "--force",
        action="store_true",
        help="run a part the planner declines, at --la/--alpha (reported as forced)",
    )
    p.add_argument(
        "--la", type=float, default=None,
        help="with --force: l_a (default: the largest that fits, <= 0.9)",
    )
    p.add_argument(
        "--alpha", type=float, default=None,
        help="with --force: alpha in rad (default: 0.3142, 18 deg)",
    )
    p.set_defaults(func=cmd_pivot)


def add_ideal_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--ideal",
        action="store_true",
        help="for debugging only: turn the real cell's uncertainty off (no hand-eye error, "
        "floor height or part tolerances, the twin's old sensor sampled every control step, no "
        "command lag; frictions +-20 %% about the planner's, mass +-10 %%); the JSON says "
        "\"ideal\": true",
    )


def _progress(bar: Any, done: int, ok: int, wall: float) -> None:
    bar.update(done, f"ok {ok}  {wall / max(1, done):.1f} s/trial")


def _trial(args: tuple[TrialSetup, int]) -> TrialResult:
    from lab.pivot_run import run_trial

    setup, seed = args
    return run_trial(setup, seed)


def add_config_argument(p: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--set KEY.PATH=VALUE`` (as ``cell sim`` has them)."""
    from cell.overrides import add_set_argument

    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell configuration YAML (as `cell sim --config`) the trials run with: "
        "skills.pivot (Grasp, Tilt, Align, the recovery, and compare's regrasp), "
        "skills.perceive (the look), skills.reposition (the drag), safety.ft_abort_force_n and "
        "ft_abort_torque_nm (every motion's guard), sim.mu_ground (part-floor friction, used "
        "exactly; a --mu-ground wins), cell.control_hz (the trial's control rate; the physics "
        "step stays <= 4 ms), cell.layout (--layout wins) and cell.catalogue (--catalogue "
        "wins); these four only where the file or a --set gives them. The rest has no meaning "
        "for a trial and is not used: cell.name and backend (always the twin), sim.seed (--seed "
        "seeds the trials), sim.yaw_spread_deg and realtime, bin, workflow, the other skills "
        "sections (slot, pack_in_box, put_back, go_home), safety's timeouts and settle times "
        "(a tree's), devices, log, faults, emulate and tree. Default: every section's defaults",
    )
    add_set_argument(p)


@dataclass(frozen=True)
class TrialConfig:
    """What a cell configuration (``--config`` and ``--set``) gives the trials; None where it
    gives nothing (the trial's own default)."""

    params: dict[str, Any] = field(default_factory=dict)  #: :class:`PivotParams` overrides
    look: Any = None  #: :class:`skills.perception.look.LookParams`
    reposition: Any = None  #: :class:`skills.reposition.RepositionParams`
    home: Any = None  #: :class:`skills.home.HomeParams`
    mu_ground: float | None = None  #: sim.mu_ground, where given
    control_hz: float | None = None  #: cell.control_hz, where given
    layout: Any = None  #: :class:`drivers.layout.CellLayout` of cell.layout, where given
    catalogue: Path | None = None  #: cell.catalogue (relative to the file), where given
    gripper: Any = None  #: :class:`drivers.gripper_spec.GripperSpec` of ``gripper``, where given
    #: devices.arm's servoj (lookahead s, gain) where sim.servoj is on, else None
    servo: tuple[float, float] | None = None


def trial_config(config_path: Path | None, sets: Sequence[str] = ()) -> TrialConfig:
    """Read, ``--set`` and validate a configuration as ``cell sim`` does (None and no ``sets``:
    nothing given), then take what a trial uses from it (see :func:`add_config_argument`).

    Skill sections and the safety limits apply as a tree node would apply them; sim.mu_ground,
    cell.control_hz, cell.layout and cell.catalogue only where the file or a ``--set`` gives
    them (a default is not a choice: the trial keeps its own, e.g. the perturbed floor
    friction). Any problem is a :class:`UserError` in one line naming the file and line or the
    ``--set``, and the key."""
    if config_path is None and not sets:
        from cell.config import CellConfig, twin_servo

        # nothing given: the trials keep their own defaults, and the arm moves as the shipped
        # configuration's does (sim.servoj)
        return TrialConfig(servo=twin_servo(CellConfig()))
    from cell.assemble import _layout
    from cell.config import gripper_of, skill_settings, twin_servo, validate_document
    from cell.overrides import apply_sets
    from skills.params import apply_config, with_limits
    from trees.yaml_lines import ConfigError, LinedDocument, load_yaml

    try:
        doc = load_yaml(config_path) if config_path is not None else LinedDocument("--set", {})
        doc = apply_sets(doc, sets)
        config = validate_document(doc)
        layout = _layout(config, doc) if config.cell.layout else None
        gripper = gripper_of(config, doc) if "gripper" in config.model_fields_set else None
    except ConfigError as exc:
        raise UserError(str(exc)) from None
    base = PivotParams(l_a=0.5, alpha=0.3)
    safety = config.safety
    settings = skill_settings(config)
    # With a cell's configuration, Align takes the hole grasp that cell's stations expect.
    cell_given = config_path is not None or "slot" in config.skills.model_fields_set
    fixed = settings["pivot_fixed"] if cell_given else {}

    def limited(params: Any) -> Any:
        return with_limits(params, safety.ft_abort_force_n, safety.ft_abort_torque_nm)

    tuned = limited(apply_config(dataclasses.replace(base, **fixed), settings["pivot"]))
    catalogue = None
    if "catalogue" in config.cell.model_fields_set and config.cell.catalogue is not None:
        catalogue = Path(config.cell.catalogue)
        if config_path is not None and not catalogue.is_absolute():
            catalogue = config_path.resolve().parent / catalogue
    return TrialConfig(
        params={
            f.name: getattr(tuned, f.name)
            for f in dataclasses.fields(tuned)
            if getattr(tuned, f.name) != getattr(base, f.name)
        },
        look=limited(settings["perceive"]),
        reposition=limited(settings["reposition"]),
        home=limited(settings["go_home"]),
        mu_ground=config.sim.mu_ground if "mu_ground" in config.sim.model_fields_set else None,
        control_hz=config.cell.control_hz if "control_hz" in config.cell.model_fields_set else None,
        layout=layout,
        catalogue=catalogue,
        gripper=gripper,
        servo=twin_servo(config),
    )


def pivot_overrides(config_path: Path | None, sets: Sequence[str] = ()) -> dict[str, Any]:
    """The :class:`PivotParams` fields a configuration changes: its ``skills.pivot`` keys, and
    its ``safety`` force and torque as the guard of every motion (as a tree node would give)."""
    return trial_config(config_path, sets).params


def with_control_rate(physics: Any, control_hz: float) -> Any:
    """``physics`` ticking the skills at ``control_hz``, its physics step no longer than the
    default's (substeps = ceil(default physics rate / control_hz))."""
    rate = type(physics)().control_hz * type(physics)().substeps
    substeps = max(1, math.ceil(rate / control_hz - 1e-9))
    return dataclasses.replace(physics, control_hz=control_hz, substeps=substeps)


def pivot_args(
    part: str,
    trials: int,
    catalogue: Path | None,
    cell: Path | None,
    nominal: bool,
    config: Path | None = None,
    sets: Sequence[str] = (),
    ideal: bool = False,
) -> argparse.Namespace:
    """The arguments ``cell pivot`` would get for one part, so other commands (sweep, compare)
    reuse its checks and setup unchanged: one source of truth for what a trial is."""
    return argparse.Namespace(
        part=part, trials=trials, jobs=1, mu_ground=None, record=None, catalogue=catalogue,
        cell=cell, nominal=nominal, force=False, la=None, alpha=None, config=config,
        set=list(sets), ideal=ideal,
    )


def build_setup(args: argparse.Namespace) -> tuple[TrialSetup, PivotPlan, bool]:
    """Everything checked, nothing simulated: the trial setup, the plan, whether forced."""
    from drivers.layout import CellLayout
    from lab.pivot_run import TrialSetup

    if args.trials < 1:
        raise PivotInputError(f"--trials: must be >= 1, got {args.trials}")
    if args.jobs < 1:
        raise PivotInputError(f"--workers (--jobs): must be >= 1, got {args.jobs}")
    if args.mu_ground is not None and not (math.isfinite(args.mu_ground) and args.mu_ground >= 0):
        raise PivotInputError(f"--mu-ground: must be a finite number >= 0, got {args.mu_ground}")
    mu_pad = getattr(args, "mu_pad", None)
    if mu_pad is not None and not (math.isfinite(mu_pad) and mu_pad >= 0):
        raise PivotInputError(f"--mu-pad: must be a finite number >= 0, got {mu_pad}")
    if args.record is not None and args.record.suffix.lower() != ".gif":
        raise PivotInputError(f"--record: {args.record}: the animation is written as a .gif")
    given = trial_config(getattr(args, "config", None), getattr(args, "set", None) or ())
    catalogue = load_catalogue(args.catalogue if args.catalogue is not None else given.catalogue)
    part = catalogue.get(args.part)
    if args.cell is not None:
        layout = CellLayout.from_yaml(args.cell)
    else:
        layout = given.layout if given.layout is not None else CellLayout()
    frictions = Frictions()
    spec = given.gripper if given.gripper is not None else default_gripper()
    # the planner's model of that gripper
    gripper = Gripper.from_spec(spec)
    plan = plan_pivot(part, gripper, frictions)
    forced = False
    if not plan.pivotable:
        where = f"{catalogue.path}: parts.{part.name}"
        if not args.force:
            raise PivotInputError(
                f"{where}: not pivotable: {plan.reason} (--force --la L --alpha A tries anyway)"
            )
        if gripper.finger_width >= part.hole:
            raise PivotInputError(
                f"{where}: hole_mm: {part.hole * 1e3:g} mm is narrower than the "
                f"{gripper.finger_width * 1e3:g} mm finger: no finger can enter it, not even "
                "with --force"
            )
        forced = True
        alpha = 0.3142 if args.alpha is None else args.alpha
        if not 0.0 < alpha < 0.5 * math.pi:
            raise PivotInputError(f"--alpha: must lie in (0, pi/2) rad, got {alpha:g}")
        section = part.section(gripper.finger_width)
        usable = gripper.stroke - gripper.clearance
        # By default the largest l_a (at most 0.9) whose jaw opening fits the stroke.
        la_fit = (usable - section.delta * math.sin(alpha)) / (2 * section.a * math.cos(alpha))
        l_a = min(0.9, la_fit) if args.la is None else args.la
        if not 0.0 < l_a <= 1.0:
            raise PivotInputError(f"--la: must lie in (0, 1], got {l_a:g}")
        opening = float(jaw_opening(section, l_a, alpha))
        if opening > usable + 1e-9:
            raise PivotInputError(
                f"--la/--alpha: the grasp needs a {opening * 1e3:.0f} mm jaw opening plus "
                f"{gripper.clearance * 1e3:.0f} mm clearance, the stroke is "
                f"{gripper.stroke * 1e3:.0f} mm"
            )
        plan = dataclasses.replace(plan, l_a=l_a, alpha=alpha, delta_m=section.delta)
    elif args.la is not None or args.alpha is not None:
        raise PivotInputError("--la/--alpha: only with --force on a part the planner declines")
    setup = TrialSetup(
        part=part,
        plan=plan,
        frictions=frictions,
        layout=layout,
        params=given.params,
        look=given.look,
        reposition=given.reposition,
        home=given.home,
        gripper=spec,
    )
    mu_ground = args.mu_ground if args.mu_ground is not None else given.mu_ground
    if mu_ground is not None:
        setup = dataclasses.replace(setup, mu_ground=mu_ground)
    if mu_pad is not None:
        setup = dataclasses.replace(setup, mu_pad=mu_pad)
    # sim.servoj (on unless the configuration turns it off): the arm follows as a UR does
    setup = dataclasses.replace(setup, servo=given.servo)
    if given.control_hz is not None:
        setup = dataclasses.replace(
            setup, physics=with_control_rate(setup.physics, given.control_hz)
        )
    if args.nominal:
        setup = dataclasses.replace(setup, perceive=False)
    if getattr(args, "ideal", False):
        from sim.uncertainty import Uncertainty

        pert = setup.perturbation
        setup = dataclasses.replace(setup, uncertainty=Uncertainty.ideal(pert.friction, pert.mass))
    if getattr(args, "pose", "nominal") == "random":
        setup = dataclasses.replace(setup, pose="random")
    reason = setup.reach_problem() if setup.pose == "nominal" else None
    if reason is not None:
        if args.cell is not None:
            source = str(args.cell)
        elif given.layout is not None:
            config = getattr(args, "config", None)
            source = f"{config}: cell.layout" if config is not None else "--set cell.layout"
        else:
            source = "the default cell layout"
        raise PivotInputError(f"{source}: bin_center: {reason}")
    return setup, plan, forced


def cmd_pivot(args: argparse.Namespace) -> int:
    from lab.pivot_run import summarize

    try:
        setup, plan, forced = build_setup(args)
    except PivotInputError as exc:
        raise UserError(str(exc)) from None
    seeds = [args.seed + i for i in range(args.trials)]
    wall0 = time.perf_counter()
    from cell.progress import Progress

    bar = Progress(len(seeds), "trials")
    results: list[TrialResult] = []
    recorded: Path | None = None
    traced = False
    first = 0
    if args.record is not None:
        result, traced = _recorded_trial(setup, seeds[0], args.record)
        results.append(result)
        recorded = args.record
        first = 1
        _progress(bar, 1, sum(r.success for r in results), time.perf_counter() - wall0)
    rest = [(setup, s) for s in seeds[first:]]
    if args.jobs > 1 and len(rest) > 1:
        with multiprocessing.get_context("spawn").Pool(args.jobs) as pool:
            for r in pool.imap(_trial, rest):
                results.append(r)
                _progress(
                    bar,
                    len(results),
                    sum(x.success for x in results),
                    time.perf_counter() - wall0,
                )
    else:
        for item in rest:
            results.append(_trial(item))
            _progress(
                bar,
                len(results),
                sum(x.success for x in results),
                time.perf_counter() - wall0,
            )
    bar.close()
    wall = time.perf_counter() - wall0
    summary = summarize(setup.part.name, results)
    summary.update(
        {
            "seed": args.seed,
            "forced": forced,
            "pose_source": "nominal" if args.nominal else "camera",
            "gripper": setup.gripper.name,
            "ideal": setup.uncertainty.is_ideal,
            "mu_ground": setup.mu_ground,
            "mu_pad": setup.mu_pad,
            "plan": plan.to_json(),
            "physics": setup.physics_json(),
            "wall_time_s": wall,
            "recorded": None if recorded is None else str(recorded),
        }
    )
    write_json(args.json, summary)
    print(_format_summary(summary, results, wall))
    print(
        f"wrote {args.json}"
        + (f", {recorded}" if recorded else "")
        + (f" and {trace_path(recorded)}" if recorded and traced else "")
    )
    return 0


def _recorded_trial(setup: TrialSetup, seed: int, path: Path) -> tuple[TrialResult, bool]:
    """The first trial, filmed; and whether it got as far as a contact trace (a Grasp that
    fails has none to plot)."""
    from lab.pivot_run import run_trial
    from sim.recorder import Recorder

    rec: dict[str, Recorder] = {}
    cx, cy = setup.nominal_center()

    def on_frame(world: Any, robot: Any) -> None:
        if "r" not in rec:
            yaw = setup.nominal_yaw
            normal = (math.sin(yaw), -math.cos(yaw), 0.0)
            target = (cx, cy, 0.5 * setup.part.length)
            rec["r"] = Recorder(world, target, normal, distance=0.24, height=0.15)
        rec["r"].capture()

    traced: dict[str, Any] = {}

    def trace(samples: Any, phase_starts: dict[str, float]) -> None:
        traced.update(samples=samples, phases=phase_starts)

    result = run_trial(setup, seed, on_frame=on_frame, frame_every=12, trace=trace)
    if "r" in rec:
        rec["r"].save_gif(path, fps=12)
    if traced.get("samples"):
        from cell.figures import plot_contact_trace

        verdict = "success" if result.success else f"failed: {result.failure}"
        plot_contact_trace(
            traced["samples"],
            traced["phases"],
            trace_path(path),
            f"{setup.part.name}, seed {seed}: {verdict} (final grasp {result.final_grasp}, "
            f"longest free {result.longest_free_s:.2f} s)",
        )
        return result, True
    return result, False


def trace_path(gif: Path) -> Path:
    """``FILE.gif`` -> ``FILE_trace.png``: the contact trace written beside the animation."""
    return gif.with_name(gif.stem + "_trace.png")


def _format_summary(summary: dict[str, Any], results: list[TrialResult], wall: float) -> str:
    k, n = summary["successes"], summary["trials"]
    lo, hi = summary["wilson95"]
    lines = [
        f"part        {summary['part']}"
        + ("  (FORCED past the planner)" if summary["forced"] else ""),
        f"success     {k}/{n}  ({100.0 * k / n:.0f} %, Wilson 95 % interval "
        f"{100 * lo:.0f}-{100 * hi:.0f} %)",
    ]
    failures: dict[str, int] = {}
    for r in results:
        if not r.success and r.failure:
            key = r.failure_key
            failures[key] = failures.get(key, 0) + 1
    for reason, count in sorted(failures.items(), key=lambda kv: -kv[1]):
        lines.append(f"  failed    {count} x {reason}")
    sim = sum(r.sim_time for r in results)
    trial_wall = sum(r.wall_time for r in results)
    lines.append(
        f"time        {sim:.0f} s simulated in {trial_wall:.0f} s of trials "
        f"({sim / max(trial_wall, 1e-9):.1f}x real time), {wall:.0f} s wall"
    )
    return "\n".join(lines)
