"""`cell check-hardware` against protocol peers on this machine (the emulated devices of
sim/emulate, tests/drivers/peers.py): the gripper's URCap socket (TCP) and a pseudo-terminal
FT300 pass; the UR5 (nothing listens) and the D435 (no camera) fail with their addresses.
Nothing is moved."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sim.emulate.gripper_server import UrcapServer
from tests.addresses import free_port, quiet_host
from tests.drivers.peers import ft300_peer, gripper


@pytest.fixture
def peers():
    urcap = UrcapServer(gripper(), quiet_host(), port=0)  # the URCap is on the arm's host
    ft = ft300_peer().start()
    yield urcap, ft
    urcap.stop()
    ft.close()


def _config(tmp_path: Path, urcap_port: int, ft_port: str, rtde_host: str) -> Path:
    cfg = tmp_path / "hw.yaml"
    cfg.write_text(
        "cell:\n  backend: hw\n"
        "devices:\n"
        f"  arm: {{host: {rtde_host}, connect_timeout_s: 0.5}}\n"
        f"  gripper: {{transport: urcap, urcap_port: {urcap_port}, timeout_s: 0.5}}\n"
        f"  ft: {{port: {ft_port}, stale_after_s: 0.5}}\n"
    )
    return cfg


def test_check_hardware_table_against_peers(tmp_path, peers) -> None:
    urcap, ft = peers
    out = tmp_path / "check.json"
    cfg = _config(tmp_path, urcap.port, ft.port, quiet_host())
    t0 = time.monotonic()
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cell.cli",
            "check-hardware",
            "--config",
            str(cfg),
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    elapsed = time.monotonic() - t0
    assert r.returncode == 1, r.stdout + r.stderr  # the arm and the camera are not there
    assert "Traceback" not in r.stderr
    rows = {d["device"]: d for d in json.loads(out.read_text())["devices"]}
    assert rows["2F-85"]["ok"], rows["2F-85"]  # activated through the URCap socket
    assert rows["FT300"]["ok"], rows["FT300"]
    assert float(rows["FT300"]["details"]["stream_rate_hz"]) > 80.0
    assert not rows["UR5"]["ok"] and f"{quiet_host()}:30004" in rows["UR5"]["address"]
    assert not rows["D435"]["ok"] and "no RealSense camera" in rows["D435"]["error"]
    assert "2 of 4 failed" in r.stdout
    assert elapsed < 60.0  # bounded retries, no storm


def test_check_hardware_with_nothing_there_names_every_address(tmp_path) -> None:
    cfg = _config(tmp_path, free_port(), str(tmp_path / "no_tty"), quiet_host())
    r = subprocess.run(
        [sys.executable, "-m", "cell.cli", "check-hardware", "--config", str(cfg)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 1 and "4 of 4 failed" in r.stdout
    assert f"{quiet_host()}:30004" in r.stdout and "no_tty" in r.stdout
    assert "Traceback" not in r.stderr
