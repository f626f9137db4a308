"""The Robotiq 2F-85 driver: the :class:`drivers.gripper.Gripper` interface over Modbus RTU or
the gripper URCap's socket on the UR controller.

Import this package only on the hardware path: it imports pymodbus (the twin needs none of it).
:func:`make_gripper` builds the driver from the configuration's plain values.
"""

from __future__ import annotations

from drivers.robotiq_gripper.gripper import Robotiq2F85
from drivers.robotiq_gripper.modbus_rtu import ModbusRtuTransport
from drivers.robotiq_gripper.registers import (
    DEFAULT_BAUDRATE,
    DEFAULT_UNIT_ID,
    URCAP_PORT,
    Calibration,
    GripperStatus,
    fault_text,
)
from drivers.robotiq_gripper.transport import GripperTransport
from drivers.robotiq_gripper.urcap import UrcapSocketTransport

__all__ = [
    "Calibration",
    "GripperStatus",
    "GripperTransport",
    "ModbusRtuTransport",
    "Robotiq2F85",
    "UrcapSocketTransport",
    "fault_text",
    "make_gripper",
]


def make_gripper(
    transport: str = "modbus-rtu",
    *,
    port: str = "/dev/ttyUSB0",
    unit_id: int = DEFAULT_UNIT_ID,
    baudrate: int = DEFAULT_BAUDRATE,
    host: str = "",
    urcap_port: int = URCAP_PORT,
    timeout: float | None = None,
    retries: int = 2,
    open_count: int = 0,
    closed_count: int = 255,
    poll_hz: float | None = None,
    stale_after: float = 0.5,
) -> Robotiq2F85:
    """A (not yet started) :class:`Robotiq2F85` for ``transport`` "modbus-rtu" (``port``,
    ``unit_id``, ``baudrate``) or "urcap-socket" (``host``, ``urcap_port``).

    Defaults per transport: timeout 0.1 s and 50 Hz polling on the serial line; 0.5 s and 25 Hz
    on the socket (each status there is seven request/reply round trips).
    """
    calibration = Calibration(open_count, closed_count)
    link: GripperTransport
    if transport == "modbus-rtu":
        link = ModbusRtuTransport(port, unit_id=unit_id, baudrate=baudrate,
                                  timeout=0.1 if timeout is None else timeout, retries=retries)
        hz = 50.0 if poll_hz is None else poll_hz
    elif transport == "urcap-socket":
        if not host:
            raise ValueError("the urcap-socket transport needs host (the UR controller)")
        link = UrcapSocketTransport(host, urcap_port, timeout=0.5 if timeout is None else timeout,
                                    retries=retries)
        hz = 25.0 if poll_hz is None else poll_hz
    else:
        raise ValueError(f"unknown gripper transport {transport!r}; valid: modbus-rtu, "
                         "urcap-socket")
    return Robotiq2F85(link, calibration, poll_hz=hz, stale_after=stale_after)
