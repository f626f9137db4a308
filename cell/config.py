"""The cell's YAML task configuration, validated once into typed, frozen objects.

Why pydantic: one declaration gives the checks (types, ranges, unknown keys), the typed object the
code uses and the JSON Schema editors use (``cell schema``); a hand-written validator would keep
three copies of the same facts. Numbers are SI; the unit is in every key's name (``_s``, ``_n``,
``_m``, ``_hz``) and a string such as ``"5 mm"`` where a number is expected is refused, not parsed.

Every error reads ``file:line: key: reason``. Validation ends before anything is built, so a
configuration that fails never reaches a driver.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    create_model,
    field_validator,
    model_validator,
)

from drivers.gripper_spec import DEFAULT_GRIPPER, GripperSpec, GripperSpecError, load_gripper
from drivers.ur5.arm import SERVO_GAIN, SERVO_LOOKAHEAD
from skills.motion import (
    DEFAULT_MAX_FORCE,
    DEFAULT_MAX_TORQUE,
    MAX_FORCE_LIMIT,
    MAX_TORQUE_LIMIT,
)
from skills.params import apply_config, config_keys
from trees.context import SECTION_DOCS, SKILL_SECTIONS
from trees.yaml_lines import ConfigError, LinedDocument, load_yaml, parse_yaml


class _Section(BaseModel):
    # strict: no "5" -> 5 or "true" -> True coercion; a wrong type is an error the user sees.
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class CellSection(_Section):
    """What the cell is and which backend runs it."""

    name: str = Field("bushing-machining", description="a name for logs and the state file")
    backend: Literal["sim", "hw"] = Field(
        "sim", description="sim: the PyBullet twin; hw: the real UR5, 2F-85, FT300 and D435"
    )
    control_hz: float = Field(125.0, ge=10.0, le=500.0, description="tick rate of the tree (Hz)")
    tick_niceness: int = Field(
        -5, ge=-20, le=19, description="the nice value of the tick loop's thread in paced runs "
        "(`cell run`, `sim.realtime`): lower runs first; where the process may not raise it, it "
        "runs as it is and the run's JSON says so; 0 leaves it unchanged"
    )
    catalogue: str | None = Field(
        None, description="part catalogue YAML (relative to this file); default: the shipped one"
    )
    layout: dict[str, Any] = Field(
        default_factory=dict,
        description="cell geometry overrides (m, rad), the keys of `cell pivot --cell`; "
        "see docs/commands.md, 'Cell layout (YAML)'",
    )


class SimSection(_Section):
    """The twin: what lies in the bin and how the physics runs."""

    seed: int = Field(0, ge=0, description="seed of the bin scene and the perturbations")
    yaw_spread_deg: float = Field(
        3.0, ge=0.0, le=45.0, description="spawned parts' yaw spread about the radial direction"
    )
    mu_ground: float = Field(0.4, gt=0.0, le=2.0, description="part-floor friction")
    realtime: bool = Field(False, description="pace the twin to wall time (for watching)")
    servoj: bool = Field(
        True,
        description="the twin's arm follows streamed targets by UR's servoj law with "
        "devices.arm.servo_lookahead_s and servo_gain, as a UR does (false: each target within "
        "the control step, for debugging)",
    )


class BinSection(_Section):
    """What lies in the bin at the start, and how a person fills it (the twin's bin)."""

    fill: Literal["rows", "random"] = Field(
        "rows",
        description="rows: lying along the radial direction where the pivot reaches (staged); "
        "random: tipped in from random poses and left where physics settles them",
    )
    parts: int = Field(
        8,
        ge=0,
        le=30,
        description="parts in the bin at the start and at each refill (rows: at most what the "
        "rows hold: 8 in the default layout, 10 in the example's wider bin)",
    )


class ArmDevice(_Section):
    host: str = Field("192.168.1.10", min_length=1, description="UR controller address")
    rtde_frequency_hz: float = Field(
        125.0, ge=10.0, le=500.0, description="RTDE rate: 125 on a CB3, up to 500 on e-Series"
    )
    connect_timeout_s: float = Field(
        5.0, gt=0.0, le=60.0, description="dashboard server (TCP 29999) reply timeout"
    )
    watchdog_hz: float | None = Field(
        10.0, gt=0.0, le=500.0,
        description="arm ur_rtde's watchdog once the ticks start: the controller stops the "
        "control script (and the arm) when the cell has not polled it for 1/hz s -- a dead "
        "process, a lost link, a stalled loop. null turns it off. At 10 Hz the emulated "
        "cell's longest tick in three cycles was 36.2 ms (docs/emulator.md)",
    )
    servo_lookahead_s: float = Field(
        SERVO_LOOKAHEAD, ge=0.03, le=0.2,
        description="servoj's lookahead time for each streamed target (UR's range): the arm "
        "trails the stream by about this much; the twin's arm follows the same law",
    )
    servo_gain: float = Field(
        SERVO_GAIN, ge=100.0, le=2000.0,
        description="servoj's proportional gain, 1/s^2 (UR's range); the twin's arm uses it too",
    )
    home_joints_deg: list[float] = Field(
        default_factory=lambda: [167.39, -89.5, 82.82, -83.32, -90.0, -102.61],
        min_length=6,
        max_length=6,
        description="home joint angles (deg, base to wrist 3; the TCP 0.5 m in front, 0.3 m up, "
        "tool down); reached by a joint move, which also unwinds the wrist",
    )

    @field_validator("home_joints_deg")
    @classmethod
    def _within_limits(cls, value: list[float]) -> list[float]:
        for i, q in enumerate(value):
            if not (math.isfinite(q) and -360.0 <= q <= 360.0):
                raise ValueError(f"joint {i + 1}: {q} deg is outside the UR5's +-360 deg")
        return value


class GripperDevice(_Section):
    transport: Literal["modbus", "urcap"] = Field(
        "modbus",
        description="modbus: Modbus RTU on the gripper's serial line; urcap: the Robotiq URCap "
        "socket on the UR controller (devices.arm.host)",
    )
    port: str = Field("/dev/ttyUSB0", min_length=1, description="2F-85 Modbus RTU serial port")
    baudrate: int = Field(115200, ge=1200, le=1000000)
    slave_id: int = Field(9, ge=1, le=247, description="Modbus unit id")
    urcap_port: int = Field(63352, ge=1, le=65535, description="URCap socket port")
    timeout_s: float = Field(0.5, gt=0.0, le=10.0, description="per request")
    open_count: int | None = Field(
        None, ge=0, le=255,
        description="this unit's position count (gPO) fully open; with closed_count the "
        "width calibration; null: measured at start-up (the fingers close and open)",
    )
    closed_count: int | None = Field(
        None, ge=0, le=255, description="this unit's position count (gPO) fully closed",
    )

    @model_validator(mode="after")
    def _both_counts(self) -> GripperDevice:
        if (self.open_count is None) != (self.closed_count is None):
            raise ValueError("open_count and closed_count go together (both, or neither)")
        if self.open_count is not None and not self.open_count < self.closed_count:  # type: ignore[operator]
            raise ValueError("open_count must be below closed_count")
        return self


class FTDevice(_Section):
    port: str = Field(
        "/dev/ttyUSB1",
        min_length=1,
        description="FT300 serial port, or socket://HOST:PORT for a serial device server's raw "
        "TCP port",
    )
    baudrate: int = Field(19200, ge=1200, le=1000000)
    slave_id: int = Field(9, ge=1, le=247, description="Modbus unit id (stream start)")
    stale_after_s: float = Field(
        0.05,
        gt=0.0,
        le=5.0,
        description="a sample older than this is an error (the FT300 streams at 100 Hz)",
    )


class CameraDevice(_Section):
    serial: str | None = Field(None, description="D435 serial number (None: the only one)")
    width: int = Field(640, ge=64, le=1920)
    height: int = Field(480, ge=48, le=1080)
    fps: int = Field(30, ge=1, le=90)
    timeout_ms: int = Field(1000, ge=10, le=30000, description="a frame must arrive within")
    stream: str | None = Field(
        None,
        description="host:port of a D435 frame stream (the emulator's, `cell emulate`) instead "
        "of the USB camera; width, height and fps then come from the stream",
    )

    @field_validator("stream")
    @classmethod
    def _host_port(cls, value: str | None) -> str | None:
        if value is None:
            return value
        host, _, port = value.rpartition(":")
        if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
            raise ValueError(f"{value!r} is not host:port (port 1..65535)")
        return value


class DevicesSection(_Section):
    """The real devices (read only when ``cell.backend`` is ``hw``; the twin reads
    ``devices.arm``'s servo law where ``sim.servoj`` asks it to move as the UR does)."""

    arm: ArmDevice = Field(default_factory=ArmDevice)
    gripper: GripperDevice = Field(default_factory=GripperDevice)
    ft: FTDevice = Field(default_factory=FTDevice)
    camera: CameraDevice = Field(default_factory=CameraDevice)


class WorkflowSection(_Section):
    """The bushing-machining workflow of the paper's Section I."""

    part: str = Field("bushing", description="catalogue part the cell handles")
    cycles: int = Field(
        10,
        ge=1,
        le=100000,
        description="cycles to run (pick, feed, machine, pack); also `cell sim --cycles`",
    )
    machining_time_s: float = Field(5.0, ge=0.0, le=3600.0)
    max_failures_per_part: int = Field(
        2, ge=1, le=10, description="a part that failed this many picks is skipped"
    )
    pick_order: Literal["nearest", "freest"] = Field(
        "nearest",
        description="nearest: the part nearest the robot first; freest: the part with the most "
        "room to its neighbours and the walls first (for a bin tipped full)",
    )
    max_failed_cycles: int = Field(
        3, ge=1, le=100, description="consecutive cycles without a pick before the cell stops"
    )


class SafetySection(_Section):
    """The cell's force-torque abort limits: of every motion leaf whose tree node gives none,
    both for the FT guard around the leaf and for every motion of its skill."""

    ft_abort_force_n: float = Field(
        DEFAULT_MAX_FORCE, gt=0.0, le=MAX_FORCE_LIMIT,
        description="|F| at the wrist that stops a motion (N)"
    )
    ft_abort_torque_nm: float = Field(
        DEFAULT_MAX_TORQUE,
        gt=0.0,
        le=MAX_TORQUE_LIMIT,
        description="|T| at the wrist that stops a motion (N*m)",
    )
    default_timeout_s: float = Field(
        30.0, gt=0.0, le=600.0, description="the longest a motion leaf of the tree may run (s)"
    )
    ft_settle_s: float = Field(
        0.5,
        ge=0.0,
        le=5.0,
        description="a motion about to start waits this long for a wrench over its limits to "
        "fall back (a spike of a few samples) before its guard fails it (s)",
    )
    ft_link_grace_s: float = Field(
        0.5,
        ge=0.0,
        le=5.0,
        description="a lost force-torque stream stops every motion at once; if it is back "
        "within this time the cell goes on (retries), else it stops for a person (0: stop at "
        "once)",
    )


class LogSection(_Section):
    tick_log: str | None = Field(
        "out/cell_ticks.jsonl",
        description="JSONL tick log; every output path is relative to the folder `cell` runs "
        "in (paths the configuration reads are relative to the configuration)",
    )
    state_file: str | None = Field(
        "out/cell_state.json", description="the cell's state, saved after each cycle and on exit"
    )
    journal: str | None = Field(
        "out/cell_journal.sqlite",
        description="crash-safe journal (SQLite, WAL) of every workflow event; `--resume` "
        "continues from it; a fresh run keeps the last 5 earlier journals (NAME.1 newest)",
    )
    frames: bool = Field(
        True,
        description="keep each camera frame (JPEG, 320 px wide) beside the tick log, for "
        "`cell replay --serve`",
    )
    wrench_deadband_n: float = Field(
        1.0,
        ge=0.0,
        le=50.0,
        description="the tick log writes the wrench when a force component moved more than this",
    )
    wrench_deadband_nm: float = Field(
        0.1, ge=0.0, le=5.0, description="likewise for a torque component"
    )


def _rate(what: str) -> Any:
    return Field(0.0, ge=0.0, le=1.0, description=f"probability per {what}")


class FaultRates(_Section):
    """Fault rates of the twin (``sim/faults.py``): each the probability that the fault happens
    at one opportunity of its kind. One field per fault, so an unknown name is an error."""

    missed_grasp: float = _rate("gripper close command (it is not executed)")
    slip_in_tilt: float = _rate("Tilt (finger friction drops briefly; the part slips)")
    drop_in_transit: float = _rate("carry between stations (the jaws open; the part falls)")
    ft_spike: float = _rate("arm motion command (150-300 N for 1-3 samples)")
    camera_lost: float = _rate("capture (TimeoutError)")
    camera_invalid: float = _rate("capture (all-zero depth)")
    gripper_fault: float = _rate("gripper command (fault() reports a code for 0.3-2 s)")
    protective_stop: float = _rate("arm motion command (the arm faults, protective_stop=True)")
    link_lost: float = _rate("arm motion command (the FT sensor raises DeviceError 5-50 samples)")


class FaultsSection(_Section):
    """Fault injection in the twin (`cell soak`; ignored on hardware)."""

    enabled: bool = Field(False, description="inject the faults at `rates`")
    seed: int = Field(0, ge=0, description="seed of the faults' generator")
    rates: FaultRates = Field(default_factory=FaultRates)


class EmulatedFault(_Section):
    """One fault `cell emulate` puts on the wire, on a schedule."""

    device: Literal["arm", "gripper", "ft", "camera"] = Field(
        description="whose cable: arm (every UR socket), gripper (its serial line and the "
        "URCap socket), ft (the sensor's cable, power included), camera (frames freeze)"
    )
    fault: Literal["cable", "protective_stop", "force_step"] = Field(
        "cable", description="cable: pull the cable; protective_stop: the arm's (arm only); "
        "force_step: a load step on the wrist sensor (ft only), as a collision reads"
    )
    at_s: float = Field(
        ge=0.0, description="when: seconds of the emulated controller's time after the arm "
        "first moved"
    )
    mid_motion: bool = Field(
        True, description="wait from at_s until the arm is moving, then pull"
    )
    duration_s: float | None = Field(
        None, gt=0.0, description="plug the cable back after this long (null: only SIGUSR1 or "
        "a restart of the emulator brings it back); a force step lasts this long (null: 0.5 s)"
    )
    force_n: float = Field(
        150.0, gt=0.0, le=1000.0, description="force_step: the step's size (N, along the "
        "sensor's +z, against the tool's approach); more than the running motion's limit"
    )


class EmulateSection(_Section):
    """`cell emulate`: the emulators' own settings (the devices' addresses are `devices`)."""

    camera_width: int = Field(
        424, ge=64, le=1920, description="the emulated D435's frame width (px)"
    )
    camera_height: int = Field(
        240, ge=48, le=1080, description="the emulated D435's frame height (px)"
    )
    camera_fps: int = Field(
        6, ge=1, le=90, description="frames a second the emulated D435 renders and sends"
    )
    faults: list[EmulatedFault] = Field(
        default_factory=list, description="faults on the wire, each once, on a schedule"
    )
    step_niceness: int = Field(
        -10, ge=-20, le=19, description="the nice value of the thread that steps the twin "
        "(lower runs first; where the process may not raise it, it runs as it is and the "
        "report says so; 0 leaves it unchanged)"
    )

    @field_validator("faults")
    @classmethod
    def _arm_only_stop(cls, value: list[EmulatedFault]) -> list[EmulatedFault]:
        for i, f in enumerate(value):
            if f.fault == "protective_stop" and f.device != "arm":
                raise ValueError(f"fault {i}: a protective stop is the arm's, not the "
                                 f"{f.device}'s")
            if f.fault == "force_step" and f.device != "ft":
                raise ValueError(f"fault {i}: a force step is on the wrist sensor (device: "
                                 f"ft), not the {f.device}'s")
        return value


def _shown(value: float) -> float:
    return float(f"{value:.12g}")  # 4 deg, not 4.000000000000001


def _skill_section_model(name: str, params: type) -> type[BaseModel]:
    fields: dict[str, Any] = {}
    for k in config_keys(params):
        fields[k.key] = (
            float,
            Field(
                _shown(k.shown(k.default)),
                ge=_shown(k.shown(k.low)),
                le=_shown(k.shown(k.high)),
                description=f"{k.doc} ({k.shown_unit})",
            ),
        )
    model = create_model(  # type: ignore[call-overload]
        f"Skills{''.join(w.title() for w in name.split('_'))}Section",
        __base__=_Section,
        __doc__=f"skills.{name}: {SECTION_DOCS[name]}",
        **fields,
    )
    return model  # type: ignore[no-any-return]


#: One model per skill section, generated from the skill's parameter dataclass: the defaults,
#: ranges and units written there are the only copy.
SkillsSection: type[BaseModel] = create_model(  # type: ignore[call-overload]
    "SkillsSection",
    __base__=_Section,
    __doc__="Each skill's parameters (SI, unit in the key's name, angles in degrees); a tree "
    "node of that skill may override any of them",
    **{
        name: (model, Field(default_factory=model))
        for name, model in (
            (name, _skill_section_model(name, cls)) for name, cls in SKILL_SECTIONS.items()
        )
    },
)


class CellConfig(_Section):
    """The whole task configuration. ``tree`` is a behaviour spec or ``{file: PATH}``."""

    cell: CellSection = Field(default_factory=CellSection)
    sim: SimSection = Field(default_factory=SimSection)
    bin: BinSection = Field(default_factory=BinSection)
    devices: DevicesSection = Field(default_factory=DevicesSection)
    workflow: WorkflowSection = Field(default_factory=WorkflowSection)
    safety: SafetySection = Field(default_factory=SafetySection)
    skills: SkillsSection = Field(default_factory=SkillsSection)  # type: ignore[valid-type]
    log: LogSection = Field(default_factory=LogSection)
    faults: FaultsSection = Field(default_factory=FaultsSection)
    emulate: EmulateSection = Field(default_factory=EmulateSection)
    gripper: str = Field(
        DEFAULT_GRIPPER,
        description="the gripper's description: a shipped name (robotiq_2f85, gentle_wire) or "
        "the path of a description .yaml relative to this file; the twin, the emulator and the "
        "driver use it, and every gripper force and speed of the skills must lie in its ranges",
    )
    tree: dict[str, Any] = Field(
        default_factory=lambda: {"file": "trees/bushing_machining.yaml"},
        description="the behaviour tree: a node spec, or {file: PATH} relative to this file "
        "(default: the shipped bushing-machining tree)",
    )

    @field_validator("tree")
    @classmethod
    def _tree_not_empty(cls, value: dict[str, Any]) -> dict[str, Any]:
        if not value:
            raise ValueError("must be a behaviour spec or {file: PATH}")
        return value


def default_config_path() -> Path:
    """The example configuration shipped with the package (`cell sim` without --config)."""
    return Path(__file__).resolve().parent / "data" / "bushing_cell.yaml"


def _reason(err: dict[str, Any]) -> str:
    kind, msg = err.get("type", ""), err.get("msg", "")
    value = err.get("input")
    if kind == "extra_forbidden":
        return "unknown key"
    if kind in ("float_type", "int_type", "float_parsing", "int_parsing") and isinstance(
        value, str
    ):
        return (
            f"expected a number, got the text {value!r}; numbers are SI and the unit is in "
            "the key's name"
        )
    if kind == "missing":
        return "missing"
    return f"{msg}, got {value!r}" if "input" in err and not isinstance(value, dict) else msg


def _valid_keys(model: type[BaseModel], loc: tuple[Any, ...]) -> list[str] | None:
    """The keys allowed where an unknown key ``loc`` was found, for the error message."""
    current: Any = model
    for part in loc[:-1]:
        if not (isinstance(current, type) and issubclass(current, BaseModel)):
            return None
        field = current.model_fields.get(str(part))
        if field is None:
            return None
        current = field.annotation
    if isinstance(current, type) and issubclass(current, BaseModel):
        return list(current.model_fields)
    return None


def validate_document(doc: LinedDocument) -> CellConfig:
    """Typed configuration from a loaded document; :class:`ConfigError` on the first problems.

    An empty file is refused: a configuration whose keys were lost (a file truncated, the
    wrong path) would otherwise drive the whole default cell. ``{}`` says "the defaults"."""
    if doc.data is None:
        raise ConfigError(
            doc.source, None, "",
            "the file is empty (no keys, only comments or blanks); write `{}` to run the "
            "shipped defaults",
        )
    data = doc.data
    if not isinstance(data, dict):
        raise ConfigError(doc.source, 1, "", "expected a mapping of sections at the top level")
    try:
        config = CellConfig.model_validate(data)
    except ValidationError as exc:
        messages = []
        for err in exc.errors():
            loc = tuple(err["loc"])
            reason = _reason(err)
            if err.get("type") == "extra_forbidden":
                keys = _valid_keys(CellConfig, loc)
                if keys:
                    reason += f"; valid keys: {', '.join(keys)}"
            messages.append(doc.error(loc, reason))
        first = messages[0]
        if len(messages) > 1:
            rest = "\n".join(str(m) for m in messages[1:])
            raise ConfigError(
                first.source, first.line, first.key, f"{first.reason}\n{rest}"
            ) from None
        raise first from None
    for key in ("ft_abort_force_n", "ft_abort_torque_nm"):
        if not math.isfinite(getattr(config.safety, key)):
            raise doc.error(("safety", key), "must be finite")
    check_actuators(config, doc, gripper_of(config, doc))
    return config


def _base_dir(doc: LinedDocument) -> Path:
    """Where the configuration's relative paths start: its file's folder (else here)."""
    source = Path(doc.source)
    return source.resolve().parent if source.is_file() else Path.cwd()


def twin_servo(config: CellConfig) -> tuple[float, float] | None:
    """servoj's (lookahead s, gain) the twin's arm follows its stream by: devices.arm's, where
    ``sim.servoj`` asks the twin to move as the UR does; None (each target within the step)
    otherwise."""
    if not config.sim.servoj:
        return None
    arm = config.devices.arm
    return (arm.servo_lookahead_s, arm.servo_gain)


def gripper_of(config: CellConfig, doc: LinedDocument) -> GripperSpec:
    """The configured gripper's description; :class:`ConfigError` at ``gripper`` if it cannot
    be read."""
    try:
        return load_gripper(config.gripper, _base_dir(doc))
    except GripperSpecError as exc:
        where = f"its key {exc.key}: " if exc.key else ""
        raise doc.error(("gripper",), f"{where}{exc.reason}") from None


#: What each actuator tag of a skill parameter (:func:`skills.params.si`) must lie within:
#: the description's range (SI), and the name a person knows it by.
_ACTUATOR_RANGES = {
    "grip_force": (lambda g: (g.force_min, g.force_max), "grip force per finger"),
    "finger_speed": (lambda g: (g.speed_min, g.speed_max), "finger speed"),
}


def check_actuators(config: CellConfig, doc: LinedDocument, gripper: GripperSpec) -> None:
    """Refuse every skill value that commands the gripper outside what the unit can do.

    Why here: every command that reads a configuration validates it through this module, so a
    force or speed the gripper cannot make stops the run before a twin or a device opens. A
    real unit would clamp it (a 2F-85 asked for 2 N grips with 20 N) while the configuration and
    the log said otherwise; a refusal says so instead."""
    for name, cls in SKILL_SECTIONS.items():
        section = getattr(config.skills, name)
        for key in config_keys(cls):
            if key.actuator is not None:
                reason = actuator_problem(key, float(getattr(section, key.key)), gripper)
                if reason:
                    raise doc.error(("skills", name, key.key), reason)


def actuator_problem(key: Any, configured: float, gripper: GripperSpec) -> str | None:
    """Why ``configured`` (as the YAML has it) for ``key`` (a :class:`skills.params.ConfigKey`
    with an actuator tag) is beyond ``gripper``; None when it is within."""
    bounds, what = _ACTUATOR_RANGES[key.actuator]
    low, high = bounds(gripper)
    value = configured * key.scale
    if low - 1e-9 <= value <= high + 1e-9:
        return None
    shown = key.shown
    return (
        f"{shown(value):g} is outside the {what} of the gripper {gripper.name!r}, "
        f"{shown(low):g}..{shown(high):g} {key.shown_unit} (the unit would not do what is "
        "asked); set it in that range or name another gripper description (key 'gripper')"
    )


def check_tree_actuators(spec: Any, doc: LinedDocument, path: tuple[Any, ...],
                         gripper: GripperSpec) -> None:
    """The same refusal for a tree node's own overrides of a skill's gripper values."""
    from trees.registry import REGISTRY

    if isinstance(spec, list):
        for i, child in enumerate(spec):
            check_tree_actuators(child, doc, (*path, i), gripper)
        return
    if not isinstance(spec, dict):
        return
    node = REGISTRY.get(spec.get("type")) if isinstance(spec.get("type"), str) else None
    section = node.section if node is not None else None
    if section is not None:
        for key in config_keys(SKILL_SECTIONS[section]):
            if key.actuator is not None and isinstance(spec.get(key.key), (int, float)):
                reason = actuator_problem(key, float(spec[key.key]), gripper)
                if reason:
                    raise doc.error((*path, key.key), reason)
    for name, value in spec.items():
        if isinstance(value, (dict, list)):
            check_tree_actuators(value, doc, (*path, name), gripper)


def skill_settings(
    config: CellConfig, slot_depth: float | None = None, gripper: Any = None
) -> dict[str, Any]:
    """Each skill section's parameters (SI) as configured; the pivot's are the configured values
    alone (``apply_config`` them to a :class:`PivotParams` once ``l_a`` and ``alpha`` are planned).

    Some values are one fact of the cell, not a skill's: the hole grasp is one grasp (Align's
    ``wall_depth`` and the packing's ``grip_depth`` are the slot's ``grip_depth``), the pocket's
    depth is the layout's ``slot_depth`` (``slot_depth``; None: the skill's default), and the
    approach clearance and finger thickness are the planner's gripper model's (``gripper``, a
    :class:`drivers.parts.Gripper`; None: the skills' defaults)."""

    def values(name: str) -> dict[str, float]:
        return getattr(config.skills, name).model_dump(exclude_unset=True)

    slot = apply_config(SKILL_SECTIONS["slot"](), values("slot"))
    if slot_depth is not None:
        slot = dataclasses.replace(slot, slot_depth=slot_depth)
    pivot = dict(values("pivot"))
    settings: dict[str, Any] = {"slot": slot, "pivot": pivot}
    for name, cls in SKILL_SECTIONS.items():
        if name not in settings:
            base = cls(grip_depth=slot.grip_depth) if name == "pack_in_box" else cls()
            settings[name] = apply_config(base, values(name))
    fixed: dict[str, float] = {"wall_depth": slot.grip_depth}
    if gripper is not None:
        fixed |= {
            "approach_clearance": gripper.clearance,
            "finger_thickness": gripper.finger_thickness,
        }
    settings["pivot_fixed"] = fixed
    return settings


def skills_reference() -> str:
    """The ``skills:`` sections as Markdown tables, key by key (docs/configuration.md)."""
    out: list[str] = []
    for name, cls in SKILL_SECTIONS.items():
        out += [f"#### `skills.{name}`: {SECTION_DOCS[name]}", ""]
        out += ["| key | default | range | unit | meaning |", "| --- | --- | --- | --- | --- |"]
        for k in config_keys(cls):
            lo, hi, d = (_shown(k.shown(v)) for v in (k.low, k.high, k.default))
            out.append(
                f"| `skills.{name}.{k.key}` | {d:g} | {lo:g}..{hi:g} | {k.shown_unit} | {k.doc} |"
            )
        out.append("")
    return "\n".join(out)


def load_config(path: str | Path | None) -> tuple[CellConfig, LinedDocument]:
    """Read and validate a configuration file (None: the shipped example)."""
    doc = load_yaml(path if path is not None else default_config_path())
    return validate_document(doc), doc


def config_from_text(text: str, source: str = "<config>") -> tuple[CellConfig, LinedDocument]:
    doc = parse_yaml(text, source)
    return validate_document(doc), doc


def schema() -> dict[str, Any]:
    """The JSON Schema of the configuration, for editors (``cell schema``)."""
    return CellConfig.model_json_schema()


__all__ = [
    "CellConfig",
    "ConfigError",
    "config_from_text",
    "default_config_path",
    "load_config",
    "schema",
]
