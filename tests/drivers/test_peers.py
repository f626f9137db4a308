"""One copy of the protocol peers, apart from the drivers they test.

The peers the driver tests talk to are the device emulators of ``sim/emulate``, set up by
``tests/drivers/peers.py``; both are written from the devices' manuals. Read from the source:

* no peer imports a driver's protocol code (the FT300's frames and CRC, the 2F-85's registers,
  Modbus and URCap transports, the UR5's RTDE and dashboard clients), so a driver is never
  checked against itself. The UR5's kinematics is the arm's geometry, not its wire: the twin's
  arm backend uses it. The D435's frame stream is exempt: a USB camera has no network protocol,
  so its stream is the project's own format, shared on purpose (docs/emulator.md);
* there are two CRC-16s in all: the driver's (``drivers/ft300/protocol.py``) and the peers'
  (``sim/emulate/rtu.py``), written apart from the same manual.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_layers import _modules

ROOT = Path(__file__).resolve().parents[2]
#: the peers: every emulator module and the driver tests' set-up of them
PEERS = sorted((ROOT / "sim" / "emulate").rglob("*.py")) + [ROOT / "tests/drivers/peers.py"]
#: (file, function) of each CRC-16 implementation in the project
CRC16S = {("drivers/ft300/protocol.py", "crc16_modbus"), ("sim/emulate/rtu.py", "crc16")}
#: The CRC-16 polynomials (Modbus: 0x8005, reflected 0xA001)
POLYNOMIALS = {0x8005, 0xA001}
#: The drivers' modules a peer may import from a real driver's package: not a wire
NOT_PROTOCOL = {("ur5", "kinematics")}
#: Real drivers whose wire is a vendor's protocol (the D435's stream is the project's own)
VENDOR_WIRES = {"ft300", "robotiq_gripper", "ur5"}


def _driver_protocol_imports(path: Path) -> list[str]:
    """``line: module`` for each import of a driver's protocol code in ``path``."""
    out = []
    for line, name in _modules(path):
        parts = name.split(".")
        if parts[0] != "drivers" or len(parts) < 2 or parts[1] not in VENDOR_WIRES:
            continue
        if len(parts) >= 3 and (parts[1], parts[2]) in NOT_PROTOCOL:
            continue
        out.append(f"{line}: {name}")
    return out


def _crc16_implementations(path: Path) -> list[str]:
    """The functions in ``path`` that compute a CRC-16 themselves: bit by bit with the
    polynomial, or from a 256-entry table (``<table>`` for one outside a function)."""
    tree = ast.parse(path.read_text(), str(path))

    def polynomial(node: ast.AST) -> bool:
        return any(isinstance(n, ast.Constant) and type(n.value) is int
                   and n.value in POLYNOMIALS for n in ast.walk(node))

    def table(node: ast.AST) -> bool:
        return any(isinstance(n, ast.List | ast.Tuple) and len(n.elts) == 256
                   and all(isinstance(e, ast.Constant) and type(e.value) is int
                           for e in n.elts) for n in ast.walk(node))

    found = []
    in_function: set[ast.AST] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            in_function.update(ast.walk(node))
            if polynomial(node) or table(node):
                found.append(node.name)
    for node in ast.walk(tree):
        if node not in in_function and isinstance(node, ast.List | ast.Tuple) and table(node):
            found.append("<table>")
    return found


def _project_sources() -> list[Path]:
    """Every Python file of the project (not under a hidden folder or an installed package)."""
    return sorted(p for p in ROOT.rglob("*.py")
                  if not any(part.startswith(".") or part == "site-packages"
                             for part in p.relative_to(ROOT).parts))


def test_the_peers_are_the_emulators() -> None:
    assert (ROOT / "tests/drivers/peers.py").is_file()
    assert not (ROOT / "tests/drivers/peers").exists(), "a second family of peers is back"
    assert len(PEERS) > 5


@pytest.mark.parametrize("path", PEERS, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_peer_imports_a_driver_s_protocol_code(path: Path) -> None:
    wrong = _driver_protocol_imports(path)
    assert not wrong, f"{path.relative_to(ROOT)} imports driver protocol code: {wrong}"


def test_two_crc16s_in_all_the_driver_s_and_the_peers() -> None:
    found = {(str(p.relative_to(ROOT)), name) for p in _project_sources()
             for name in _crc16_implementations(p)}
    assert found == CRC16S


def test_the_two_crc16s_agree_on_the_check_value() -> None:
    from drivers.ft300.protocol import crc16_modbus
    from sim.emulate.rtu import crc16

    assert crc16(b"123456789") == crc16_modbus(b"123456789") == 0x4B37  # CRC-16/MODBUS


@pytest.mark.parametrize(
    "line",
    [
        "from drivers.ft300.protocol import with_crc",
        "import drivers.ft300",
        "from drivers.robotiq_gripper import registers",
        "from drivers.robotiq_gripper.registers import encode_status",
        "from drivers.ur5.rtde_adapter import RECEIVE_VARIABLES",
        "def f():\n    from drivers.ur5 import DashboardClient",
    ],
    ids=["ft300-protocol", "ft300", "registers", "register-helper", "rtde", "dashboard"],
)
def test_the_scan_sees_a_driver_s_protocol_imported(tmp_path: Path, line: str) -> None:
    bad = tmp_path / "peer.py"
    bad.write_text(f"from drivers.ur5.kinematics import jacobian\n{line}\n")
    assert len(_driver_protocol_imports(bad)) == 1


@pytest.mark.parametrize(
    "source",
    [
        "def crc(data):\n    c = 0xFFFF\n    for b in data:\n        c ^= b\n"
        "        for _ in range(8):\n            c = (c >> 1) ^ 0xA001 if c & 1 else c >> 1\n"
        "    return c\n",
        "def crc(data):\n    return POLY_0x8005(data, 0x8005)\n",
        f"TABLE = {list(range(256))}\n",
    ],
    ids=["bitwise", "polynomial", "table"],
)
def test_the_scan_sees_a_crc16(tmp_path: Path, source: str) -> None:
    bad = tmp_path / "crc.py"
    bad.write_text(source)
    assert len(_crc16_implementations(bad)) == 1


def test_the_peers_need_no_pybullet() -> None:
    """The driver tests stay light: the peers and the emulators' modules import, and the peers
    are built, with PyBullet hidden, and none of the twin is imported (only sim.emulate)."""
    code = (
        "import sys\n"
        "sys.modules['pybullet'] = None\n"
        "sys.modules['pybullet_data'] = None\n"
        "import sim.emulate.camera_process, sim.emulate.camera_stream, sim.emulate.ur_standalone\n"
        "from tests.drivers import peers\n"
        "peers.ft300_peer().close()\n"
        "assert peers.gripper().get_var('STA') == 0\n"
        "with peers.dashboard_peer() as d:\n"
        "    peers.protective_stop(d)\n"
        "tops = ('sim', 'pybullet')\n"
        "print(' '.join(sorted(m for m, mod in sys.modules.items()\n"
        "                      if mod is not None and m.split('.')[0] in tops)))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    imported = r.stdout.split()
    assert "sim.emulate.ur_controller" in imported
    assert all(m in ("sim", "sim.emulate") or m.startswith("sim.emulate.") for m in imported), (
        imported)
