"""``cell sweep``: Table-3 sweeps of pivot trials over several parts, run as Ray tasks.

Contract (scripts rely on it)::

    cell sweep --part NAME... --trials N [--workers K] [--address ADDR] --out DIR
        [--config FILE] [--set KEY.PATH=VALUE]...

Why Ray: the same command runs on this machine (a local Ray instance it starts and stops itself,
nothing to set up) and on an existing Ray cluster (``--address``), so a sweep too large for one
box needs no other code. Each trial is one task running
:func:`lab.pivot_run.run_trial` with seed ``S + i`` for trial ``i`` of every part,
exactly as ``cell pivot`` seeds them: a seed fixes a trial, so the sweep's outcomes equal a
serial run's whatever the order the tasks finish in. ``--config`` and ``--set`` apply a cell
configuration to every trial exactly as ``cell pivot`` does
(:func:`lab.pivot_cmd.trial_config`), and each ``per_trial`` entry carries
``cell pivot``'s keys (``grip_force_n``, ``peak_force_n``, ``shove_mm`` included).

Parts the planner declines are not run; they appear in the table as refused, with the reason.
Everything the user gives is checked before Ray starts (unknown part, bad ``--trials``, a cell
layout out of reach, a configuration or ``--set`` that fails validation); an address that cannot
be reached ends with one line naming it, exit 2, after at most :data:`CONNECT_TIMEOUT_S`
seconds.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import os
import socket
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cell.catalogue import load_catalogue
from cell.errors import UserError
from drivers.gripper_spec import default_gripper
from drivers.parts import Gripper
from lab.stats import wilson_interval
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import PivotPlan, plan_pivot

if TYPE_CHECKING:  # the twin (pybullet) is imported only where trials run
    from lab.pivot_run import TrialResult, TrialSetup

#: Longest wait (s) for an existing cluster to answer ``--address``: a TCP probe first (refused,
#: unroutable, unknown host), then Ray's own handshake, which otherwise retries for minutes.
CONNECT_TIMEOUT_S = 30.0


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "sweep",
        help="pivot trials of several parts in parallel on Ray; Table-3-style table and plot",
        description="Run N perturbed pivot trials of each part as Ray tasks (a local Ray "
        "instance by default, an existing cluster with --address) and write a Table-3-style "
        "table (markdown and CSV) beside the paper's rows, the per-trial JSON and a plot of the "
        "success rate against l_a and alpha. Trial i of every part uses seed S+i, as "
        "`cell pivot` does, so the results equal a serial run's.",
    )
    p.add_argument(
        "--part",
        nargs="+",
        action="extend",
        required=True,
        metavar="NAME",
        help="catalogue parts, in table order (--part may also be repeated)",
    )
    p.add_argument(
        "--trials", type=int, required=True, metavar="N", help="trials per part (N >= 1)"
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="K",
        help="trials run at once: the local Ray instance's CPUs (default: all cores), or at "
        "most this many tasks in flight on a cluster (default: as many as it schedules)",
    )
    p.add_argument(
        "--address",
        default=None,
        metavar="ADDR",
        help="an existing Ray cluster's address (host:port of its head, as `ray start --head` "
        "prints); default: start a local Ray instance for this sweep",
    )
    p.add_argument(
        "--seed", type=int, default=0, metavar="S", help="seed of trial 0 of every part (0)"
    )
    p.add_argument(
        "--nominal",
        action="store_true",
        help="give the skills the part's nominal pose instead of looking with the wrist camera",
    )
    p.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="directory for the outputs"
    )
    p.add_argument(
        "--layout",
        "--cell",
        dest="cell",
        type=Path,
        default=None,
        metavar="FILE",
        help="cell layout YAML (default: the default layout)",
    )
    p.add_argument(
        "--catalogue", type=Path, default=None, metavar="FILE", help="part catalogue YAML"
    )
    from lab.pivot_cmd import add_config_argument, add_ideal_argument

    add_config_argument(p)
    add_ideal_argument(p)
    p.set_defaults(func=cmd_sweep)


@dataclass
class PartSweep:
    """One row of the sweep: the plan, the setup (None when refused) and the results so far."""

    name: str
    plan: PivotPlan
    paper: dict[str, Any]
    setup: TrialSetup | None = None
    results: list[TrialResult] = field(default_factory=list)

    @property
    def refused(self) -> bool:
        return self.setup is None


def _pivot_namespace(args: argparse.Namespace, part: str) -> argparse.Namespace:
    from lab.pivot_cmd import pivot_args

    return pivot_args(
        part, args.trials, args.catalogue, args.cell, args.nominal,
        config=getattr(args, "config", None), sets=getattr(args, "set", None) or (),
        ideal=getattr(args, "ideal", False),
    )


def prepare(args: argparse.Namespace) -> list[PartSweep]:
    """Everything checked, nothing simulated, Ray not started: one :class:`PartSweep` per part."""
    from lab.pivot_cmd import PivotInputError, build_setup, trial_config

    if args.trials < 1:
        raise UserError(f"--trials: must be >= 1, got {args.trials}")
    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers: must be >= 1, got {args.workers}")
    if args.address is not None:
        _split_address(args.address)  # its form; whether it answers is for connect_ray
    seen: set[str] = set()
    for name in args.part:
        if name in seen:
            raise UserError(f"--part: {name} is given twice")
        seen.add(name)
    given = trial_config(getattr(args, "config", None), getattr(args, "set", None) or ())
    catalogue = load_catalogue(args.catalogue if args.catalogue is not None else given.catalogue)
    rows: list[PartSweep] = []
    for name in args.part:
        part = catalogue.get(name)  # ValueError naming the catalogue for an unknown part
        plan = plan_pivot(part, Gripper.from_spec(given.gripper or default_gripper()), Frictions())
        row = PartSweep(name=name, plan=plan, paper=dict(part.reference))
        if plan.pivotable:
            try:
                row.setup = build_setup(_pivot_namespace(args, name))[0]
            except PivotInputError as exc:
                raise UserError(str(exc)) from None
        rows.append(row)
    return rows


# --- Ray ---------------------------------------------------------------------------------------


def _trial_task(setup: TrialSetup, seed: int) -> TrialResult:
    """The body of one Ray task; module level so workers import it by name."""
    from lab.pivot_run import run_trial

    return run_trial(setup, seed)


def _split_address(address: str) -> tuple[str, int]:
    """``host:port`` of ``--address``, or a UserError saying what form it must have."""
    if "://" in address:
        scheme = address.split("://", 1)[0]
        if scheme == "ray":
            raise UserError(
                f"--address {address}: the Ray Client (ray://) needs `pip install "
                '"ray[client]"`; give the head\'s GCS address host:port (6379 by default)'
            )
        raise UserError(f"--address {address}: expected host:port, not a {scheme}:// URL")
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UserError(f"--address {address}: expected host:port, e.g. 10.0.0.5:6379")
    return host.strip("[]"), int(port)


def _probe(address: str, timeout: float) -> None:
    """Fail fast on a refused port, an unknown host or no route, before Ray's long retries."""
    host, port = _split_address(address)
    try:
        with socket.create_connection((host, port), timeout=min(timeout, 10.0)):
            pass
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        if isinstance(exc, TimeoutError | socket.timeout):
            why = f"no answer within {min(timeout, 10.0):g} s"
        raise UserError(f"--address {address}: cannot reach a Ray cluster there: {why}") from None


