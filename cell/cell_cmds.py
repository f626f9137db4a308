"""`cell sim`, `cell run`, `cell tree`, `cell replay`, `cell schema`: the cell as a product.

Contract forms (scripts rely on them; keep them exactly):

* ``cell sim --config FILE --cycles N --seed S [--record FILE.gif] --json FILE``
* ``cell run --config FILE``
* ``cell tree --config FILE``
* ``cell replay LOG``
* ``cell check-hardware --config FILE [--move-test]``

A configuration that fails validation exits 2 with ``file:line: key: reason`` lines and opens no
device. Ctrl-C / SIGTERM during a run stop the arm, flush the log, save the state and exit 130 /
143.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from cell.errors import UserError
from cell.journal import RETURNED_TO_BIN, RETURNED_TO_SLOT
from cell.output import report_config_error, write_json
from cell.overrides import add_set_argument
from drivers.events import EventKind
from trees.yaml_lines import ConfigError

#: Events printed as progress lines by `cell sim`.
PROGRESS_KINDS = frozenset(
    {EventKind.PICKED, EventKind.FED, EventKind.MACHINED, EventKind.PACKED,
     EventKind.CYCLE_FAILED, EventKind.BIN_EMPTY}
)


def load_prepared(path: Path | None, sets: Any = (), **bin_overrides: Any) -> Any:
    """The configuration at ``path`` (None: the shipped example) validated and prepared
    (:func:`cell.assemble.prepare`): what `cell sim`, `cell run`, `cell tree`, `cell
    check-hardware` and `cell soak` start from. ``sets``: the ``--set KEY.PATH=VALUE`` texts,
    applied before validation (:mod:`cell.overrides`). ``bin_overrides``: keys of the ``bin``
    section given on the command line (None: the file's). Raises :class:`ConfigError`."""
    from cell.assemble import prepare
    from cell.config import BinSection, default_config_path, validate_document
    from cell.overrides import apply_sets
    from trees.yaml_lines import load_yaml

    doc = apply_sets(load_yaml(path if path is not None else default_config_path()), sets)
    config = validate_document(doc)
    given = {k: v for k, v in bin_overrides.items() if v is not None}
    if given:
        from pydantic import ValidationError

        try:
            fixed = BinSection.model_validate({**config.bin.model_dump(), **given})
        except ValidationError as exc:
            err = exc.errors()[0]
            raise UserError(
                f"--{err['loc'][0]}: {err['msg']}, got {err.get('input')!r}"
            ) from None
        config = config.model_copy(update={"bin": fixed})
    return prepare(config, doc)


#: the --cycles help of `cell sim` and `cell run`
CYCLES_HELP = (
    "cycles to run (default: the configuration's workflow.cycles; the shipped example's is 10)"
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sim",
        help="run the cell's workflow in the PyBullet twin",
        description="Runs the configured tree in the twin: pick each part by the pivot into a "
        "hole grasp, feed the machine slot, wait, pick it from the slot, pack it in the box. "
        "Every outcome is judged from the simulated state. Without --config: the shipped "
        "bushing-machining example.",
    )
    p.add_argument("--config", type=Path, default=None, help="cell configuration YAML")
    p.add_argument("--cycles", type=int, default=None, help=CYCLES_HELP)
    p.add_argument("--seed", type=int, default=None, help="seed of the bin scene (sim.seed)")
    p.add_argument(
        "--fill",
        choices=("rows", "random"),
        default=None,
        help="how the bin is filled (bin.fill): staged rows, or tipped in at random",
    )
    p.add_argument("--parts", type=int, default=None, help="parts in the bin (bin.parts)")
    p.add_argument("--record", type=Path, default=None, help="write an animated GIF of the run")
    p.add_argument("--trace", type=Path, default=None,
                   help="CSV, one row per step of the twin: its time, wrist wrench (raw, tool "
                   "frame), finger opening, TCP position and arm mode (as `cell emulate --trace`)")
    p.add_argument("--json", type=Path, default=None, help="write the summary as JSON")
    p.add_argument(
        "--max-sim-time",
        type=float,
        default=None,
        help="simulated seconds before the run is cut (default: 150 per cycle, plus 60)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue from the journal (log.journal) after a crash or a stop",
    )
    p.add_argument(
        "--monitor",
        default=None,
        metavar="HOST:PORT",
        help="serve a read-only web page of the run (tree, wrench, camera, events) on "
        "HOST:PORT, e.g. 127.0.0.1:8765 (port 0: any free one)",
    )
    add_set_argument(p)
    p.set_defaults(func=cmd_sim)

    p = sub.add_parser(
        "run",
        help="run the cell on the hardware backend",
        description="Runs the configured tree on the real UR5, 2F-85, FT300 and D435. Refuses "
        "unless the configuration says `cell.backend: hw` and the device checks pass.",
    )
    p.add_argument("--config", type=Path, required=True, help="cell configuration YAML")
    p.add_argument("--cycles", type=int, default=None, help=CYCLES_HELP)
    p.add_argument("--json", type=Path, default=None, help="write the summary as JSON")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue from the journal (log.journal) after a crash or a stop",
    )
    p.add_argument(
        "--monitor",
        default=None,
        metavar="HOST:PORT",
        help="serve a read-only web page of the run (tree, wrench, camera, events) on "
        "HOST:PORT, e.g. 127.0.0.1:8765 (port 0: any free one)",
    )
    add_set_argument(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser(
        "tree",
        help="print the behaviour tree and write its picture",
        description="Builds the configured tree (no device is opened), prints it as text and "
        "writes DOT and PNG pictures.",
    )
    p.add_argument("--config", type=Path, default=None, help="cell configuration YAML")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="directory for tree.dot/.png, tree.xml (--format btcpp) or tree.yaml (--from-btcpp)"
        " (default: out; --from-btcpp without it prints the YAML)",
    )
    p.add_argument("--types", action="store_true", help="list the behaviour types and exit")
    p.add_argument(
        "--format",
        choices=("picture", "btcpp"),
        default=None,
        help="picture: DOT and PNG (default); btcpp: BehaviorTree.CPP v4 XML (DIR/tree.xml) "
        "that Groot2 opens; not with --from-btcpp, which writes the YAML form",
    )
    p.add_argument(
        "--from-btcpp",
        type=Path,
        default=None,
        metavar="FILE",
        help="read a BehaviorTree.CPP v4 XML tree (e.g. edited in Groot2) into the YAML form",
    )
    add_set_argument(p)
    p.set_defaults(func=cmd_tree)

    p = sub.add_parser(
        "replay",
        help="print the timeline of a run from its JSONL tick log",
        description="Reads a tick log written by `cell sim` or `cell run` and prints when each "
        "behaviour started and ended, with its feedback, the events and the aborts.",
    )
    p.add_argument("log", type=Path, help="the JSONL tick log (log.tick_log in the config)")
    p.add_argument("--all", action="store_true", help="every status change, not only leaves")
    p.add_argument(
        "--serve",
        default=None,
        metavar="HOST:PORT",
        help="serve the monitor's page over the recorded run, with a time slider, instead of "
        "printing the timeline",
    )
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser(
        "check-hardware",
        help="connect to and check every configured device",
        description="Connects to the UR5 (RTDE and dashboard), the 2F-85 (activates it), the "
        "FT300 (stream rate, bias) and the D435 (one frame), prints a table, and closes them. "
        "Never moves the arm unless --move-test. Exit 0 only when every check passes.",
    )
    p.add_argument("--config", type=Path, required=True, help="cell configuration YAML")
    p.add_argument(
        "--move-test",
        action="store_true",
        help="also turn the last wrist joint 2 deg and back, slowly",
    )
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=cmd_check_hardware)

    p = sub.add_parser("schema", help="print the configuration's JSON Schema (for editors)")
    p.add_argument(
        "--json", "--out", dest="out", type=Path, default=None, metavar="FILE",
        help="write it to this file instead",
    )
    p.set_defaults(func=cmd_schema)


