"""Addresses for tests that need nothing to listen there.

A UR controller is always reached on fixed ports (RTDE 30004, the dashboard 29999), so a test
that expects "connection refused" on ``127.0.0.1`` meets whatever else on the machine listens
there: ``cell emulate`` with its shipped configuration, or another copy of this suite. Each
test process takes a loopback address of its own instead (Linux routes all of 127.0.0.0/8 to
the loopback interface), in a range no emulator or peer of this project binds.
"""

from __future__ import annotations

import os
import socket


def free_port() -> int:
    """A localhost port nothing listens on (bound, then released): a refused connection."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def quiet_host() -> str:
    """A loopback address of this process's own on which nothing listens."""
    pid = os.getpid()
    return f"127.{200 + (pid >> 16) % 50}.{(pid >> 8) & 255}.{max(1, pid & 255)}"
