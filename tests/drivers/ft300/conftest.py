"""Every FT300 test must leave no reader or peer thread behind (stop() and close() join them)."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    yield
    left = [t.name for t in threading.enumerate() if t.name.startswith("ft300")]
    assert not left, f"threads still running after the test: {left}"
