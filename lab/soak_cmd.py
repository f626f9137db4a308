"""`cell soak`: the configured cell in the twin, with faults, for many cycles.

Contract form (scripts rely on it; keep it exactly)::

    cell soak [--config FILE] --cycles N --faults default|none --seed S --json FILE

Why: a production cell runs for days; the soak measures how the tree handles faults over many
cycles, and whether any part is ever lost track of. It runs the tree of ``cell sim`` (the same
:func:`cell.assemble.prepare` / :func:`cell.assemble.open_backend` / :class:`cell.runner.TickLoop`)
in runs of at most the free box places, and between runs plays the person at the cell:

* the bin is empty: tip in ``bin.parts`` new parts, as ``bin.fill`` says;
* the box is full, holds a part the tree did not record, or blocked a packing: ship it (its
  parts are counted as ``shipped``) and put in an empty one;
* after every run: take out the parts in the hand, in the slot and on the floor (recorded in
  ``removed_by_operator`` by where they were, never moved into the box), open the jaws and jog
  the arm home, clear every pending fault (a reset);
* the bin still holds parts the tree gave up on: take them out (``removed_by_operator.in_bin``)
  and refill.

An exception escaping the tree is caught, counted with its traceback, the world's parts are
accounted where they are, and the soak goes on with a fresh twin. Every part's place comes from
the simulated state (:meth:`sim.cell_twin.SimCellBackend.account`); ``unaccounted`` is the parts
spawned less those found anywhere (in a twin, removed by the person, or shipped).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import traceback
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cell.errors import UserError
from cell.output import report_config_error, write_json
from drivers.events import EventKind, SlotState, StopKind
from skills.status import Failure
from trees.yaml_lines import ConfigError

PLACES = ("in_bin", "in_hand", "in_slot", "packed", "on_floor")
#: Seed distance between shards of a ``--workers`` soak: far beyond the seeds one shard draws
#: (scene seed + 1000 per twin + 7 per refill; fault seed + 7919 per twin).
SHARD_SEED_STEP = 10_000_019


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "soak",
        help="run the cell in the twin with injected faults for many cycles",
        description="Runs the configured cell in the twin with faults (sim/faults.py) for N "
        "cycles, refilling the bin, shipping full boxes and, when the cell stops for a person, "
        "playing the person (clear what is lost, reset, go on). Writes where every part ended, "
        "the aborts by reason and any exception that escaped the tree.",
    )
    p.add_argument("--config", type=Path, default=None, help="cell configuration YAML")
    p.add_argument("--cycles", type=int, required=True, help="cycles to attempt")
    p.add_argument(
        "--faults",
        choices=("default", "none"),
        default=None,
        help="default: the documented default rates; none: no faults (default: the "
        "configuration's `faults` section)",
    )
    p.add_argument(
        "--seed", type=int, default=None, help="seed of the bin scenes and the faults"
    )
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.add_argument(
        "--workers",
        type=int,
        default=1,
        help="split the cycles into this many shards, each its own cell (twin) in its own "
        f"process; shard k seeds its scenes and faults with S + {SHARD_SEED_STEP}*k, so shard 0 "
        "is the serial run (default: 1)",
    )
    p.add_argument(
        "--fill",
        choices=("rows", "random"),
        default=None,
        help="how the bin is filled and refilled (bin.fill; default: the configuration's)",
    )
    p.add_argument(
        "--parts", type=int, default=None,
        help="parts tipped in at each refill (bin.parts; default: the configuration's)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    from cell.overrides import add_set_argument

    add_set_argument(p)
    p.set_defaults(func=cmd_soak)


def cmd_soak(args: argparse.Namespace) -> int:
    from cell.cell_cmds import load_prepared
    from sim.faults import DEFAULT_RATES, no_faults

    if args.cycles < 1:
        raise UserError(f"--cycles: must be >= 1, got {args.cycles}")
    if args.seed is not None and args.seed < 0:
        raise UserError(f"--seed: must be >= 0, got {args.seed}")
    if args.parts is not None and args.parts < 1:
        raise UserError(f"--parts: must be >= 1, got {args.parts}")
    # --fill / --parts are the bin keys set from the command line (shards get them too)
    args.set = [*(args.set or ())]
    if args.fill is not None:
        args.set.append(f"bin.fill={args.fill}")
    if args.parts is not None:
        args.set.append(f"bin.parts={args.parts}")
    try:
        prep = load_prepared(args.config, args.set)
    except ConfigError as exc:
        return report_config_error(exc, "soak")
    config = prep.config
    if config.cell.backend != "sim":
        raise UserError(
            f"{prep.doc.source}: cell.backend is {config.cell.backend!r}; `cell soak` runs the "
            "twin only"
        )
    if args.faults == "default":
        rates = dict(DEFAULT_RATES)
    elif args.faults == "none" or not config.faults.enabled:
        rates = no_faults()
    else:
        rates = config.faults.rates.model_dump()
    if args.workers < 1:
        raise UserError(f"--workers: must be >= 1, got {args.workers}")
    scene_seed = config.sim.seed if args.seed is None else args.seed
    fault_seed = config.faults.seed if args.seed is None else args.seed
    if args.workers == 1:
        result = Soak(prep, rates, scene_seed, fault_seed, args.cycles, quiet=args.quiet).run()
    else:
        result = run_shards(
            args.config,
            rates,
            scene_seed,
            fault_seed,
            args.cycles,
            args.workers,
            args.quiet,
            tuple(args.set),
        )
    _print(result)
    if args.json is not None:
        write_json(args.json, result)
        print(f"wrote {args.json}")
    if result["interrupted"]:
        return 130
    return 0 if result["unhandled_exceptions"] == 0 and result["unaccounted"] == 0 else 1


# ------------------------------------------------------------------------------- the soak
def abort_key(node: str | None, code: str | None) -> str:
    """What counts an abort as one kind: the tree leaf that stopped and the failure's code,
    e.g. ``grasp: force_torque`` (never the message's numbers or wording)."""
    what = code or "uncoded"
    return f"{node}: {what}" if node else what


def stop_key(state: Any) -> str:
    """A stop counted by its code and, for a stop_on_failure, the node's configured reason."""
    code = state.stop_code or "uncoded"
    return f"{code}: {state.stop_cause}" if state.stop_cause else str(code)


class Soak:
    """The soak's state across runs and twins; :meth:`run` gives the report."""

    def __init__(
        self,
        prep: Any,
        rates: dict[str, float],
        scene_seed: int,
        fault_seed: int,
        cycles: int,
        quiet: bool = False,
        on_twin: Callable[[Any], None] | None = None,
        label: str = "",
    ) -> None:
        """``on_twin(injector)`` is called for each new twin, after its devices are wrapped
        (tests force a fault at a known moment with it)."""
        self.on_twin = on_twin
        self.label = f"{label} " if label else ""
        self.first_prep = prep
        self.config, self.doc = prep.config, prep.doc
        self.rates, self.scene_seed, self.fault_seed = rates, scene_seed, fault_seed
        self.cycles, self.quiet = cycles, quiet
        self.places = len(prep.geometry.tray_places)
        self.place_xy = [tuple(map(float, pl[:2])) for pl in prep.geometry.tray_places]
        self.backend: Any = None
        self.injector: Any = None
        self.twins = 0
        self.refills = 0
        # What the cell has done, across runs (the tree is built afresh for each run).
        self.done = 0
        self.attempted = 0
        self.filled: set[int] = set()
        self.failures: dict[tuple[int, int], int] = {}
        # Parts: spawned, found in retired twins, removed by the person, shipped in boxes.
        self.spawned = 0
        self.retired: Counter[str] = Counter()
        self.removed: Counter[str] = Counter()
        self.shipped = 0
        self.boxes = 0
        self.aborts: Counter[str] = Counter()
        self.stops: Counter[str] = Counter()
        self.exceptions: list[dict[str, Any]] = []
        self.events: Counter[str] = Counter()
        self.judged_ok: Counter[str] = Counter()
        self.faults_total: dict[str, Counter[str]] = {
            "opportunities": Counter(),
            "drawn": Counter(),
            "injected": Counter(),
        }
        self.runs: list[dict[str, Any]] = []
        self.interventions = 0
        self.false_empty = 0
        self.sim_time = 0.0
        self.interrupted = False

    # -- the twin ----------------------------------------------------------------------------
    def _open_twin(self, prep: Any) -> None:
        from cell.assemble import open_backend
        from sim.faults import twin_injector

        seed = self.scene_seed + 1000 * self.twins
        self.backend = open_backend(prep, seed=seed)
        self.injector = twin_injector(self.backend, self.rates, self.fault_seed + 7919 * self.twins)
        prep.ctx.devices = self.backend.wrap_devices(self.injector.wrap)
        self.twins += 1
        self.spawned += len(self.backend.bodies)
        if self.on_twin is not None:
            self.on_twin(self.injector)
        self.filled, self.failures = set(), {}

    def _retire_twin(self) -> None:
        """Account the parts of a twin given up (after an exception) where they are, close it."""
        if self.backend is None:
            return
        try:
            self.retired.update(self.backend.account())
        finally:
            self._collect_faults()
            self.backend.close()
            self.backend = None

    def _collect_faults(self) -> None:
        if self.injector is None:
            return
        s = self.injector.summary()
        for k in ("opportunities", "drawn", "injected"):
            self.faults_total[k].update(s[k])
        self.injector = None

    # -- a run of the tree -------------------------------------------------------------------
    def _prepare(self) -> Any:
        from cell.assemble import prepare

        if self.backend is None:
            prep = prepare(self.config, self.doc)
            self._open_twin(prep)
        else:
            prep = prepare(self.config, self.doc)
            prep.ctx.devices = self.backend.devices
            prep.ctx.machine = self.backend.machine
            prep.state.on_event.append(self.backend.judge)
        ctx = prep.ctx
        ctx.filled = set(self.filled)
        ctx.failures = dict(self.failures)
        ctx.slot_state = SlotState.EMPTY  # the person emptied it
        ctx.limits.cycles_done = self.done
        free = self.places - len(self.filled)
        ctx.limits.cycles = self.done + max(1, min(self.cycles - self.attempted, free))
        return prep

    def _run_once(self) -> dict[str, Any]:
        from cell.runner import TickLog, TickLoop

        prep = self._prepare()
        n_cycles = prep.ctx.limits.cycles - self.done
        loop = TickLoop(
            prep.root,
            self.backend,
            prep.state,
            TickLog(None),
            self.config.cell.control_hz,
            wrench=lambda: None,
            state_file=None,
        )
        t0 = self.backend.clock.now()
        info: dict[str, Any] = {"cycles_asked": n_cycles}
        try:
            result = loop.run(150.0 * n_cycles + 60.0)
            info["status"] = result.status
        except Exception as exc:  # noqa: BLE001 -- the soak counts what escapes the tree
            info["status"] = "exception"
            self.exceptions.append(
                {
                    "run": len(self.runs) + 1,
                    "error": f"{type(exc).__name__}: {exc}",
                    "traceback": traceback.format_exc().splitlines()[-12:],
                }
            )
        finally:
            if self.backend is not None:
                self.sim_time += self.backend.clock.now() - t0
        state = prep.state
        self.filled = set(prep.ctx.filled)
        self.failures = dict(prep.ctx.failures)
        kinds = Counter(e["kind"] for e in state.events)
        self.events.update(kinds)
        for e in state.events:
            v = e.get("verdict")
            if isinstance(v, dict) and v.get("ok"):
                self.judged_ok[e["kind"]] += 1
        done = kinds[EventKind.CYCLE_DONE]
        failed = max(0, kinds[EventKind.CYCLE_FAILED] - kinds[EventKind.BIN_EMPTY])
        self.done += done
        self.attempted += done + failed
        for a in state.aborts:
            self.aborts[abort_key(a.get("node"), a.get("code"))] += 1
        if state.stop_reason:
            self.stops[stop_key(state)] += 1
        info.update(
            cycles_done=done,
            cycles_failed=failed,
            stop_reason=state.stop_reason,
            stop_code=state.stop_code,
            abort_codes=[a.get("code") for a in state.aborts],
            bin_empty=[
                e.get("skipped", 0) for e in state.events if e["kind"] == EventKind.BIN_EMPTY
            ],
        )
        if info["status"] == "interrupted":
            self.interrupted = True
        return info

    # -- the person at the cell --------------------------------------------------------------
    def _operator(self, info: dict[str, Any]) -> None:
        """Between runs: clear what is lost, ship a full box, refill the bin, reset."""
        backend = self.backend
        if info["status"] == "exception":
            self._retire_twin()
            return
        where = backend.parts_where()
        acted = False
        for body, place in where:
            if place in ("in_hand", "in_slot", "on_floor"):
                backend.remove_part(body)
                self.removed[place] += 1
                acted = True
        in_box = [b for b, place in where if place == "packed"]
        # A packing that stopped because the box was in the way (a packed part pushed out of
        # its place by an earlier abort): the person sees a box that needs sorting and ships
        # it, as for a full one; otherwise every later packing would stop at the same spot.
        box_codes = {Failure.BLOCKED, Failure.NO_CONTACT}
        codes = info["abort_codes"]  # the stop's own cause is the last abort before it
        blocked = bool(info.get("stop_reason")) and bool(codes) and codes[-1] in box_codes
        if len(self.filled) >= self.places or blocked or not self._box_in_order(in_box):
            for body in in_box:
                backend.remove_part(body)
            self.shipped += len(in_box)
            self.boxes += 1
            self.filled = set()
        stuck = info["status"] != "success" and info.get("stop_code") == StopKind.FAILED_CYCLES
        in_bin = [b for b, place in where if place == "in_bin"]
        gave_up = bool(info["bin_empty"]) and info["bin_empty"][-1] > 0
        if in_bin and info["bin_empty"] and not gave_up:
            self.false_empty += 1  # the tree saw an empty bin that was not (invalid depth)
        streak = self.false_empty_in_a_row(info)
        if in_bin and (stuck or gave_up or streak >= 3):
            for body in in_bin:
                backend.remove_part(body)
            self.removed["in_bin"] += len(in_bin)
            in_bin = []
            acted = True
        if not in_bin:
            count = self.config.bin.parts
            seed = self.scene_seed + 1 + 7 * self.refills + 1000 * self.twins
            self.spawned += len(backend.refill_bin(count, seed))
            self.refills += 1
            self.failures = {}
        if info["status"] != "success" or acted:
            self.interventions += 1
        self._reset_robot()

    #: How far (m) a packed part may stand from its place's centre, and how far from upright
    #: (rad), before the person sees a box out of order. The pushes pack to within 2.2 mm
    #: (measured).
    PLACE_TOLERANCE = 0.004
    UPRIGHT_TOLERANCE = math.radians(10.0)

    def _box_in_order(self, in_box: list[Any]) -> bool:
        """Whether the box holds exactly the places the cell recorded as filled, each part
        upright on its own place. A part an abort pushed off its place, or one the cell did not
        record, makes the cell's next packing push against a neighbour that is not where it
        should be -- a person ships such a box (as a full one) rather than let it stop every
        later packing."""
        if len(in_box) != len(self.filled):
            return False
        seen: set[int] = set()
        for body in in_box:
            xy = body.pose().position[:2]
            k = min(range(self.places), key=lambda i: math.dist(self.place_xy[i], xy))
            off = math.dist(self.place_xy[k], xy)
            if off > self.PLACE_TOLERANCE or body.tilt() < math.pi / 2 - self.UPRIGHT_TOLERANCE:
                return False
            seen.add(k)
        return seen == self.filled

    def false_empty_in_a_row(self, info: dict[str, Any]) -> int:
        """Runs in a row that ended on an empty bin that was not (the person gives up on 3)."""
        if info["bin_empty"] and info["bin_empty"][-1] == 0:
            self._false_streak = getattr(self, "_false_streak", 0) + 1
        else:
            self._false_streak = 0
        return self._false_streak

    def _reset_robot(self) -> None:
        """Open the jaws and jog the arm home on the twin's own devices, with the faults
        cleared; if the arm cannot get there (stuck in a protective stop against something),
        the person moves it by hand (freedrive)."""
        from drivers.arm import MotionState
        from drivers.pose import Pose

        self.injector.reset()
        robot = self.backend.robot
        world = self.backend.world
        robot.gripper.open()
        home = robot.arm.home_joints
        for _ in range(int(1.0 / world.settings.control_dt)):
            world.step()
        tool = robot.arm.tool_pose()
        robot.arm.move_to(Pose(tool.position + [0.0, 0.0, 0.05], tool.rotation), 0.1, 0.5)
        for _ in range(int(2.0 / world.settings.control_dt)):
            world.step()
            if robot.arm.status().state is not MotionState.MOVING:
                break
        if home is not None:
            robot.arm.move_joints(home, 1.0, 2.0)
            for _ in range(int(10.0 / world.settings.control_dt)):
                world.step()
                if robot.arm.status().state is not MotionState.MOVING:
                    break
            if robot.arm.status().state is not MotionState.DONE:
                robot.arm.reset_joints(home)
        robot.ft.bias()
        self.injector.reset()

    # -- the whole soak ----------------------------------------------------------------------
    def run(self) -> dict[str, Any]:
        wall0 = time.perf_counter()
        max_runs = 4 * self.cycles + 20
        while self.attempted < self.cycles and len(self.runs) < max_runs:
            info = self._run_once()
            info["wall_s"] = round(time.perf_counter() - wall0, 1)
            self.runs.append(info)
            self._progress(info)
            if self.interrupted:
                break
            if self.attempted < self.cycles:
                try:
                    self._operator(info)
                except Exception as exc:  # noqa: BLE001 -- a broken twin: start a fresh one
                    self.exceptions.append(
                        {
                            "run": len(self.runs),
                            "error": f"operator: {type(exc).__name__}: {exc}",
                            "traceback": traceback.format_exc().splitlines()[-12:],
                        }
                    )
                    self._retire_twin()
        final: Counter[str] = Counter(self.retired)
        if self.backend is not None:
            final.update(self.backend.account())
            self._collect_faults()
            self.backend.close()
            self.backend = None
        parts = {k: int(final[k]) for k in PLACES}
        removed = {k: int(self.removed[k]) for k in ("in_bin", "in_hand", "in_slot", "on_floor")}
        found = sum(parts.values()) + sum(removed.values()) + self.shipped
        wall = time.perf_counter() - wall0
        return {
            "cycles": self.cycles,
            "cycles_attempted": self.attempted,
            "cycles_done": self.done,
            "unhandled_exceptions": len(self.exceptions),
            "exceptions": self.exceptions,
            "parts": parts,
            "removed_by_operator": removed,
            "shipped": {"boxes": self.boxes, "parts": self.shipped},
            "spawned": self.spawned,
            "unaccounted": self.spawned - found,
            "aborts_by_reason": dict(self.aborts.most_common()),
            "stops_by_reason": dict(self.stops.most_common()),
            "events": dict(self.events),
            "judged_ok": dict(self.judged_ok),
            "operator_interventions": self.interventions,
            "false_bin_empty": self.false_empty,
            "bin_refills": self.refills,
            "twins": self.twins,
            "runs": self.runs,
            "faults": {
                "seed": self.fault_seed,
                "rates": self.rates,
                **{k: dict(v) for k, v in self.faults_total.items()},
            },
            "seed": self.scene_seed,
            "sim_time_s": round(self.sim_time, 1),
            "wall_s": round(wall, 1),
            "wall_s_per_cycle": round(wall / max(1, self.attempted), 2),
            "interrupted": self.interrupted,
        }

    def _progress(self, info: dict[str, Any]) -> None:
        if self.quiet:
            return
        stop = f"  stop: {info['stop_reason']}" if info.get("stop_reason") else ""
        sys.stderr.write(
            f"  {self.label}run {len(self.runs):3d}: {info['status']:<9s} "
            f"+{info['cycles_done']} done "
            f"+{info['cycles_failed']} failed  ({self.attempted}/{self.cycles} cycles, "
            f"wall {info['wall_s']:.0f} s){stop}\n"
        )


# ------------------------------------------------------------------------------ shards
def _shard(
    config_path: Path | None,
    rates: dict[str, float],
    scene_seed: int,
    fault_seed: int,
    cycles: int,
    label: str,
    quiet: bool,
    sets: tuple[str, ...] = (),
) -> dict[str, Any]:
    """One shard in a worker process: its own configuration load, twin and person."""
    from cell.cell_cmds import load_prepared

    prep = load_prepared(config_path, sets)
    return Soak(prep, rates, scene_seed, fault_seed, cycles, quiet, label=label).run()


def run_shards(
    config_path: Path | None,
    rates: dict[str, float],
    scene_seed: int,
    fault_seed: int,
    cycles: int,
    workers: int,
    quiet: bool = False,
    sets: tuple[str, ...] = (),
) -> dict[str, Any]:
    """Why shards: the twin steps its physics on one core (about 10 s of wall per cycle), so a
    1000-cycle soak in one process takes hours; shards are independent cells (each with its own
    bin, box and person) whose reports add up. Each shard still runs hundreds of cycles in one
    process, which is what finds state that drifts or leaks over a long run."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    workers = min(workers, cycles)
    share = [cycles // workers + (1 if k < cycles % workers else 0) for k in range(workers)]
    wall0 = time.perf_counter()
    ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: no PyBullet state forked
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futures = [
            pool.submit(
                _shard,
                config_path,
                rates,
                scene_seed + SHARD_SEED_STEP * k,
                fault_seed + SHARD_SEED_STEP * k,
                n,
                f"shard {k}",
                quiet,
                sets,
            )
            for k, n in enumerate(share)
        ]
        reports = [f.result() for f in futures]
    return merge_reports(reports, time.perf_counter() - wall0)


def merge_reports(reports: list[dict[str, Any]], wall: float) -> dict[str, Any]:
    """The shards' reports added up into one of the same form, with each shard's own figures
    under ``shards``."""
    first = reports[0]
    sums = (
        "cycles", "cycles_attempted", "cycles_done", "unhandled_exceptions", "spawned",
        "unaccounted", "operator_interventions", "false_bin_empty", "bin_refills", "twins",
    )
    out: dict[str, Any] = {k: sum(int(r[k]) for r in reports) for k in sums}

    def add(counts: list[dict[str, int]]) -> dict[str, int]:
        c: Counter[str] = Counter()
        for one in counts:
            c.update(one)
        return dict(c.most_common())

    out["exceptions"] = [dict(e, shard=k) for k, r in enumerate(reports) for e in r["exceptions"]]
    out["parts"] = {k: sum(r["parts"][k] for r in reports) for k in PLACES}
    out["removed_by_operator"] = {
        k: sum(r["removed_by_operator"][k] for r in reports) for k in first["removed_by_operator"]
    }
    out["shipped"] = {
        k: sum(r["shipped"][k] for r in reports) for k in ("boxes", "parts")
    }
    for key in ("aborts_by_reason", "stops_by_reason", "events", "judged_ok"):
        out[key] = add([r[key] for r in reports])
    out["runs"] = [dict(run, shard=k) for k, r in enumerate(reports) for run in r["runs"]]
    faults: dict[str, Any] = {
        "seed": [r["faults"]["seed"] for r in reports],
        "rates": first["faults"]["rates"],
    }
    for k in ("opportunities", "drawn", "injected"):
        faults[k] = add([r["faults"][k] for r in reports])
    out["faults"] = faults
    out["seed"] = first["seed"]
    out["sim_time_s"] = round(sum(r["sim_time_s"] for r in reports), 1)
    out["wall_s"] = round(wall, 1)
    out["wall_s_per_cycle"] = round(wall / max(1, out["cycles_attempted"]), 2)
    out["interrupted"] = any(r["interrupted"] for r in reports)
    out["shards"] = [
        {
            "seed": r["seed"],
            "fault_seed": r["faults"]["seed"],
            **{k: r[k] for k in ("cycles", "cycles_attempted", "cycles_done",
                                 "unhandled_exceptions", "unaccounted", "wall_s")},
            "stops": sum(r["stops_by_reason"].values()),
        }
        for r in reports
    ]
    return out


def _print(r: dict[str, Any]) -> None:
    rows = [
        ("cycles attempted", f"{r['cycles_attempted']} (asked {r['cycles']})"),
        ("cycles done (packed)", str(r["cycles_done"])),
        ("unhandled exceptions", str(r["unhandled_exceptions"])),
        ("parts at the end", ", ".join(f"{k} {v}" for k, v in r["parts"].items())),
        (
            "removed by the person",
            ", ".join(f"{k} {v}" for k, v in r["removed_by_operator"].items()),
        ),
        ("shipped", f"{r['shipped']['parts']} parts in {r['shipped']['boxes']} boxes"),
        ("spawned / unaccounted", f"{r['spawned']} / {r['unaccounted']}"),
        ("faults injected", str(sum(r["faults"]["injected"].values()))),
        ("aborts", str(sum(r["aborts_by_reason"].values()))),
        ("stops (person called)", str(sum(r["stops_by_reason"].values()))),
        ("wall time", f"{r['wall_s']:.0f} s ({r['wall_s_per_cycle']:.1f} s per cycle)"),
    ]
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")


__all__ = ["Soak", "abort_key", "add_parser", "cmd_soak", "merge_reports", "run_shards"]
