"""Every FT300 test must leave no reader or peer thread behind (stop() and close() join them)."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    yield
    # The driver's threads are ft300-*, the emulated sensor's emu-ft300.
    left = [t.name for t in threading.enumerate() if "ft300" in t.name]
    assert not left, f"threads still running after the test: {left}"