# --------------------------------------------------------------------------------- sim/run
def cmd_sim(args: argparse.Namespace) -> int:
    if args.cycles is not None and args.cycles < 1:
        raise UserError(f"--cycles: must be >= 1, got {args.cycles}")
    if args.seed is not None and args.seed < 0:
        raise UserError(f"--seed: must be >= 0, got {args.seed}")
    if args.record is not None and args.record.suffix.lower() != ".gif":
        raise UserError(f"--record: {args.record}: the animation is written as a .gif")
    if args.parts is not None and args.parts < 0:
        raise UserError(f"--parts: must be >= 0, got {args.parts}")
    if args.max_sim_time is not None and not args.max_sim_time > 0:
        raise UserError(f"--max-sim-time: must be > 0 s, got {args.max_sim_time:g}")
    try:
        prep = load_prepared(args.config, args.set, fill=args.fill, parts=args.parts)
    except ConfigError as exc:
        return report_config_error(exc, "sim")
    if prep.config.cell.backend != "sim":
        raise UserError(
            f"{prep.doc.source}: cell.backend is {prep.config.cell.backend!r}; `cell sim` runs "
            "the twin only (use `cell run` for the hardware)"
        )
    if args.cycles is not None:
        prep.ctx.limits.cycles = args.cycles
    return _run(prep, "sim", args, seed=args.seed)


