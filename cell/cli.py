"""The ``cell`` command line.

User errors (bad values, unknown parts, malformed files) print one line naming the value, file
and key, and exit with status 2 -- never a traceback. Programming errors still raise.

Contract forms (scripts rely on them; keep them exactly):

* ``cell analyze [--part NAME] --la 0.3 0.5 0.7 0.9 --mu-s 0.2 --mu-h 0.4 --mu-g 0.4
  --grid 91 --out DIR [--json FILE]``
* ``cell plan --part NAME [--json FILE]``
* ``cell pivot --part NAME --trials N --seed S [--mu-ground X] [--record FILE.gif] --json FILE``
* ``cell sim --config FILE --cycles N --seed S [--record FILE.gif] --json FILE``
* ``cell run --config FILE``, ``cell tree --config FILE``, ``cell replay LOG``
* ``cell calibrate [--cell FILE] [--views N] [--seed S] [--true-xyz X Y Z] [--true-rpy R P Y]``
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import traceback
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from cell.catalogue import Catalogue, load_catalogue
from cell.errors import UserError
from cell.output import write_json
from cell.preflight import check_outputs
from drivers.parts import Gripper
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import PivotPlan, PlannerOptions, plan_pivot
from skills.mechanics.region import (
    HALF_PI,
    alpha_axis,
    beta_axis,
    check_tilt,
    min_alpha_for_tilt,
    region_map,
)

DEFAULT_LA = [0.3, 0.5, 0.7, 0.9]


def _deg(x: float | None) -> str:
    return "-" if x is None else f"{math.degrees(x):.1f}"


def _add_physics_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--mu-s", type=float, default=0.2, help="friction at S, finger on top (0.2)")
    p.add_argument("--mu-h", type=float, default=0.4, help="friction at H, finger in hole (0.4)")
    p.add_argument("--mu-g", type=float, default=0.4, help="friction at G, part on ground (0.4)")
    p.add_argument(
        "--catalogue", type=Path, default=None, help="part catalogue YAML (default: shipped one)"
    )
    p.add_argument(
        "--finger-width",
        type=float,
        default=Gripper.finger_width,
        help="finger pad width w in m (default 0.020)",
    )
    p.add_argument(
        "--equation",
        choices=("auto", "eq7", "eq8"),
        default="auto",
        help="force balance: auto = Eq. 7 when all frictions are 0 (as the paper), else Eq. 8",
    )


def _frictions(args: argparse.Namespace) -> Frictions:
    return Frictions(mu_s=args.mu_s, mu_h=args.mu_h, mu_g=args.mu_g)


def cmd_analyze(args: argparse.Namespace) -> int:
    if not 2 <= args.grid <= 2001:
        raise UserError(f"--grid must lie in [2, 2001], got {args.grid}")
    catalogue = load_catalogue(args.catalogue)
    part = catalogue.get(args.part)
    frictions = _frictions(args)
    gripper = Gripper(finger_width=args.finger_width)
    section = part.section(gripper.finger_width)
    la = np.asarray(args.la, dtype=float)
    alphas, betas = alpha_axis(args.grid), beta_axis(args.grid)
    stable = region_map(section, la, alphas, betas, frictions, args.equation)
    from skills.mechanics.balance import resolve_equation

    equation = resolve_equation(args.equation, frictions)

    from cell.figures import plot_region_map

    tag = f"muS{args.mu_s:g}_muH{args.mu_h:g}_muG{args.mu_g:g}"
    try:
        png = plot_region_map(
            args.out / f"region_{part.name}_{tag}.png",
            part.name,
            section,
            la,
            alphas,
            betas,
            stable,
            frictions,
            equation,
        )
    except OSError as exc:
        raise UserError(f"--out {args.out}: cannot write the picture: {exc.strerror}") from None
    print(
        f"{part.name}: a = {section.a * 1e3:.1f} mm, b = {section.b * 1e3:.1f} mm, "
        f"delta = {section.delta * 1e3:.2f} mm (w = {gripper.finger_width * 1e3:.1f} mm); "
        f"{equation}; mu_S={args.mu_s:g} mu_H={args.mu_h:g} mu_G={args.mu_g:g}; "
        f"grid {args.grid}x{args.grid}"
    )
    print(
        f"{'l_a':>5} {'stable pts':>10} {'min alpha @beta=0':>18} "
        f"{'min alpha tilt->CoM over G':>27} {'min alpha tilt->90':>19}  [deg]"
    )
    for k, value in enumerate(la):
        at_zero = alphas[stable[k, :, 0]]
        to_tip = min_alpha_for_tilt(
            section, float(value), frictions, section.tip_angle, args.equation
        )
        to_top = min_alpha_for_tilt(section, float(value), frictions, HALF_PI, args.equation)
        print(
            f"{value:5.2f} {int(stable[k].sum()):10d} "
            f"{_deg(float(at_zero[0]) if at_zero.size else None):>18} "
            f"{_deg(to_tip):>27} {_deg(to_top):>19}"
        )
    print(f"wrote {png}")
    if args.json is not None:
        write_json(
            args.json,
            {
                "part": part.name,
                "l_a": la.tolist(),
                "alpha": alphas.tolist(),
                "beta": betas.tolist(),
                "stable": stable.tolist(),
                "equation": equation,
                "mu": {"S": args.mu_s, "H": args.mu_h, "G": args.mu_g},
            },
        )
        print(f"wrote {args.json}")
    return 0


def _format_plan(plan: PivotPlan) -> str:
    lines = [f"part          {plan.part}"]
    if not plan.pivotable:
        lines.append(f"verdict       NOT pivotable: {plan.reason}")
        if plan.delta_m is not None:
            lines.append(f"delta         {plan.delta_m * 1e3:.2f} mm")
        return "\n".join(lines)
    assert plan.alpha is not None and plan.delta_m is not None and plan.opening_m is not None
    assert plan.reach_m is not None
    ub = plan.beta_ub
    lines += [
        "verdict       pivotable",
        f"l_a           {plan.l_a:.2f}   "
        f"(S is {plan.l_a * 100:.0f} % of the length from the open end)",
        f"alpha         {plan.alpha:.4f} rad ({math.degrees(plan.alpha):.2f} deg; "
        f"{_deg(plan.alpha_min)} deg + margin; hooking the hole needs >= "
        f"{_deg(plan.alpha_hook)} deg)",
        f"delta         {plan.delta_m * 1e3:.2f} mm",
        f"reach past H  {plan.reach_m * 1e3:.1f} mm (the inner finger, along it)",
        f"stable beta   0 .. {_deg(plan.beta_stable_max)} deg"
        + (f"  (beta_ub {_deg(ub)} deg)" if ub is not None else "  (whole tilt)"),
        f"required      0 .. {_deg(plan.beta_required)} deg",
        f"jaw opening   {plan.opening_m * 1e3:.1f} mm + {plan.gripper.clearance * 1e3:.0f} mm "
        f"clearance of {plan.gripper.stroke * 1e3:.0f} mm stroke",
    ]
    return "\n".join(lines)


def cmd_plan(args: argparse.Namespace) -> int:
    catalogue: Catalogue = load_catalogue(args.catalogue)
    if args.all == (args.part is not None):
        raise UserError("give exactly one of --part NAME or --all")
    names = list(catalogue.parts) if args.all else [args.part]
    gripper = Gripper(
        finger_width=args.finger_width,
        stroke=args.stroke,
        clearance=args.clearance,
        finger_length=args.finger_length,
    )
    options = PlannerOptions(
        la_max=args.la_max,
        full_tilt=args.full_tilt,
        equation=args.equation,
        hook_depth=args.hook_depth,
        hold_share=args.hold_share,
        side_room=args.side_room,
    )
    frictions = _frictions(args)
    plans = [plan_pivot(catalogue.get(n), gripper, frictions, options) for n in names]
    print("\n\n".join(_format_plan(p) for p in plans))
    if args.json is not None:
        payload: Any = (
            plans[0].to_json() if not args.all else {"plans": [p.to_json() for p in plans]}
        )
        write_json(args.json, payload)
        print(f"wrote {args.json}")
    return 0


def cmd_check_tilt(args: argparse.Namespace) -> int:
    catalogue = load_catalogue(args.catalogue)
    part = catalogue.get(args.part)
    section = part.section(args.finger_width)
    required = HALF_PI if args.to == "top" else section.tip_angle
    result = check_tilt(section, args.la, args.alpha, _frictions(args), required, args.equation)
    verdict = "ok" if result.ok else "FAILS"
    print(
        f"{part.name}: l_a={args.la:g}, alpha={args.alpha:g} rad ({math.degrees(args.alpha):.1f}"
        f" deg): stable for beta 0 .. {_deg(result.beta_stable_max)} deg; required "
        f"0 .. {_deg(required)} deg: {verdict}"
    )
    return 0 if result.ok else 1


def version() -> str:
    """The installed distribution's version (the source tree's when run uninstalled)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("pivot-cell")
    except PackageNotFoundError:
        return "0.1.0 (not installed)"