def connect_ray(address: str | None, workers: int | None, timeout: float | None = None) -> bool:
    """Start a local Ray instance, or connect to the cluster at ``address``.

    Returns whether this call started (and so must shut down) Ray. A local instance gets
    ``workers`` CPUs (one trial each), no dashboard and no worker logs on the terminal: the
    sweep prints its own progress. ``address="local"`` makes Ray start a fresh instance even
    when another one runs on this machine (this box is shared) or RAY_ADDRESS is set.
    """
    import ray

    if ray.is_initialized():  # called from a program that already set Ray up
        return False
    if address is None:
        ray.init(
            address="local",
            num_cpus=workers if workers is not None else os.cpu_count(),
            include_dashboard=False,
            log_to_driver=False,
            logging_level="error",
        )
        return True
    limit = CONNECT_TIMEOUT_S if timeout is None else timeout
    _probe(address, limit)
    failure: list[BaseException] = []

    def _init() -> None:
        try:
            ray.init(address=address, log_to_driver=False, logging_level="error")
        except BaseException as exc:  # handed to the waiting thread, reported there
            failure.append(exc)

    # ray.init has no timeout of its own; waiting in a daemon thread bounds it.
    thread = threading.Thread(target=_init, name="ray-connect", daemon=True)
    thread.start()
    thread.join(limit)
    if thread.is_alive():
        raise UserError(f"--address {address}: no Ray cluster answered within {limit:g} s")
    if failure:
        first = str(failure[0]).strip().splitlines()
        why = first[0] if first else type(failure[0]).__name__
        if "RAY_AUTH_MODE" not in os.environ:
            # Ray >= 2.5x clusters started by `ray start` demand a token, but a driver given an
            # explicit address only sends one when asked to; the refusal does not say so.
            why += " (if the cluster uses token authentication: set RAY_AUTH_MODE=token)"
        raise UserError(f"--address {address}: cannot connect to a Ray cluster there: {why}")
    return True