def cmd_run(args: argparse.Namespace) -> int:
    try:
        prep = load_prepared(args.config, args.set)
    except ConfigError as exc:
        return report_config_error(exc, "run")
    if prep.config.cell.backend != "hw":
        raise UserError(
            f"{prep.doc.source}: cell.backend is {prep.config.cell.backend!r}; `cell run` drives "
            "the real cell and needs `backend: hw` (use `cell sim` for the twin)"
        )
    if args.cycles is not None:
        if args.cycles < 1:
            raise UserError(f"--cycles: must be >= 1, got {args.cycles}")
        prep.ctx.limits.cycles = args.cycles
    args.record, args.max_sim_time, args.quiet = None, None, False
    return _run(prep, "run", args, seed=None)


def _run(prep: Any, command: str, args: argparse.Namespace, seed: int | None) -> int:
    from cell.assemble import open_backend
    from cell.preflight import check_config_outputs
    from cell.runner import TickLoop

    if getattr(args, "monitor", None) is not None:
        from cell.monitor.server import parse_address

        parse_address(args.monitor)  # a bad address is refused before anything opens
    check_config_outputs(prep.config)  # before the journal, the twin or a device is opened
    # Nothing on disk changes until every check has passed: the journal is read, the twin or
    # the devices and the monitor's port are opened, and only then are the journal and the
    # logs written (a refused start keeps the run a --resume continues).
    try:
        plan = _plan_journal(prep, command, bool(getattr(args, "resume", False)))
    except _NothingToDo as done:
        print(str(done))
        return 0
    paced = command == "run" or prep.config.sim.realtime
    if paced:
        from drivers.priority import set_thread_niceness

        # Before the devices open: their readers (the FT300's, whose guard stops the arm on a
        # sample over the limit) inherit the tick loop's priority instead of waiting behind it.
        set_thread_niceness(prep.config.cell.tick_niceness)
    try:
        backend = open_backend(prep, seed=seed, resume=plan.state)
    except ConfigError as exc:
        return report_config_error(exc, command)
    config = prep.config
    cycles = prep.ctx.limits.cycles
    from cell.monitor import open_session

    try:
        session = open_session(
            prep, getattr(args, "monitor", None), command,
            accepted=lambda: _open_journal(prep, plan),
        )
    except UserError:
        backend.close()
        if prep.state.journal is not None:
            prep.state.journal.close()
        raise
    log = session.log
    trace = None
    recorder = None
    if args.record is not None:
        from cell.recording import CellRecorder, caption_for

        g = prep.geometry
        target = (0.5 * (g.bin_roi[0] + g.bin_roi[1]) - 0.15, 0.0, 0.15)
        arm = prep.ctx.devices.arm
        recorder = CellRecorder(
            backend.world,
            target,
            (0.9, 0.0, 0.45),
            distance=1.25,
            height=0.5,
            tool_position=lambda: arm.tool_pose().position,
            caption=caption_for(prep),
        )
    progress = _Progress(prep, cycles, quiet=args.quiet)

    def on_tick(tick: int) -> None:
        progress.update(tick)
        if recorder is not None and tick % 25 == 0:
            recorder.capture()

    loop = TickLoop(
        prep.root,
        backend,
        prep.state,
        log,
        config.cell.control_hz,
        wrench=lambda: prep.ctx.devices.ft.wrench(),
        on_tick=on_tick,
        realtime=paced,
        state_file=config.log.state_file,
        taps=session.taps,
        monitor=session.live,
        niceness=config.cell.tick_niceness,
    )
    max_time = args.max_sim_time if args.max_sim_time is not None else 150.0 * cycles + 60.0
    box_png = None
    parts = None
    twin_left: list[dict[str, Any]] | None = None
    stills: list[Path] = []
    try:
        if getattr(args, "trace", None) is not None:
            from sim.trace import TwinTrace

            trace = TwinTrace(args.trace, backend.world, backend.robot)
        if recorder is not None:
            stills.append(_bin_picture(backend, prep, args.record, "start"))
        result = loop.run(max_time)
        if recorder is not None:
            box_png = _box_picture(backend, prep, args.record)
            stills.append(_bin_picture(backend, prep, args.record, "end"))
        if hasattr(backend, "account"):
            parts = backend.account()
            twin_left = backend.left_in_bin()
    finally:
        if trace is not None:
            trace.close()
        session.close()
        log.close()
        backend.close()
        if prep.state.journal is not None:
            prep.state.journal.close()
    progress.done()
    summary = _summary(prep, result, cycles)
    if parts is not None:
        summary["parts"] = parts  # where every part is at the end, judged by the twin
        summary["left_in_bin"] = parts["in_bin"]
    summary["left_reasons"] = left_reasons(
        prep.state.events, summary.get("left_in_bin"), prep.state.stop_reason, twin_left
    )
    summary["repositioned"] = prep.state.counts.get(EventKind.REPOSITIONED, 0)
    summary["phases"] = log.phases.table(summary["packed_claimed"] or None)
    _print_summary(summary)
    if recorder is not None and recorder.frames:
        recorder.save_gif(args.record, fps=12)
        print(f"wrote {args.record} ({len(recorder.frames)} frames)")
    if box_png is not None:
        print(f"wrote {box_png} (the box at the end)")
    for still in stills:
        print(f"wrote {still} (the bin)")
    if args.json is not None:
        write_json(args.json, summary)
        print(f"wrote {args.json}")
    if result.status == "interrupted":
        print(
            f"cell {command}: interrupted: arm stopped, log flushed, state saved; "
            + _resume_hint(prep, getattr(args, "argv", None), command),
            file=sys.stderr,
        )
        return 128 + int(result.signum or 2)
    return 0 if result.status == "success" else 1


