"""The hardware path runs without the twin: `cell tree`, `cell run` and `cell check-hardware` on a
machine without PyBullet (a cell's controller PC need not have it).

Each command runs in a fresh interpreter in which ``pybullet`` and everything under it cannot be
imported, as on such a machine. `cell tree` must build and draw the shipped tree; `cell run` and
`cell check-hardware` on a configuration whose devices are not there must fail the way they do
with PyBullet installed -- the exit status and the devices named -- not with an ImportError. And
none of them may have imported the twin (``sim``) at all.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cell
from tests.addresses import free_port, quiet_host

SHIPPED = Path(cell.__file__).resolve().parent / "data" / "bushing_cell.yaml"

#: Hides PyBullet (``pybullet``, ``pybullet_data``, ``pybullet_utils``, ...) from the import
#: system, reports at exit which modules of the twin were imported, then runs the CLI.
PRELUDE = """
import atexit, importlib.abc, sys

class _NoPyBullet(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0].startswith("pybullet"):
            raise ModuleNotFoundError(f"No module named {name!r} (hidden by the test)", name=name)
        return None

for _name in [m for m in sys.modules if m.split(".")[0].startswith("pybullet")]:
    del sys.modules[_name]
sys.modules["pybullet"] = None
sys.modules["pybullet_data"] = None
sys.meta_path.insert(0, _NoPyBullet())

def _twin_modules():
    twin = sorted(m for m in sys.modules if m == "sim" or m.startswith("sim."))
    print("TWIN MODULES: " + (", ".join(twin) or "none"), file=sys.stderr)

atexit.register(_twin_modules)
"""


def _cell(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    code = PRELUDE + f"\nfrom cell.cli import main\nsys.exit(main({args!r}))\n"
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=cwd
    )


def _hw_config(tmp_path: Path) -> Path:
    """The hardware backend with nothing there: nothing listens on the UR's RTDE port or the
    URCap port, the FT300's serial port does not exist, and there is no camera."""
    cfg = tmp_path / "hw.yaml"
    cfg.write_text(
        "cell:\n  backend: hw\n"
        "devices:\n"
        f"  arm: {{host: {quiet_host()}, connect_timeout_s: 0.5}}\n"
        f"  gripper: {{transport: urcap, urcap_port: {free_port()}, timeout_s: 0.5}}\n"
        f"  ft: {{port: {tmp_path / 'no_tty'}, stale_after_s: 0.5}}\n"
        "skills:\n  pivot: {grip_force_n: 20, hold_force_n: 20}\n  slot: {hold_force_n: 20}\n"
        "log:\n"
        f"  tick_log: {tmp_path / 'ticks.jsonl'}\n"
        f"  state_file: {tmp_path / 'state.json'}\n"
        f"  journal: {tmp_path / 'journal.sqlite'}\n",
        encoding="utf-8",
    )
    return cfg


def _clean(r: subprocess.CompletedProcess[str]) -> None:
    """No traceback, no import error, and the twin never imported."""
    assert "Traceback" not in r.stderr, r.stderr
    assert "ImportError" not in r.stderr and "ModuleNotFoundError" not in r.stderr, r.stderr
    assert "TWIN MODULES: none" in r.stderr, r.stderr


def test_the_prelude_really_hides_pybullet(tmp_path: Path) -> None:
    code = PRELUDE + "\nimport sim.world\n"
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=tmp_path
    )
    assert r.returncode != 0 and "pybullet" in r.stderr


def test_cell_tree_builds_the_shipped_tree_without_pybullet(tmp_path: Path) -> None:
    r = _cell(["tree", "--config", str(SHIPPED), "--out", str(tmp_path)], tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "tree.dot").exists() and "wrote" in r.stdout
    _clean(r)


def test_cell_run_refuses_on_the_devices_not_on_pybullet(tmp_path: Path) -> None:
    r = _cell(["run", "--config", str(_hw_config(tmp_path))], tmp_path)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "cell run: error:" in r.stderr
    assert "start-up checks failed, nothing moved" in r.stderr
    assert f"{quiet_host()}:30004" in r.stderr and "no_tty" in r.stderr
    _clean(r)


def test_cell_check_hardware_reports_every_device_without_pybullet(tmp_path: Path) -> None:
    r = _cell(["check-hardware", "--config", str(_hw_config(tmp_path))], tmp_path)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "4 of 4 failed" in r.stdout
    for device in ("UR5", "2F-85", "FT300", "D435"):
        assert device in r.stdout
    assert f"{quiet_host()}:30004" in r.stdout
    _clean(r)
