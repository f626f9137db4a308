"""The 2F-85's register map and the unit conversions, in one place.

Both transports speak the same variables (the Modbus registers and the URCap socket's ``SET``/
``GET`` names are two spellings of one register map), so the driver works in these terms and each
transport only encodes them. Everything here is pure arithmetic: no I/O, easy to test.

Register map (Robotiq 2F-85/2F-140 instruction manual, section "Control"; each register holds two
bytes, high byte first):

==========  =========================================  ==========================================
register    high byte                                  low byte
==========  =========================================  ==========================================
0x03E8      ACTION REQUEST: rACT bit 0, rGTO bit 3,    reserved
            rATR bit 4, rARD bit 5
0x03E9      reserved                                   rPR position request (0 open .. 255 closed)
0x03EA      rSP speed (0 slowest .. 255 fastest)       rFR force (0 weakest .. 255 strongest)
0x07D0      GRIPPER STATUS: gACT bit 0, gGTO bit 3,    reserved
            gSTA bits 4-5, gOBJ bits 6-7
0x07D1      FAULT STATUS: gFLT bits 0-3, kFLT 4-7      gPR position request echo
0x07D2      gPO position (0..255)                      gCU finger current (x 10 mA)
==========  =========================================  ==========================================
"""

from __future__ import annotations

from dataclasses import dataclass

ACTION_ADDRESS = 0x03E8  #: first action-request register (written with function 16)
STATUS_ADDRESS = 0x07D0  #: first status register (read with function 4, also 3)
STATUS_REGISTERS = 3  #: status registers the driver reads (gripper status .. position, current)
DEFAULT_UNIT_ID = 9  #: the 2F-85's factory Modbus unit (slave) id
DEFAULT_BAUDRATE = 115200  #: the 2F-85's factory baud rate (8 data bits, no parity, 1 stop bit)
URCAP_PORT = 63352  #: the gripper URCap's socket on the UR controller

STROKE = 0.085  #: m, the 2F-85's largest opening between the pads
SPEED_MIN, SPEED_MAX = 0.020, 0.150  #: m/s, the speeds rSP 0 and 255 stand for
FORCE_MIN, FORCE_MAX = 20.0, 235.0  #: N, the grip forces rFR 0 and 255 stand for

# gSTA: activation status
STA_RESET, STA_ACTIVATING, STA_ACTIVE = 0, 1, 3
# gOBJ: object detection status (valid when gGTO = 1)
OBJ_MOVING, OBJ_STALLED_OPENING, OBJ_STALLED_CLOSING, OBJ_AT_POSITION = 0, 1, 2, 3

#: gFLT codes and what a person at the cell should read (wording after the manual's fault table)
FAULTS: dict[int, str] = {
    0x05: "action delayed: the activation (or reactivation) must complete first",
    0x07: "the activation bit must be set before a motion is requested",
    0x08: "maximum operating temperature exceeded (>= 85 C internally); let it cool below 80 C",
    0x09: "no communication for at least 1 s",
    0x0A: "under minimum operating voltage",
    0x0B: "automatic release in progress",
    0x0C: "internal fault; contact Robotiq support",
    0x0D: "activation fault: check for interference or another error, then reactivate",
    0x0E: "overcurrent triggered",
    0x0F: "automatic release completed; reset and reactivate",
}

STA_TEXT = {
    STA_RESET: "reset (or automatic release)",
    STA_ACTIVATING: "activation in progress",
    2: "not used",
    STA_ACTIVE: "activation completed",
}


def fault_text(code: int) -> str | None:
    """Readable text for a gFLT code, or None for 0 (no fault). Unknown codes are still named."""
    if code == 0:
        return None
    return f"fault 0x{code:02X}: {FAULTS.get(code, 'unknown fault code')}"


@dataclass(frozen=True)
class ActionRequest:
    """One write of the three action registers: what the gripper should do next."""

    act: bool  #: rACT: 1 activates, 0 resets (clears faults)
    gto: bool = False  #: rGTO: go to the requested position
    atr: bool = False  #: rATR: automatic release (emergency); never used by the cell
    position: int = 0  #: rPR 0..255 (0 open, 255 closed)
    speed: int = 0  #: rSP 0..255
    force: int = 0  #: rFR 0..255


@dataclass(frozen=True)
class GripperStatus:
    """The decoded status registers."""

    act: int  #: gACT
    gto: int  #: gGTO
    sta: int  #: gSTA
    obj: int  #: gOBJ
    flt: int  #: gFLT
    kflt: int  #: kFLT (controller fault nibble, shown in checks only)
    pr: int  #: gPR, the position request echo
    po: int  #: gPO, the position
    cu: int | None  #: gCU, the finger current (x 10 mA); None where not readable (URCap socket)

    @property
    def activated(self) -> bool:
        """gACT = 1 and gSTA = 3: the gripper accepts motion requests."""
        return self.act == 1 and self.sta == STA_ACTIVE