def run_sweep(
    rows: list[PartSweep],
    trials: int,
    seed: int,
    workers: int | None,
    progress: Any = sys.stderr,
) -> float:
    """Submit every trial as a Ray task and collect the results as they arrive.

    At most ``workers`` tasks are in flight (``None``: all of them, and the cluster's scheduler
    decides). Each part's results end sorted by seed. Returns the wall time in seconds.
    """
    import ray

    remote = ray.remote(num_cpus=1, max_retries=0)(_trial_task)
    setups = {row.name: ray.put(row.setup) for row in rows if row.setup is not None}
    pending_jobs = [
        (row, setups[row.name], seed + i)
        for row in rows
        if row.setup is not None
        for i in range(trials)
    ]
    # Interleave the parts so every row fills up from the start (progress reads per part).
    pending_jobs.sort(key=lambda job: job[2])
    total = len(pending_jobs)
    limit = total if workers is None else workers
    in_flight: dict[Any, tuple[PartSweep, int]] = {}
    done = 0
    wall0 = time.perf_counter()
    queue = list(reversed(pending_jobs))
    while queue or in_flight:
        while queue and len(in_flight) < limit:
            row, ref_setup, s = queue.pop()
            in_flight[remote.remote(ref_setup, s)] = (row, s)
        ready, _ = ray.wait(list(in_flight), num_returns=1)
        for ref in ready:
            row, s = in_flight.pop(ref)
            result: TrialResult = ray.get(ref)
            row.results.append(result)
            done += 1
            ok = sum(r.success for r in row.results)
            verdict = "ok" if result.success else f"FAILED ({result.failure})"
            progress.write(
                f"[{done:>{len(str(total))}}/{total}] {row.name} seed {s}: {verdict}, "
                f"{result.wall_time:.1f} s; {row.name} {ok}/{len(row.results)}, "
                f"{time.perf_counter() - wall0:.0f} s elapsed\n"
            )
            progress.flush()
    for row in rows:
        row.results.sort(key=lambda r: r.seed)
    return time.perf_counter() - wall0


# --- outputs -----------------------------------------------------------------------------------


def _paper_success(text: Any) -> tuple[int, int] | None:
    """``"9/10"`` -> (9, 10); None when the catalogue has no such entry."""
    try:
        k, n = (int(x) for x in str(text).split("/"))
    except ValueError:
        return None
    return (k, n) if 0 <= k <= n and n > 0 else None


def _paper_la(text: Any) -> tuple[float, float] | None:
    """The paper's l_a as (at the grasp, after sliding): ``"0.9->0.65"`` -> (0.9, 0.65)."""
    try:
        values = [float(x) for x in str(text).split("->")]
    except ValueError:
        return None
    return (values[0], values[-1]) if values else None


def _fmt(value: float | None, spec: str) -> str:
    return "" if value is None else format(value, spec)


