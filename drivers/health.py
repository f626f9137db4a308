"""What every real driver shares: its error type and its start-up check result.

A :class:`DeviceError` names the device, its address and the cause, so a person at the cell
knows which cable to look at. :class:`CheckResult` is what ``cell check-hardware`` prints, one
row per device.
"""

from __future__ import annotations

from dataclasses import dataclass, field


class DeviceError(RuntimeError):
    """A device that does not answer, answers wrongly, or reports a fault."""

    def __init__(self, device: str, address: str, cause: str) -> None:
        self.device, self.address, self.cause = device, address, cause
        super().__init__(f"{device} at {address}: {cause}")


@dataclass
class CheckResult:
    """One device's start-up check: passed or not, what it reported, and why not."""

    device: str
    address: str
    ok: bool
    details: dict[str, str] = field(default_factory=dict)
    error: str | None = None


def backoff_delays(attempts: int, first: float = 0.1, factor: float = 2.0, cap: float = 2.0
                   ) -> list[float]:
    """Waits (s) between bounded connection attempts: no retry storms."""
    out, d = [], first
    for _ in range(max(0, attempts - 1)):
        out.append(min(d, cap))
        d *= factor
    return out
