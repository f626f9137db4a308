"""The 2F-85 over Modbus RTU on its RS-485 link (USB adapter), through pymodbus's serial client.

What the real gripper uses (Robotiq 2F-85/2F-140 manual, Modbus RTU examples): function 16
(write multiple registers) for the three action registers from 0x03E8, and function 4 (read input
registers) for the status from 0x07D0; the manual also shows function 3 (read holding registers)
on the same addresses, so ``status_function=3`` is offered for gateways that only pass 3.
Unit id 9, 115200 baud, 8N1.

pymodbus's own retries are switched off (``retries=0``) so that :func:`with_retries` alone decides
how often a request is repeated and how long to back off in between.

pymodbus 3.10 or newer is required, and checked when the transport is built: the unit is passed as
``device_id=``, which older 3.x releases do not know. pymodbus 3.6 swallows the unknown keyword and
addresses unit 0, the broadcast (every write executed by every device on the line, never
answered); 3.9 raises TypeError in the status thread. Either way the only symptom would be a
stale status, so an older pymodbus is refused by name instead.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable

import pymodbus
from pymodbus.client import ModbusSerialClient
from pymodbus.exceptions import ConnectionException, ModbusException

from drivers.health import DeviceError
from drivers.robotiq_gripper.registers import (
    ACTION_ADDRESS,
    DEFAULT_BAUDRATE,
    DEFAULT_UNIT_ID,
    STATUS_ADDRESS,
    STATUS_REGISTERS,
    ActionRequest,
    GripperStatus,
    decode_status,
    encode_request,
)
from drivers.robotiq_gripper.transport import DEVICE, TransientError, with_retries

PYMODBUS_MIN = (3, 10)  #: the first pymodbus whose client calls take ``device_id=``


def _version(text: str) -> tuple[int, int]:
    """Major and minor of a version string ("3.9.2" -> (3, 9), "3.10.0rc1" -> (3, 10));
    (0, 0) when it has none."""
    m = re.match(r"(\d+)\.(\d+)", text)
    return (int(m.group(1)), int(m.group(2))) if m else (0, 0)


class ModbusRtuTransport:
    """:class:`GripperTransport` over Modbus RTU (pymodbus ``ModbusSerialClient``).

    ``port``: serial device (``/dev/ttyUSB0``; pyserial URLs such as ``socket://host:port`` also
    work, for RTU through a serial-to-Ethernet converter); ``unit_id``: the gripper's Modbus id;
    ``timeout``: s to wait for one answer (the gripper answers within a few ms); ``retries``:
    extra tries after a timeout; ``backoff_first``: s before the first retry (doubling).
    Thread-safe: one lock serialises the requests on the line.
    """

    kind = "modbus-rtu"

    def __init__(
        self,
        port: str,
        unit_id: int = DEFAULT_UNIT_ID,
        baudrate: int = DEFAULT_BAUDRATE,
        timeout: float = 0.1,
        retries: int = 2,
        backoff_first: float = 0.05,
        status_function: int = 4,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if status_function not in (3, 4):
            raise ValueError(f"status_function must be 3 or 4, got {status_function}")
        if not 1 <= unit_id <= 247:
            raise ValueError(f"unit_id must be 1..247, got {unit_id}")
        self.port, self.unit_id, self.baudrate = port, unit_id, baudrate
        self.timeout, self.retries, self.backoff_first = timeout, retries, backoff_first
        self.status_function = status_function
        self.address = f"{port} unit {unit_id} ({baudrate} baud)"
        found = getattr(pymodbus, "__version__", "0")
        if _version(found) < PYMODBUS_MIN:
            need = ".".join(map(str, PYMODBUS_MIN))
            raise DeviceError(DEVICE, self.address,
                              f"pymodbus {found} is too old: this driver needs pymodbus >= {need} "
                              f"(older releases do not address the unit; pip install "
                              f"'pymodbus>={need},<4')")
        self._sleep = sleep
        self._lock = threading.Lock()
        self._client = ModbusSerialClient(
            port,
            baudrate=baudrate,
            bytesize=8,
            parity="N",
            stopbits=1,
            timeout=timeout,
            retries=0,
            name="robotiq-2f85",
        )

    def connect(self) -> None:
        """Open the serial port; a missing or busy port is a :class:`DeviceError` at once."""
        with self._lock:
            self._open()

    def _open(self) -> None:
        if self._client.connected:
            return
        if not self._client.connect():
            raise DeviceError(DEVICE, self.address, f"cannot open serial port {self.port}")

    def write_request(self, request: ActionRequest) -> None:
        """Write the three action registers with function 16."""
        values = encode_request(request)

        def op() -> None:
            self._call(
                lambda: self._client.write_registers(
                    ACTION_ADDRESS, values, device_id=self.unit_id
                ),
                "write 0x03E8",
            )

        with self._lock:
            self._open()
            with_retries(op, "no answer to the action request", self.address, self.retries,
                         self.backoff_first, self._sleep)

    def read_status(self) -> GripperStatus:
        """Read the three status registers from 0x07D0 with function 4 (or 3)."""
        read = (self._client.read_input_registers if self.status_function == 4
                else self._client.read_holding_registers)

        def op() -> list[int]:
            rr = self._call(
                lambda: read(STATUS_ADDRESS, count=STATUS_REGISTERS, device_id=self.unit_id),
                "read 0x07D0",
            )
            return list(rr.registers)

        with self._lock:
            self._open()
            regs = with_retries(op, "no answer to the status request", self.address,
                                self.retries, self.backoff_first, self._sleep)
        return decode_status(regs)

    def _call(self, request: Callable[[], object], what: str):  # noqa: ANN202 - pymodbus PDU
        """One request: a timeout or lost port is transient, an exception reply is final."""
        try:
            rr = request()
        except ConnectionException as exc:
            raise TransientError(f"{what}: link error ({exc})") from exc
        except ModbusException as exc:  # ModbusIOException: no (valid) answer in time
            raise TransientError(f"{what}: no answer within {self.timeout} s") from exc
        if rr.isError():  # type: ignore[attr-defined]
            code = getattr(rr, "exception_code", "?")
            raise DeviceError(DEVICE, self.address, f"{what}: Modbus exception reply {code}")
        return rr

    def close(self) -> None:
        """Close the serial port."""
        with self._lock:
            self._client.close()
