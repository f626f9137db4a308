"""``cell compare``: the pivot against the regrasp baseline on the same parts and seeds.

::

    cell compare --part NAME --trials N --seed S [--json FILE] [--nominal]
        [--config FILE] [--set KEY.PATH=VALUE]...

Trial ``i`` uses seed ``S + i`` for both methods, so both meet the same perturbed part (true pose,
frictions, mass). The pivot runs as ``cell pivot`` runs it (:func:`run_trial`); the baseline is
:func:`lab.regrasp_run.run_regrasp_trial`. Both get the part's pose the same way:
by default from the twin's wrist camera (the Look skill, before the first grasp; its time counts
in the tact time of both), with ``--nominal`` the nominal pose; the JSON's ``pose_source`` says
which (``camera`` or ``nominal``). ``--config`` and ``--set`` apply a cell configuration as
``cell pivot`` does (the regrasp runs with skills.pivot's parameters; there is no regrasp
section). The pivot's per-trial entries carry ``cell pivot``'s keys, ``grip_force_n``,
``peak_force_n`` and ``shove_mm`` included (null in the regrasp's). Both are judged by
:func:`sim.judge.judge` after the lift and measured by the same :class:`GripperProbe`: tact time
(first motion to the end of the lift of the hole grasp, simulated seconds) and the volume swept
by the gripper's collision geometry (5 mm voxels, cm^3). Means and medians are over successful
trials. The project's goal is a pivot at least 30 % faster (tact ratio pivot / regrasp <= 0.70);
the command reports what it measures either way.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path
from typing import Any

from cell.errors import UserError
from cell.output import write_json
from lab.pivot_cmd import add_config_argument, add_ideal_argument

GOAL_RATIO = 0.70  #: pivot tact / regrasp tact the project aims at (at least 30 % faster)


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "compare",
        help="pivot versus the regrasp baseline: success, tact time, swept volume",
        description="Run N seeded trials of the pivot and of the regrasp baseline "
        "(pinch, turn upright in the air, set down, Align) on the same perturbed part in the "
        "twin (the same draws of the cell's uncertainty, as `cell pivot` draws them; --ideal "
        "without), judge both from the simulated state, and report success, tact time and the "
        "volume swept by the gripper.",
    )
    p.add_argument("--part", required=True, help="part name from the catalogue")
    p.add_argument("--trials", type=int, default=10, help="trials per method (10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first trial; trial i: S+i")
    p.add_argument("--json", type=Path, default=None, help="where to write the results")
    p.add_argument(
        "--layout", "--cell", dest="cell", type=Path, default=None, metavar="FILE",
        help="cell layout YAML (default: the default layout)",
    )
    p.add_argument("--catalogue", type=Path, default=None, help="part catalogue YAML")
    p.add_argument(
        "--nominal",
        action="store_true",
        help="give both methods the part's nominal pose instead of looking with the wrist camera",
    )
    add_config_argument(p)
    add_ideal_argument(p)
    p.set_defaults(func=cmd_compare)


def _stats(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"mean": None, "median": None, "min": None, "max": None}
    return {
        "mean": statistics.fmean(values),
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
    }


def summarize_method(name: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Success k/N with its Wilson interval; tact time and swept volume over the successes."""
    from lab.stats import wilson_interval

    ok = [r for r in rows if r["success"]]
    k, n = len(ok), len(rows)
    lo, hi = wilson_interval(k, n)
    return {
        "method": name,
        "trials": n,
        "successes": k,
        "wilson95": [lo, hi],
        "tact_s": _stats([r["tact_s"] for r in ok if r["tact_s"] is not None]),
        "swept_cm3": _stats([r["swept_cm3"] for r in ok]),
        "per_trial": rows,
    }


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b <= 0 else a / b