def table_rows(rows: list[PartSweep], trials: int) -> list[dict[str, Any]]:
    """One flat record per part: the CSV's columns, which the markdown table formats."""
    out = []
    for row in rows:
        plan = row.plan
        k = sum(r.success for r in row.results)
        n = len(row.results)
        lo, hi = wilson_interval(k, n) if n else (None, None)
        paper_k = _paper_success(row.paper.get("success"))
        p_lo, p_hi = wilson_interval(*paper_k) if paper_k else (None, None)
        alpha_p = row.paper.get("alpha_rad")
        out.append(
            {
                "part": row.name,
                "status": "refused" if row.refused else "run",
                "reason": plan.reason if row.refused else "",
                "l_a": plan.l_a,
                "alpha_deg": None if plan.alpha is None else math.degrees(plan.alpha),
                "delta_mm": None if plan.delta_m is None else plan.delta_m * 1e3,
                "successes": k if n else None,
                "trials": n if n else None,
                "rate": k / n if n else None,
                "wilson_lo": lo,
                "wilson_hi": hi,
                "failures": _failure_counts(row.results),
                "paper_l_a": row.paper.get("l_a", ""),
                "paper_alpha_deg": None if alpha_p is None else math.degrees(float(alpha_p)),
                "paper_delta_mm": row.paper.get("delta_mm"),
                "paper_success": row.paper.get("success", ""),
                "paper_wilson_lo": p_lo,
                "paper_wilson_hi": p_hi,
            }
        )
    return out


def _failure_counts(results: list[TrialResult]) -> str:
    counts: dict[str, int] = {}
    for r in results:
        if not r.success and r.failure:
            key = r.failure_key
            counts[key] = counts.get(key, 0) + 1
    return "; ".join(f"{c} x {why}" for why, c in sorted(counts.items(), key=lambda kv: -kv[1]))


def write_csv(path: Path, records: list[dict[str, Any]]) -> None:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(records[0]), lineterminator="\n")
    writer.writeheader()
    for rec in records:
        writer.writerow({k: ("" if v is None else v) for k, v in rec.items()})
    path.write_text(buf.getvalue(), encoding="utf-8")