def _resume_hint(prep: Any, argv: list[str] | None, command: str) -> str:
    """The command that continues this run from its journal (the same command line, plus
    ``--resume``)."""
    import shlex

    if prep.config.log.journal is None:
        return "no journal (log.journal is null), so the run cannot be resumed"
    words = [w for w in (argv or [command]) if w != "--resume"]
    run = getattr(prep.state.journal, "run", None)
    return f"run {run} is in {prep.config.log.journal}; resume with: " + shlex.join(
        ["cell", *words, "--resume"]
    )


def _box_picture(backend: Any, prep: Any, record: Path) -> Path:
    """A close-up of the box at the end of the run, beside the GIF."""
    x0, x1, y0, y1 = prep.geometry.tray_roi
    target = (0.5 * (x0 + x1), 0.5 * (y0 + y1), prep.geometry.tray_floor_z)
    return _still(backend, target, (0.35, 0.35, 0.0), 0.25, 0.35, record, "_box.png")


def _bin_picture(backend: Any, prep: Any, record: Path, when: str) -> Path:
    """The bin seen from above its far side (``FILE_bin_start.png``, ``FILE_bin_end.png``):
    how the parts lay when the run began, and what it left."""
    x0, x1, y0, y1 = prep.geometry.bin_roi
    target = (0.5 * (x0 + x1), 0.5 * (y0 + y1), prep.geometry.bin_floor_z)
    return _still(backend, target, (0.7, 0.0, 0.7), 0.6, 0.0, record, f"_bin_{when}.png")


