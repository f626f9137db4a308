"""The shipped emulated cell moved out of other tests' way: its arm (and URCap) on a loopback
alias of this process's own, its pseudo-terminal links and state under a test's directory, its
camera stream on a free port; `cell emulate` and `cell run` read the same file."""

from __future__ import annotations

import socket
from pathlib import Path

from lab.emulate_cmd import EXAMPLE
from sim.emulate.ur_standalone import loopback_host


def free_port(host: str) -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def emulated_config(tmp_path: Path, extra: str = "") -> Path:
    """A copy of the shipped example for this test; ``extra`` YAML is appended (its sections
    must not repeat the example's)."""
    host = loopback_host()
    text = EXAMPLE.read_text()
    for old, new in (
        ("host: 127.0.0.1", f"host: {host}"),
        ("port: /tmp/pivot-cell/gripper", f"port: {tmp_path}/dev/gripper"),
        ("port: socket://127.0.0.1:50300", f"port: socket://{host}:{free_port(host)}"),
        ("stream: 127.0.0.1:50435", f"stream: {host}:{free_port(host)}"),
        ("tick_log: out/cell_ticks.jsonl", f"tick_log: {tmp_path}/out/cell_ticks.jsonl"),
        ("state_file: out/cell_state.json", f"state_file: {tmp_path}/out/cell_state.json"),
    ):
        assert old in text, old
        text = text.replace(old, new)
    if extra:
        text = text.replace("  faults: []", extra) if extra.startswith("  faults:") else (
            text + extra)
    path = tmp_path / "emulated.yaml"
    path.write_text(text)
    return path