def markdown_table(records: list[dict[str, Any]], header: str) -> str:
    """Table 3's columns (l_a, alpha, delta, success, 95 % CI) for the twin, then the paper's."""
    lines = [
        header,
        "",
        "| part | l_a | alpha [deg] | delta [mm] | success | Wilson 95 % | failures "
        "| paper: l_a | alpha [deg] | delta [mm] | success | Wilson 95 % |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in records:
        paper = (
            f"| {r['paper_l_a']} | {_fmt(r['paper_alpha_deg'], '.1f')} "
            f"| {_fmt(r['paper_delta_mm'], 'g')} | {r['paper_success']} | "
            + (
                f"{100 * r['paper_wilson_lo']:.0f}-{100 * r['paper_wilson_hi']:.0f} % |"
                if r["paper_wilson_lo"] is not None
                else " |"
            )
        )
        if r["status"] == "refused":
            lines.append(
                f"| {r['part']} | refused by the planner: {r['reason']} (not run) | | | | | "
                + paper
            )
            continue
        lines.append(
            f"| {r['part']} | {r['l_a']:.2f} | {r['alpha_deg']:.1f} | {r['delta_mm']:.1f} "
            f"| {r['successes']}/{r['trials']} "
            f"| {100 * r['wilson_lo']:.0f}-{100 * r['wilson_hi']:.0f} % "
            f"| {r['failures'] or '-'} " + paper
        )
    return "\n".join(lines) + "\n"


def spread(xs: list[float], step: float) -> list[float]:
    """Positions at least ``step`` apart, each group of crowded points centred on its own mean
    and kept in order: equal values (bushing and bottle share a plan, many rates are 100 %)
    stay visible side by side, and nothing moves further than its group needs."""
    order = sorted(range(len(xs)), key=lambda i: xs[i])
    groups = [[i] for i in order]

    def place(group: list[int]) -> list[float]:
        centre = sum(xs[i] for i in group) / len(group)
        return [centre + (k - 0.5 * (len(group) - 1)) * step for k in range(len(group))]

    merged = True
    while merged:
        merged = False
        for g in range(len(groups) - 1):
            if place(groups[g])[-1] + step > place(groups[g + 1])[0] + 1e-12:
                groups[g : g + 2] = [groups[g] + groups[g + 1]]
                merged = True
                break
    out = [0.0] * len(xs)
    for group in groups:
        for i, x in zip(group, place(group), strict=True):
            out[i] = x
    return out


def plot_success(path: Path, records: list[dict[str, Any]], title: str) -> Path:
    """Success rate (Wilson 95 % bars) against l_a and against alpha, one point per part, the
    paper's measurements as open markers (its l_a slid during the tilt for three parts: drawn as
    an arrow from the grasp value to the final one)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(1, 2, figsize=(11.5, 5.0), dpi=120, sharey=True)
    colors = plt.get_cmap("tab10")(np.arange(len(records)) % 10)
    markers = "osD^vPXh<>p"
    handles = []
    # (panel, x, x_end, rate %, lo %, hi %, part index, paper?) for every point to draw
    points: dict[str, list[tuple[float, float, float, float, float, int, bool]]] = {
        "l_a": [],
        "alpha_deg": [],
    }
    for i, r in enumerate(records):
        label = r["part"] + ("  (refused: not run)" if r["status"] == "refused" else "")
        handles.append(
            plt.Line2D([], [], color=colors[i], marker=markers[i % len(markers)], ls="", ms=7,
                       label=label)
        )  # fmt: skip
        if r["status"] == "run":
            bar = (100 * r["rate"], 100 * r["wilson_lo"], 100 * r["wilson_hi"])
            points["l_a"].append((r["l_a"], r["l_a"], *bar, i, False))
            points["alpha_deg"].append((r["alpha_deg"], r["alpha_deg"], *bar, i, False))
        paper_k = _paper_success(r["paper_success"])
        if paper_k is None:
            continue
        bar = (
            100 * paper_k[0] / paper_k[1],
            100 * r["paper_wilson_lo"],
            100 * r["paper_wilson_hi"],
        )
        la = _paper_la(r["paper_l_a"])
        if la is not None:
            points["l_a"].append((la[0], la[1], *bar, i, True))
        if r["paper_alpha_deg"] is not None:
            alpha = r["paper_alpha_deg"]
            points["alpha_deg"].append((alpha, alpha, *bar, i, True))
    moved = {}
    for ax, key, step in ((axes[0], "l_a", 0.02), (axes[1], "alpha_deg", 1.1)):
        pts = points[key]
        xs = spread([p[0] for p in pts], step)
        moved[key] = max((abs(x - p[0]) for x, p in zip(xs, pts, strict=True)), default=0.0)
        for x, (x0, x_end, y, lo, hi, i, paper) in zip(xs, pts, strict=True):
            col, mk = colors[i], markers[i % len(markers)]
            style = (
                {"ms": 8, "mfc": "white", "mew": 1.6, "capsize": 3, "lw": 0.9, "alpha": 0.85}
                if paper
                else {"ms": 7, "capsize": 4, "lw": 1.8}
            )
            ax.errorbar(
                x, y, yerr=[[y - lo], [hi - y]], color=col, marker=mk, ls="",
                zorder=4 if paper else 3, **style,
            )  # fmt: skip
            if x_end != x0:
                ax.annotate(
                    "", xy=(x_end + x - x0, y), xytext=(x, y),
                    arrowprops={"arrowstyle": "->", "color": col, "lw": 1.2, "alpha": 0.85},
                )  # fmt: skip
    axes[0].set_xlabel("$l_a$ (grasp distance / part length)")
    axes[1].set_xlabel(r"$\alpha$ gripper tilt [deg]")
    axes[0].set_ylabel("success rate [%]  (bars: Wilson 95 %)")
    axes[0].set_xlim(0.15, 1.0)
    axes[1].set_xlim(0, 55)
    for ax in axes:
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.25)
    kinds = [
        plt.Line2D([], [], color="0.3", marker="o", ls="", ms=7, label="twin (this sweep)"),
        plt.Line2D(
            [], [], color="0.3", marker="o", mfc="white", ls="", ms=8, label="paper (real arm)"
        ),
        plt.Line2D([], [], color="0.3", lw=1.2, label="paper: $l_a$ slid from -> to"),
    ]
    fig.legend(
        handles=handles + kinds,
        loc="center left",
        bbox_to_anchor=(0.80, 0.5),
        fontsize=8,
        framealpha=0.9,
    )
    fig.text(
        0.01,
        0.01,
        "Crowded points are set apart sideways so that equal values stay visible (by at most "
        f"{moved['l_a']:.3f} in $l_a$ and {moved['alpha_deg']:.1f} deg in alpha here).",
        fontsize=7,
        color="0.35",
    )
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0.0, 0.03, 0.80, 1.0))
    fig.savefig(path)
    plt.close(fig)
    return path


def write_outputs(
    out: Path,
    rows: list[PartSweep],
    args: argparse.Namespace,
    wall: float,
    cluster: str,
) -> list[Path]:
    """table.md, table.csv, sweep.json and success.png in ``out``."""
    records = table_rows(rows, args.trials)
    pose = "nominal pose" if args.nominal else "wrist camera"
    ideal = bool(getattr(args, "ideal", False))
    drawn = (
        "frictions 0.2/0.4/0.4 +-20 % (--ideal)" if ideal
        else "the cell's uncertainty drawn per trial (sim/uncertainty.py)"
    )
    header = (
        f"Sweep: {args.trials} trials per part, seeds {args.seed}..{args.seed + args.trials - 1}, "
        f"{pose}, {drawn}; {cluster}; {wall:.0f} s wall. "
        "Paper: Table 3 (real arm, 10 trials); its Wilson interval computed from k/N."
    )
    payload = {
        "trials": args.trials,
        "seed": args.seed,
        "pose_source": pose,
        "ideal": ideal,
        "ray": cluster,
        "wall_time_s": wall,
        "parts": [
            {
                "part": row.name,
                "status": "refused" if row.refused else "run",
                "reason": row.plan.reason if row.refused else None,
                "plan": row.plan.to_json(),
                "paper": row.paper,
                "successes": sum(r.success for r in row.results),
                "trials": len(row.results),
                "wilson95": list(wilson_interval(sum(r.success for r in row.results),
                                                 len(row.results)))
                if row.results else None,
                "per_trial": [r.to_json() for r in row.results],
            }
            for row in rows
        ],
    }  # fmt: skip
    paths = [out / "table.md", out / "table.csv", out / "sweep.json", out / "success.png"]
    try:
        out.mkdir(parents=True, exist_ok=True)
        paths[0].write_text(markdown_table(records, header), encoding="utf-8")
        write_csv(paths[1], records)
        paths[2].write_text(json.dumps(payload, indent=1) + "\n", encoding="utf-8")
        plot_success(
            paths[3],
            records,
            f"Pivot success in the twin ({args.trials} trials per part, {pose}) "
            "beside the paper's Table 3",
        )
    except OSError as exc:
        raise UserError(f"--out {out}: cannot write: {exc.strerror or exc}") from None
    return paths


def cmd_sweep(args: argparse.Namespace) -> int:
    from cell.extras import require

    require("ray", "cell sweep")
    rows = prepare(args)
    if not os.access(args.out if args.out.exists() else _existing_parent(args.out), os.W_OK):
        raise UserError(f"--out {args.out}: not writable")
    for row in rows:
        if row.refused:
            print(f"{row.name}: refused by the planner, not run: {row.plan.reason}")
    runnable = [row for row in rows if not row.refused]
    wall = 0.0
    cluster = "no trials run"
    if runnable:
        import ray

        started = connect_ray(args.address, args.workers)
        try:
            cpus = int(ray.cluster_resources().get("CPU", 0))
            where = "local Ray instance" if args.address is None else f"Ray cluster {args.address}"
            cluster = f"{where}, {cpus} CPUs"
            print(
                f"{cluster}: {len(runnable) * args.trials} trials of {len(runnable)} "
                + ("part" if len(runnable) == 1 else "parts"),
                flush=True,
            )
            wall = run_sweep(rows, args.trials, args.seed, args.workers)
        finally:
            if started:
                ray.shutdown()
    paths = write_outputs(args.out, rows, args, wall, cluster)
    for rec in table_rows(rows, args.trials):
        if rec["status"] == "run":
            print(
                f"{rec['part']:<16} {rec['successes']}/{rec['trials']}  Wilson 95 % "
                f"{100 * rec['wilson_lo']:.0f}-{100 * rec['wilson_hi']:.0f} %  "
                f"(paper {rec['paper_success'] or '-'})"
            )
    print(f"wall time {wall:.0f} s; wrote " + ", ".join(str(p) for p in paths))
    return 0


def _existing_parent(path: Path) -> Path:
    for parent in [path, *path.parents]:
        if parent.exists():
            return parent
    return Path(".")