def _still(  # noqa: PLR0913 -- the camera's placement, spelled out
    backend: Any,
    target: tuple[float, float, float],
    normal: tuple[float, float, float],
    distance: float,
    height: float,
    record: Path,
    suffix: str,
) -> Path:
    from PIL import Image

    from sim.recorder import Recorder

    rec = Recorder(backend.world, target, normal, distance=distance, height=height, size=(480, 360))
    rec.capture()
    path = record.with_name(record.stem + suffix)
    path.parent.mkdir(parents=True, exist_ok=True)  # --record's folder, as --json makes its own
    Image.fromarray(rec.frames[0]).save(path)
    return path


class _NothingToDo(Exception):
    pass


@dataclasses.dataclass
class _JournalPlan:
    """What the run will do with its journal once its start is accepted."""

    path: Path | None
    resume: bool
    state: Any = None  #: :class:`cell.journal.Resume` to continue from (None: a fresh run)
    returned: str | None = None  #: the record of a held part put back, appended at the start
    run: int = 1  #: the number the run gets in the journal


def _plan_journal(prep: Any, command: str, resume: bool) -> _JournalPlan:
    """Read the crash-safe journal and say how the run will continue; writes nothing.

    On resume, the cell's state (box places filled, the slot, cycles done) is restored from the
    journal into the run's context -- in memory only, so a start refused afterwards (a device,
    the monitor's port) leaves the journal as it was and the next ``--resume`` finds the run.
    A part the journal says was in the gripper cannot be re-created in the twin (nor trusted on
    hardware): in the twin it goes back where it came from -- the bin, or for a machined part
    the slot -- and the journal will say so; on hardware the run is refused until a person has
    done the same.
    """
    from cell.journal import JournalError, Resume, read_journal

    path = prep.config.log.journal
    if path is None:
        if resume:
            raise UserError("--resume needs a journal: log.journal is null in the configuration")
        return _JournalPlan(None, False)
    p = Path(path)
    if not resume:
        return _JournalPlan(p, False)
    if not p.exists():
        raise UserError(f"--resume: no journal at {p} (log.journal)")
    try:
        events, run = read_journal(p)
        state = Resume.from_events(events)
        returned = None
        if state.in_hand is not None:
            if command == "run":
                where = "the bin" if state.in_hand == "bin" else "the slot (it is machined)"
                raise UserError(
                    f"--resume: the journal ({p}) says the gripper held a part when the cell "
                    f"stopped; take it out and put it back in {where}, then resume"
                )
            returned = RETURNED_TO_BIN if state.in_hand == "bin" else RETURNED_TO_SLOT
            state = Resume.from_events([*events, {"kind": returned, "run": run}])
    except JournalError as exc:
        raise UserError(f"log.journal: {exc}") from None
    ctx = prep.ctx
    if state.cycles_done >= ctx.limits.cycles:
        raise _NothingToDo(
            f"{state.cycles_done} of {ctx.limits.cycles} cycles already done (journal {p})"
        )
    ctx.filled = set(state.filled)
    ctx.slot_state = state.slot
    ctx.limits.cycles_done = state.cycles_done
    return _JournalPlan(p, True, state, returned, run)


