"""The core runs without the extras (torch and onnx, Ray), the learned perception's inference
included, and a command that needs a missing extra says which one to install: exit 2, one line,
no traceback."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from .test_cli import assert_user_error

#: A process in which torch, onnx and Ray are not installed, as far as any import can tell.
NO_EXTRAS = """\
import importlib.abc, sys
class _NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("torch", "onnx", "ray"):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, _NotInstalled())
from cell.cli import main
"""


def run_without_extras(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    code = NO_EXTRAS + f"sys.exit(main({argv!r}))"
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=cwd
    )


@pytest.mark.parametrize(
    ("argv", "extra"),
    [
        (["sweep", "--part", "bushing", "--trials", "1", "--out", "{d}"], "sweep"),
        (["train-perception", "--scenes", "2", "--epochs", "1", "--out", "{d}/w.onnx"], "learned"),
    ],
)
def test_a_missing_extra_is_named(argv: list[str], extra: str, tmp_path: Path) -> None:
    out_dir = tmp_path / "o"
    out_dir.mkdir()
    r = run_without_extras([a.replace("{d}", str(out_dir)) for a in argv], tmp_path)
    assert_user_error(r.returncode, r.stdout, r.stderr, argv[0], f'"pivot-cell[{extra}]"')
    assert list(out_dir.iterdir()) == []


def test_the_core_runs_without_torch_and_ray(tmp_path: Path) -> None:
    """`cell plan`, `cell tree` and a pivot trial in a process where torch and Ray cannot be
    imported at all."""
    for argv in (
        ["plan", "--part", "bushing"],
        ["tree", "--out", str(tmp_path / "tree")],
        [
            "pivot",
            "--part",
            "bushing",
            "--trials",
            "1",
            "--seed",
            "0",
            "--json",
            str(tmp_path / "p.json"),
        ],
    ):
        r = run_without_extras(argv, tmp_path)
        assert r.returncode == 0, (argv, r.stderr[-2000:])
        assert "torch" not in r.stderr and "Traceback" not in r.stderr


def test_the_learned_perception_runs_without_torch(tmp_path: Path) -> None:
    """`cell perceive --pipeline learned` (the shipped ONNX model through OpenCV) in a process
    where torch and onnx cannot be imported: it scores its scene."""
    out = tmp_path / "p.json"
    argv = ["perceive", "--scenes", "1", "--seed", "0", "--json", str(out)]
    r = run_without_extras([*argv, "--pipeline", "learned"], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "torch" not in r.stderr and "Traceback" not in r.stderr
    data = json.loads(out.read_text())
    assert data["pipeline"] == "learned" and data["parts"] >= 1 and data["found"] >= 1, data
