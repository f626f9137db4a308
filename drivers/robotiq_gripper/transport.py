"""The small interface both transports offer, and their shared bounded-retry helper.

The driver only ever writes an :class:`ActionRequest` and reads a :class:`GripperStatus`, so a
transport is four methods. Every operation is tried a bounded number of times with back-off
(:func:`drivers.health.backoff_delays`) and then fails with a :class:`DeviceError` naming the
device, its address and the cause: a gripper that does not answer costs at most
``(retries + 1) * timeout`` plus the back-off, never a retry storm.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol, TypeVar, runtime_checkable

from drivers.health import DeviceError, backoff_delays
from drivers.robotiq_gripper.registers import ActionRequest, GripperStatus

DEVICE = "2F-85"  #: the device name in errors and check rows

T = TypeVar("T")


class TransientError(Exception):
    """A failure worth retrying (timeout, lost connection); anything else fails at once."""


@runtime_checkable
class GripperTransport(Protocol):
    """Moves action requests and status between the driver and the gripper."""

    address: str  #: where the gripper is, for messages ("/dev/ttyUSB0 unit 9", "host:63352")
    kind: str  #: "modbus-rtu" or "urcap-socket"

    def connect(self) -> None:
        """Open the link (port or socket); raises :class:`DeviceError` when it cannot."""
        ...

    def write_request(self, request: ActionRequest) -> None:
        """Send one action request; raises :class:`DeviceError` after bounded retries."""
        ...

    def read_status(self) -> GripperStatus:
        """Read the status; raises :class:`DeviceError` after bounded retries."""
        ...

    def close(self) -> None:
        """Close the link; safe to call twice."""
        ...


def with_retries(
    op: Callable[[], T],
    what: str,
    address: str,
    retries: int,
    backoff_first: float,
    sleep: Callable[[float], None] = time.sleep,
    on_retry: Callable[[], None] | None = None,
) -> T:
    """Run ``op`` up to ``retries + 1`` times, waiting the back-off between tries.

    Only :class:`TransientError` is retried (a Modbus exception reply is an answer: asking
    again would get the same one). ``on_retry`` runs before each new try (a socket transport
    reconnects there). Raises :class:`DeviceError` naming ``address`` and the last cause.
    """
    delays = backoff_delays(retries + 1, first=backoff_first, cap=1.0)
    last = ""
    for attempt in range(retries + 1):
        try:
            return op()
        except TransientError as exc:
            last = str(exc)
        if attempt < retries:
            sleep(delays[attempt])
            if on_retry is not None:
                on_retry()
    raise DeviceError(DEVICE, address, f"{what}: {last} (after {retries + 1} tries)")