def _open_journal(prep: Any, plan: _JournalPlan) -> None:
    """Once the start is accepted: open the journal the run appends to.

    A fresh run keeps the earlier journals beside it (``NAME.1.sqlite`` the newest, up to
    :data:`cell.journal.KEEP_JOURNALS`) rather than deleting them, and says so."""
    from cell.journal import KEEP_JOURNALS, Journal, JournalError, keep_earlier

    if plan.path is None:
        return
    p = plan.path
    if not plan.resume:
        kept = keep_earlier(p)
        if kept is not None:
            print(
                f"a fresh run: the previous journal is kept as {kept} (the last {KEEP_JOURNALS} "
                f"are kept; --resume continues one instead)"
            )
    try:
        journal = Journal(p)
        journal.begin_run()
        if plan.returned is not None:
            why = "held at the crash; the twin cannot re-create a grasp"
            journal.append(0, 0.0, plan.returned, {"why": why})
    except JournalError as exc:
        raise UserError(f"log.journal: {exc}") from None
    prep.state.journal = journal
    state = plan.state
    if state is not None:
        print(
            f"run {journal.run} resumes where run {journal.run - 1} of {p} stopped: "
            f"{state.cycles_done} cycles done, box places {sorted(state.filled)} filled, "
            f"slot {state.slot}"
        )


class _Progress:
    """A progress bar on a terminal (packed parts against cycles, simulated time, the tree's
    tip), with a line per workflow step and per abort; into a file or a pipe, those lines and a
    status line every few seconds (:mod:`cell.progress`)."""

    def __init__(self, prep: Any, cycles: int, quiet: bool) -> None:
        from cell.progress import Progress

        self.prep, self.cycles, self.quiet = prep, cycles, quiet
        self.seen = 0
        self.aborts = 0
        self.wall0 = time.perf_counter()
        self.bar = Progress(cycles, "packed", quiet=quiet)

    def _line(self, text: str) -> None:
        self.bar.line(text)

    def update(self, tick: int) -> None:
        if self.quiet:
            return
        state = self.prep.state
        events = state.events
        while self.seen < len(events):
            e = events[self.seen]
            self.seen += 1
            if e["kind"] in PROGRESS_KINDS:
                verdict = e.get("verdict")
                judged = ""
                if isinstance(verdict, dict):
                    judged = (
                        " [twin: ok]" if verdict.get("ok") else f" [twin: {verdict.get('failure')}]"
                    )
                packed = state.counts.get(EventKind.PACKED, 0)
                self._line(
                    f"  t={e['t']:7.1f} s  {e['kind']:<12s}{judged}  packed {packed}/"
                    f"{self.cycles}  wall {time.perf_counter() - self.wall0:.0f} s"
                )
        for a in state.aborts[self.aborts :]:
            self._line(f"  t={a['t']:7.1f} s  abort        {a['reason']}")
        self.aborts = len(state.aborts)
        if tick % 25 == 0:  # the bar's own pacing decides what is drawn
            packed = state.counts.get(EventKind.PACKED, 0)
            tip = self.prep.root.tip()
            self.bar.update(
                min(packed, self.cycles), f"t={state.time:6.1f} s  {tip.name if tip else ''}"
            )

    def done(self) -> None:
        self.bar.close()