#: The entry-point group through which packages above the cell (the lab: trials, sweeps,
#: evaluations) add their subcommands to ``cell``: the cell never imports them.
PLUGIN_GROUP = "pivot_cell.commands"


def _add_plugins(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Subcommands of the installed plugins (pyproject.toml's ``[project.entry-points]``)."""
    from importlib.metadata import entry_points

    for ep in sorted(entry_points(group=PLUGIN_GROUP), key=lambda e: e.name):
        ep.load()(sub)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cell",
        description="pivot-cell: hole grasps of hollow parts by asymmetric pivot manipulation.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "analyze",
        help="stable-grasp regions in the (alpha, beta) plane (Fig. 5)",
        description="Map the stable (alpha, beta) set of a part for several l_a, write a "
        "Fig.-5-style PNG and, with --json, the boolean map indexed [l_a][alpha][beta].",
    )
    p.add_argument("--part", default="bushing", help="part name from the catalogue (bushing)")
    p.add_argument(
        "--la",
        type=float,
        nargs="+",
        default=DEFAULT_LA,
        metavar="L_A",
        help="values of l_a = l/(2a) in (0, 1] (default 0.3 0.5 0.7 0.9)",
    )
    p.add_argument("--grid", type=int, default=91, help="points per axis (default 91)")
    p.add_argument("--out", type=Path, default=Path("out"), help="directory for the PNG (out)")
    p.add_argument("--json", type=Path, default=None, help="also write the map as JSON here")
    _add_physics_options(p)
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser(
        "plan",
        help="choose l_a and alpha for a part, or say why it cannot be pivoted",
        description="Per-part pivot plan: the largest l_a the stroke allows and the smallest "
        "alpha whose Tilt stays in force balance.",
    )
    p.add_argument("--part", default=None, help="part name from the catalogue")
    p.add_argument("--all", action="store_true", help="plan every part of the catalogue")
    p.add_argument("--json", type=Path, default=None, help="also write the plan as JSON here")
    p.add_argument("--stroke", type=float, default=Gripper.stroke, help="gripper stroke, m (0.085)")
    p.add_argument(
        "--clearance",
        type=float,
        default=Gripper.clearance,
        help="extra jaw opening for the approach, m (0.010)",
    )
    p.add_argument(
        "--finger-length",
        type=float,
        default=Gripper.finger_length,
        help="how far the pads reach below the palm, m (0.055): bounds the hook depth",
    )
    p.add_argument(
        "--la-max",
        type=float,
        default=PlannerOptions.la_max,
        help="largest l_a to consider (0.9, the paper's largest)",
    )
    p.add_argument(
        "--hook-depth",
        type=float,
        default=PlannerOptions.hook_depth,
        help="how far the inner finger's tip must reach behind the rim, m (0.005)",
    )
    p.add_argument(
        "--hold-share",
        type=float,
        default=PlannerOptions.hold_share,
        help="how far the inner finger must reach past the rim contact H to keep the part "
        "through Align, as a share of the hole's free room (0.4)",
    )
    p.add_argument(
        "--side-room",
        type=float,
        default=PlannerOptions.side_room,
        help="room the pad needs on either side in the hole, m: for the pose's error across "
        "the part and the pad's turn in the hole (0.0015)",
    )
    p.add_argument(
        "--full-tilt",
        action="store_true",
        help="require balance up to beta = 90 deg, not only until the CoM is over G",
    )
    _add_physics_options(p)
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser(
        "check-tilt",
        help="path check of a given (l_a, alpha) along the Tilt",
        description="Exit 0 when the Tilt at (l_a, alpha) stays in force balance over the "
        "required range of beta, 1 when it does not.",
    )
    p.add_argument("--part", default="bushing", help="part name from the catalogue (bushing)")
    p.add_argument("--la", type=float, required=True, help="l_a in (0, 1]")
    p.add_argument("--alpha", type=float, required=True, help="gripper tilt alpha in rad")
    p.add_argument(
        "--to",
        choices=("tip", "top"),
        default="tip",
        help="required range: until the CoM is over G (tip) or to 90 deg (top)",
    )
    _add_physics_options(p)
    p.set_defaults(func=cmd_check_tilt)

    from cell.cell_cmds import add_parser as add_cell

    add_cell(sub)

    from cell.init_cmd import add_parser as add_init

    add_init(sub)

    _add_plugins(sub)

    from cell.help import finish_parser

    finish_parser(parser, sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # for "resume with: ..." hints
    try:
        check_outputs(args.command, args)
        return int(args.func(args))
    except (UserError, ValueError) as exc:
        # One line, whatever the message: a user error never spreads over the terminal.
        text = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        print(f"cell {args.command}: error: {text}", file=sys.stderr)
        return 2
    except OSError as exc:
        if exc.filename is None:  # not a file: a device's link, which has its own reporting
            raise
        # A file that passed the up-front check and still could not be written (a disk filled,
        # a folder removed meanwhile): one line, as a bad input is.
        print(f"cell {args.command}: error: {exc.filename}: cannot write: "
              f"{exc.strerror or type(exc).__name__}", file=sys.stderr)
        return 2


def entry() -> None:
    """The ``cell`` console script: :func:`main`, then the process's end.

    A run that lost the arm's link abandoned its ur_rtde interfaces rather than wait seconds in
    their disconnect (see :func:`drivers.ur5.rtde_adapter.links_abandoned`); everything the run
    owes (state, journal, log, summary) is written by the time :func:`main` returns, so the
    process then ends at once with the same status, its output flushed."""
    try:
        code = main()
    except BaseException as exc:
        if not _links_abandoned():
            raise
        # Even so the destructors must not run: say what happened, then end as planned.
        if isinstance(exc, SystemExit):
            code = exc.code if isinstance(exc.code, int) else 1
        else:
            traceback.print_exc()
            code = 130 if isinstance(exc, KeyboardInterrupt) else 1
    end_process(code)


def _links_abandoned() -> bool:
    adapter = sys.modules.get("drivers.ur5.rtde_adapter")
    return adapter is not None and bool(adapter.links_abandoned())


def end_process(code: int) -> NoReturn:
    """Exit with ``code``; at once, without destructors, where an arm's link was abandoned."""
    if _links_abandoned():
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    entry()
