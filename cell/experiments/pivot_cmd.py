"""``cell pivot``: randomized pivot trials of one part in the PyBullet twin.

Contract (scripts rely on it)::

    cell pivot --part NAME --trials N --seed S [--mu-ground X] [--record FILE.gif] --json FILE

``--record FILE.gif`` also writes ``FILE_trace.png``, the first trial's contact trace. Each
``per_trial`` entry carries the stricter verdict in ``success`` and what it was built from
(``inner_in_hole_all_along``, ``longest_free_s``, ``final_grasp``, ``camera_frames_steering``,
``recovered``), ``phase_times_s`` and ``l_a_trace``.

Trial ``i`` runs with seed ``S + i``; the same seed gives the same trial. Everything the user
gives is checked before anything is simulated: an unknown part, a part the planner declines
(hole narrower than the finger, deformable, ...), a cell YAML that fails validation or puts the
pick out of the arm's reach all end with one line naming the file, key and reason, exit 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import multiprocessing
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cell.catalogue import load_catalogue
from cell.errors import UserError
from cell.output import write_json
from drivers.parts import Gripper
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import PivotPlan, jaw_opening, plan_pivot
from skills.pivot import PivotParams

if TYPE_CHECKING:  # the twin (pybullet) is imported only when a pivot runs
    from cell.experiments.pivot_run import TrialResult, TrialSetup


class PivotInputError(ValueError):
    """Bad input for ``cell pivot`` (reported in one line, exit 2)."""


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "pivot",
        help="randomized Grasp/Tilt/Align trials of one part in the PyBullet twin",
        description="Run N perturbed pivot trials of a catalogue part in the simulated cell "
        "(position +-3 mm, yaw +-3 deg, frictions +-20 %, mass +-10 %), judged from the "
        "simulated state, and write the success rate with its Wilson 95 % interval as JSON.",
    )
    p.add_argument("--part", required=True, help="part name from the catalogue")
    p.add_argument("--trials", type=int, default=30, help="number of trials (30)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first trial; trial i: S+i")
    p.add_argument(
        "--mu-ground",
        type=float,
        default=None,
        help="part-floor friction coefficient, used exactly (not perturbed); default 0.4 +-20 %%",
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
        help="give the skills the part's nominal pose instead of looking with the wrist camera",
    )
    p.add_argument(
        "--pose",
        choices=("nominal", "random"),
        default="nominal",
        help="nominal: the part near its nominal pose (+-3 mm, +-3 deg); random: anywhere on "
        "the bin floor, any yaw, either end towards the robot, up against the walls",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="run a part the planner declines, at --la/--alpha (reported as forced)",
    )
    p.add_argument(
        "--la", type=float, default=None, help="with --force: l_a (largest that fits, <= 0.9)"
    )
    p.add_argument(
        "--alpha", type=float, default=None, help="with --force: alpha in rad (0.3142, 18 deg)"
    )
    p.set_defaults(func=cmd_pivot)


def _progress(bar: Any, done: int, ok: int, wall: float) -> None:
    bar.update(done, f"ok {ok}  {wall / max(1, done):.1f} s/trial")


def _trial(args: tuple[TrialSetup, int]) -> TrialResult:
    from cell.experiments.pivot_run import run_trial

    setup, seed = args
    return run_trial(setup, seed)


def add_config_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell configuration YAML whose skills.pivot section and safety limits the skills "
        "run with (default: the skills' defaults and the safety section's)",
    )


def pivot_overrides(config_path: Path | None) -> dict[str, Any]:
    """The :class:`PivotParams` fields a configuration changes: its ``skills.pivot`` keys, and
    its ``safety`` force and torque as the guard of every motion (as a tree node would give)."""
    from cell.config import CellConfig, load_config, skill_settings
    from skills.params import apply_config, with_limits
    from trees.yaml_lines import ConfigError

    try:
        config = load_config(config_path)[0] if config_path is not None else CellConfig()
    except ConfigError as exc:
        raise UserError(str(exc)) from None
    base = PivotParams(l_a=0.5, alpha=0.3)
    safety = config.safety
    settings = skill_settings(config)
    # With a cell's configuration, Align takes the hole grasp that cell's stations expect.
    fixed = settings["pivot_fixed"] if config_path is not None else {}
    tuned = with_limits(
        apply_config(dataclasses.replace(base, **fixed), settings["pivot"]),
        safety.ft_abort_force_n,
        safety.ft_abort_torque_nm,
    )
    return {
        f.name: getattr(tuned, f.name)
        for f in dataclasses.fields(tuned)
        if getattr(tuned, f.name) != getattr(base, f.name)
    }


def pivot_args(
    part: str,
    trials: int,
    catalogue: Path | None,
    cell: Path | None,
    nominal: bool,
    config: Path | None = None,
) -> argparse.Namespace:
    """The arguments ``cell pivot`` would get for one part, so other commands (sweep, compare)
    reuse its checks and setup unchanged: one source of truth for what a trial is."""
    return argparse.Namespace(
        part=part, trials=trials, jobs=1, mu_ground=None, record=None, catalogue=catalogue,
        cell=cell, nominal=nominal, force=False, la=None, alpha=None, config=config,
    )


def build_setup(args: argparse.Namespace) -> tuple[TrialSetup, PivotPlan, bool]:
    """Everything checked, nothing simulated: the trial setup, the plan, whether forced."""
    from cell.experiments.pivot_run import TrialSetup
    from drivers.layout import CellLayout

    if args.trials < 1:
        raise PivotInputError(f"--trials: must be >= 1, got {args.trials}")
    if args.jobs < 1:
        raise PivotInputError(f"--workers (--jobs): must be >= 1, got {args.jobs}")
    if args.mu_ground is not None and not (math.isfinite(args.mu_ground) and args.mu_ground >= 0):
        raise PivotInputError(f"--mu-ground: must be a finite number >= 0, got {args.mu_ground}")
    if args.record is not None and args.record.suffix.lower() != ".gif":
        raise PivotInputError(f"--record: {args.record}: the animation is written as a .gif")
    catalogue = load_catalogue(args.catalogue)
    part = catalogue.get(args.part)
    layout = CellLayout.from_yaml(args.cell) if args.cell is not None else CellLayout()
    frictions = Frictions()
    gripper = Gripper()
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
        params=pivot_overrides(getattr(args, "config", None)),
    )
    if args.mu_ground is not None:
        setup = dataclasses.replace(setup, mu_ground=args.mu_ground)
    if args.nominal:
        setup = dataclasses.replace(setup, perceive=False)
    if getattr(args, "pose", "nominal") == "random":
        setup = dataclasses.replace(setup, pose="random")
    reason = setup.reach_problem() if setup.pose == "nominal" else None
    if reason is not None:
        source = str(args.cell) if args.cell is not None else "the default cell layout"
        raise PivotInputError(f"{source}: bin_center: {reason}")
    return setup, plan, forced


def cmd_pivot(args: argparse.Namespace) -> int:
    from cell.experiments.pivot_run import summarize

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
    first = 0
    if args.record is not None:
        results.append(_recorded_trial(setup, seeds[0], args.record))
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
            "pose_source": "nominal" if args.nominal else "wrist camera",
            "mu_ground": args.mu_ground,
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
        + (f", {recorded} and {trace_path(recorded)}" if recorded else "")
    )
    return 0


def _recorded_trial(setup: TrialSetup, seed: int, path: Path) -> TrialResult:
    from cell.experiments.pivot_run import run_trial
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
        from cell.experiments.figures import plot_contact_trace

        verdict = "success" if result.success else f"failed: {result.failure}"
        plot_contact_trace(
            traced["samples"],
            traced["phases"],
            trace_path(path),
            f"{setup.part.name}, seed {seed}: {verdict} (final grasp {result.final_grasp}, "
            f"longest free {result.longest_free_s:.2f} s)",
        )
    return result


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