def left_reasons(
    events: list[dict[str, Any]],
    left_in_bin: int | None,
    stop_reason: str | None = None,
    twin: list[dict[str, Any]] | None = None,
) -> list[dict[str, Any]]:
    """Each part the cell left in the bin, named, with why. A run that ended on an empty bin:
    the parts the cell saw and passed over, and any more the twin counts as not found by
    perception. A cell that stopped for a person: the stop's reason. A run that ended on its
    cycles: the parts not tried. ``twin`` (the twin's own list of the parts in the bin, with
    ``at`` and ``lies``) names the parts the cell could not name: those it never saw are the
    twin's parts farthest from any it saw."""
    def unnamed(n: int, reason: str, seen: list[dict[str, Any]]) -> list[dict[str, Any]]:
        if not twin:
            return [{"part": "a part", "reason": reason}] * n
        spots = [e["at"] for e in seen if "at" in e]

        def apart(t: dict[str, Any]) -> float:
            return min((math.dist(t["at"], s) for s in spots), default=math.inf)

        rest = sorted(twin, key=apart, reverse=True)[:n]
        out = [{**t, "reason": reason} for t in rest]
        return out + [{"part": "a part", "reason": reason}] * (n - len(out))

    if stop_reason:
        return unnamed(left_in_bin or 0, f"left when the cell stopped: {stop_reason}", [])
    ends = [i for i, e in enumerate(events) if e["kind"] == EventKind.BIN_EMPTY]
    # The run ended on an empty bin when nothing was picked from the bin after the last time
    # the cell found it empty: that look may be the one taken while the machine ran, with the
    # part in the slot still to be machined, picked and packed after it.
    ended_empty = bool(ends) and not any(
        e["kind"] == EventKind.PICKED for e in events[ends[-1] + 1 :]
    )
    if not ended_empty:
        return unnamed(left_in_bin or 0, "not tried: the run ended first", [])
    seen: list[dict[str, Any]] = list(events[ends[-1]].get("left", []))
    if left_in_bin is not None and left_in_bin > len(seen):
        seen += unnamed(left_in_bin - len(seen), "not found by perception", seen)
    return seen


def _summary(prep: Any, result: Any, cycles: int) -> dict[str, Any]:
    state = prep.state
    events = state.events

    def judged(kind: EventKind) -> list[dict[str, Any]]:
        return [e for e in events if e["kind"] == kind]

    def ok(e: dict[str, Any]) -> bool:
        v = e.get("verdict")
        return bool(v.get("ok")) if isinstance(v, dict) else True  # hw: no twin to judge

    fed = [e for e in judged(EventKind.MACHINED) if ok(e)]
    packed_events = judged(EventKind.PACKED)
    packed = [e for e in packed_events if ok(e)]
    times = [0.0] + [e["t"] for e in packed_events]
    tacts = [b - a for a, b in zip(times[:-1], times[1:], strict=True)]
    gaps = []
    for e in packed_events:
        v = e.get("verdict")
        if isinstance(v, dict) and "gaps_mm" in v:
            gaps = v["gaps_mm"]
    return {
        "cycles": cycles,
        "packed": len(packed),
        "fed": len(fed),
        "aborts": [
            {"reason": a["reason"], "code": a.get("code"), "tick": a["tick"]} for a in state.aborts
        ],
        "tact_time_s_mean": (sum(tacts) / len(tacts)) if tacts else None,
        "wall_s": round(result.wall_s, 2),
        "status": result.status,
        "stop_reason": state.stop_reason,
        "sim_time_s": round(result.sim_time, 3),
        "ticks": result.ticks,
        "tick_period_ms": result.tick_period_ms,
        "picked": state.counts.get(EventKind.PICKED, 0),
        "picked_recovered": sum(
            1 for e in state.events if e["kind"] == EventKind.PICKED and e.get("recovered")
        ),
        "picked_standing": sum(
            1 for e in state.events if e["kind"] == EventKind.PICKED and e.get("standing")
        ),
        "packed_claimed": len(packed_events),
        "fed_claimed": state.counts.get(EventKind.FED, 0),
        "gaps_mm": gaps,
        "events": events,
    }