def _byte(value: int, name: str) -> int:
    value = int(value)
    if not 0 <= value <= 255:
        raise ValueError(f"{name} must be 0..255, got {value}")
    return value


def encode_request(req: ActionRequest) -> list[int]:
    """The three action registers (from 0x03E8) for ``req``."""
    action = int(req.act) | int(req.gto) << 3 | int(req.atr) << 4
    return [
        action << 8,
        _byte(req.position, "position"),
        _byte(req.speed, "speed") << 8 | _byte(req.force, "force"),
    ]


def decode_request(registers: list[int]) -> ActionRequest:
    """Inverse of :func:`encode_request` (used by the test peers and for logging)."""
    action = registers[0] >> 8
    return ActionRequest(
        act=bool(action & 1),
        gto=bool(action >> 3 & 1),
        atr=bool(action >> 4 & 1),
        position=registers[1] & 0xFF,
        speed=registers[2] >> 8,
        force=registers[2] & 0xFF,
    )


def encode_status(st: GripperStatus) -> list[int]:
    """The three status registers (from 0x07D0) for ``st`` (used by the test peers)."""
    status = st.act & 1 | (st.gto & 1) << 3 | (st.sta & 3) << 4 | (st.obj & 3) << 6
    return [status << 8, ((st.kflt & 0xF) << 4 | st.flt & 0xF) << 8 | st.pr & 0xFF,
            (st.po & 0xFF) << 8 | (st.cu or 0) & 0xFF]


def decode_status(registers: list[int]) -> GripperStatus:
    """Decode the three status registers read from 0x07D0."""
    if len(registers) < STATUS_REGISTERS:
        raise ValueError(f"need {STATUS_REGISTERS} status registers, got {len(registers)}")
    status = registers[0] >> 8
    fault = registers[1] >> 8
    return GripperStatus(
        act=status & 1,
        gto=status >> 3 & 1,
        sta=status >> 4 & 3,
        obj=status >> 6 & 3,
        flt=fault & 0xF,
        kflt=fault >> 4 & 0xF,
        pr=registers[1] & 0xFF,
        po=registers[2] >> 8,
        cu=registers[2] & 0xFF,
    )


@dataclass(frozen=True)
class Calibration:
    """Where the fingers really stop: the position counts (gPO) of full opening and closing.

    The 2F-85 does not use the whole 0..255 range (its software limits stop the fingers a few
    counts inside it), and each unit differs a little, so width conversions go through the
    counts measured on this unit (:meth:`Robotiq2F85.calibrate`). The defaults are the nominal
    range; without calibration widths can be off by a few millimetres near the ends.
    """

    open_count: int = 0
    closed_count: int = 255
    stroke: float = STROKE

    def __post_init__(self) -> None:
        if not 0 <= self.open_count < self.closed_count <= 255:
            raise ValueError(
                f"need 0 <= open_count < closed_count <= 255, got {self.open_count}, "
                f"{self.closed_count}"
            )

    def width(self, count: int) -> float:
        """Opening (m) at position count ``count``, clipped to 0..stroke."""
        frac = (self.closed_count - count) / (self.closed_count - self.open_count)
        return min(max(frac, 0.0), 1.0) * self.stroke

    def count(self, width: float) -> int:
        """Position request for an opening of ``width`` (m). Full opening asks for 0 and full
        closing for 255, so the fingers go to their limits whatever the calibration."""
        if width >= self.stroke:
            return 0
        if width <= 0.0:
            return 255
        c = self.closed_count - width / self.stroke * (self.closed_count - self.open_count)
        return int(min(max(round(c), 0), 255))


def speed_count(speed: float) -> int:
    """rSP for a finger speed (m/s): 20..150 mm/s onto 0..255, clipped."""
    frac = (speed - SPEED_MIN) / (SPEED_MAX - SPEED_MIN)
    return int(round(min(max(frac, 0.0), 1.0) * 255))


def force_count(force: float) -> int:
    """rFR for a grip force (N): 20..235 N onto 0..255, clipped."""
    frac = (force - FORCE_MIN) / (FORCE_MAX - FORCE_MIN)
    return int(round(min(max(frac, 0.0), 1.0) * 255))


def count_speed(count: int) -> float:
    """Finger speed (m/s) rSP ``count`` stands for."""
    return SPEED_MIN + count / 255 * (SPEED_MAX - SPEED_MIN)


def count_force(count: int) -> float:
    """Grip force (N) rFR ``count`` stands for."""
    return FORCE_MIN + count / 255 * (FORCE_MAX - FORCE_MIN)