def compare(setup: Any, seeds: list[int], progress: bool = True) -> dict[str, Any]:
    """Both methods on every seed; the summary dict ``cell compare --json`` writes."""
    from cell.progress import Progress
    from lab.pivot_run import run_trial
    from lab.regrasp_run import GripperProbe, run_regrasp_trial

    rows: dict[str, list[dict[str, Any]]] = {"pivot": [], "regrasp": []}
    bar = Progress(len(seeds), "seeds", quiet=not progress)
    wall0 = time.perf_counter()
    for i, seed in enumerate(seeds):
        for method, runner in (("pivot", run_trial), ("regrasp", run_regrasp_trial)):
            probe = GripperProbe()
            result = runner(setup, seed, on_frame=probe, frame_every=1)
            row = result.to_json()
            row.update(
                {
                    "tact_s": probe.tact_time if result.success else None,
                    "swept_cm3": probe.sweep.volume_cm3,
                    "swept_voxels": probe.sweep.count,
                }
            )
            rows[method].append(row)
        ok = {m: sum(r["success"] for r in v) for m, v in rows.items()}
        bar.update(i + 1, f"pivot ok {ok['pivot']}  regrasp ok {ok['regrasp']}")
    bar.close()
    pivot = summarize_method("pivot", rows["pivot"])
    regrasp = summarize_method("regrasp", rows["regrasp"])
    ratio_mean = _ratio(pivot["tact_s"]["mean"], regrasp["tact_s"]["mean"])
    ratio_median = _ratio(pivot["tact_s"]["median"], regrasp["tact_s"]["median"])
    return {
        "part": setup.part.name,
        "seeds": seeds,
        "pose_source": "camera" if setup.perceive else "nominal",
        "gripper": setup.gripper.name,
        "ideal": setup.uncertainty.is_ideal,
        "methods": {"pivot": pivot, "regrasp": regrasp},
        "tact_ratio_pivot_over_regrasp": {"mean": ratio_mean, "median": ratio_median},
        "goal_ratio": GOAL_RATIO,
        "goal_met": ratio_mean is not None and ratio_mean <= GOAL_RATIO,
        "swept_ratio_pivot_over_regrasp": _ratio(
            pivot["swept_cm3"]["mean"], regrasp["swept_cm3"]["mean"]
        ),
        "measurement": {
            "tact": "simulated s from the first control step executing a command to the end of "
            "the step where the arm last reported a motion done (the hole grasp's lift); with "
            "pose_source camera the look comes first and counts",
            "swept_volume": "union over control steps of the gripper's collision shapes (FT300 "
            "cylinder, gripper body box, two finger boxes) on a 5 mm world voxel grid, voxel "
            "centres inside; re-sampled when a shape moved 1 mm",
        },
        "physics": setup.physics_json(),
        "wall_time_s": time.perf_counter() - wall0,
    }


def _fmt(x: float | None, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def format_table(summary: dict[str, Any]) -> str:
    lines = [
        f"part {summary['part']}, seeds {summary['seeds'][0]}..{summary['seeds'][-1]} "
        "(same perturbed part for both)",
        f"{'method':<9}{'success':>9}{'tact mean':>11}{'median':>9}{'swept mean':>12}"
        f"{'median':>9}",
        f"{'':<9}{'':>9}{'s':>11}{'s':>9}{'cm^3':>12}{'cm^3':>9}",
    ]
    for name in ("pivot", "regrasp"):
        m = summary["methods"][name]
        lines.append(
            f"{name:<9}{m['successes']:>5}/{m['trials']:<3}"
            f"{_fmt(m['tact_s']['mean'], '.2f'):>11}{_fmt(m['tact_s']['median'], '.2f'):>9}"
            f"{_fmt(m['swept_cm3']['mean'], '.0f'):>12}{_fmt(m['swept_cm3']['median'], '.0f'):>9}"
        )
        fails: dict[str, int] = {}
        for r in m["per_trial"]:
            if not r["success"]:
                key = f"{r['phase']}: {r.get('failure_code') or 'uncoded'}"
                fails[key] = fails.get(key, 0) + 1
        for reason, count in sorted(fails.items(), key=lambda kv: -kv[1]):
            lines.append(f"  failed {count} x {reason}")
    r = summary["tact_ratio_pivot_over_regrasp"]
    if r["mean"] is not None:
        verdict = "met" if summary["goal_met"] else "NOT met"
        lines.append(
            f"tact ratio pivot/regrasp: {r['mean']:.3f} (mean), {r['median']:.3f} (median); "
            f"pivot {100 * (1 - r['mean']):+.1f} % faster; goal <= {summary['goal_ratio']:.2f}: "
            f"{verdict}"
        )
    else:
        lines.append("tact ratio pivot/regrasp: - (a method had no success)")
    sv = summary["swept_ratio_pivot_over_regrasp"]
    lines.append(f"swept volume ratio pivot/regrasp: {_fmt(sv, '.3f')} (mean)")
    return "\n".join(lines)


def cmd_compare(args: argparse.Namespace) -> int:
    from lab.pivot_cmd import PivotInputError, build_setup, pivot_args
    from sim.robot_model import FINGER_TRAVEL
    from skills.pivot import PivotParams

    ns = pivot_args(
        args.part, args.trials, args.catalogue, args.cell, nominal=args.nominal,
        config=args.config, sets=args.set, ideal=getattr(args, "ideal", False),
    )
    try:
        setup, _plan, _forced = build_setup(ns)
    except PivotInputError as exc:
        raise UserError(str(exc)) from None
    gap = PivotParams(l_a=0.5, alpha=0.3, **setup.params).wall_gap
    if setup.part.outer + 2 * gap > 2 * FINGER_TRAVEL:
        raise UserError(
            f"--part: the {setup.part.name}'s {setup.part.outer * 1e3:g} mm outer diameter and "
            f"{gap * 1e3:g} mm a side do not fit the {2e3 * FINGER_TRAVEL:g} mm stroke: no "
            "regrasp pinch"
        )
    seeds = [args.seed + i for i in range(args.trials)]
    summary = compare(setup, seeds)
    if args.json is not None:
        write_json(args.json, summary)
    print(format_table(summary))
    print(f"wall {summary['wall_time_s']:.0f} s" + (f"; wrote {args.json}" if args.json else ""))
    return 0