def _print_summary(s: dict[str, Any]) -> None:
    tact = "-" if s["tact_time_s_mean"] is None else f"{s['tact_time_s_mean']:.1f} s"
    rows = [
        ("status", s["status"] + (f" ({s['stop_reason']})" if s["stop_reason"] else "")),
        ("cycles asked", str(s["cycles"])),
        (
            "picked (hole grasp)",
            f"{s['picked']} ({s['picked_recovered']} by the recovery, "
            f"{s['picked_standing']} found standing)",
        ),
        ("fed (judged in slot)", f"{s['fed']} of {s['fed_claimed']}"),
        ("packed (judged)", f"{s['packed']} of {s['packed_claimed']}"),
        ("aborts", str(len(s["aborts"]))),
        ("tact time, mean", tact),
        ("simulated time", f"{s['sim_time_s']:.1f} s"),
        ("wall time", f"{s['wall_s']:.1f} s"),
    ]
    if s["gaps_mm"]:
        rows.append(("gaps to neighbours", ", ".join(f"{g:.1f}" for g in s["gaps_mm"]) + " mm"))
    width = max(len(r[0]) for r in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    phases = s.get("phases") or []
    if phases:
        per_part = "per_part_s" in phases[0]
        print("where the time goes (each leaf of the tree, simulated or wall-clock s):")
        name_w = max(len(str(r["phase"])) for r in phases)
        head = f"  {'leaf':<{name_w}}  {'runs':>4}  {'failed':>6}  {'mean':>7}  {'total':>8}"
        print(head + ("  per part" if per_part else ""))
        for r in phases:
            line = (
                f"  {r['phase']:<{name_w}}  {r['runs']:>4}  {r['failed']:>6}  "
                f"{r['mean_s']:>7.1f}  {r['total_s']:>8.1f}"
            )
            print(line + (f"  {r['per_part_s']:>8.1f}" if per_part else ""))


# ------------------------------------------------------------------------------ tree/replay
def cmd_tree(args: argparse.Namespace) -> int:
    import py_trees

    from trees.registry import describe_types
    from trees.render import limits_table, write_pictures

    if args.types:
        print(describe_types())
        return 0
    if args.from_btcpp is not None:
        if args.format is not None:
            raise UserError(f"--format {args.format}: does not go with --from-btcpp, which "
                            "reads a BehaviorTree.CPP tree and writes the YAML form")
        from cell.tree_xml import from_btcpp

        return from_btcpp(args.from_btcpp, args.out)
    try:
        prep = load_prepared(args.config, args.set)
    except ConfigError as exc:
        return report_config_error(exc, "tree")
    if args.format == "btcpp":
        from cell.tree_xml import write_btcpp

        return write_btcpp(prep, args.out or Path("out"))
    args.out = args.out or Path("out")
    print(py_trees.display.unicode_tree(prep.root))
    print("abort limits of each motion leaf (force, torque, time):")
    for line in limits_table(prep.root):
        print(f"  {line}")
    dot, png = write_pictures(prep.root, args.out)
    print(f"wrote {dot} and {png}")
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    if args.serve is not None:
        from cell.monitor import serve_replay

        return serve_replay(args.log, args.serve)
    from cell.replay import read_tick_log, timeline

    log = read_tick_log(args.log)
    if log.warning is not None:
        print(f"cell replay: warning: {log.warning}", file=sys.stderr)
    for row in timeline(log.lines, every=args.all):
        print(row)
    return 0


def cmd_check_hardware(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    from cell.hardware import check_hardware, format_table

    try:
        prep = load_prepared(args.config)
    except ConfigError as exc:
        return report_config_error(exc, "check-hardware")
    rows = check_hardware(prep.config, prep.layout, move_test=args.move_test)
    print(format_table(rows))
    if args.json is not None:
        write_json(
            args.json, {"ok": all(r.ok for r in rows), "devices": [asdict(r) for r in rows]}
        )
    ok = all(r.ok for r in rows)
    print("all checks passed" if ok else f"{sum(not r.ok for r in rows)} of {len(rows)} failed")
    return 0 if ok else 1


def cmd_schema(args: argparse.Namespace) -> int:
    from cell.config import schema

    text = json.dumps(schema(), indent=1)
    if args.out is not None:
        write_json(args.out, schema())
        print(f"wrote {args.out}")
    else:
        print(text)
    return 0


__all__ = ["add_parser", "load_prepared", "math"]
