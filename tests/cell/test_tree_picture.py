"""The tree picture shows what decides each node's behaviour: limits, timeouts, attempts, the
cycles; conditions apart from actions; and a legend."""

from __future__ import annotations

from pathlib import Path

from cell.cell_cmds import load_prepared
from trees.decorators import Cycles, FTGuard, Retry, Timeout
from trees.render import _kind, _label, write_pictures


def test_labels_carry_the_parameters_and_kinds_tell_conditions_apart(tmp_path: Path) -> None:
    prep = load_prepared(None, ["workflow.cycles=4"])
    nodes = list(prep.root.iterate())
    retries = [n for n in nodes if isinstance(n, Retry)]
    assert retries and all(f"{n.attempts} attempts" in _label(n) for n in retries)
    assert any("pause" in _label(n) for n in retries if n.pause_s)
    cycles = next(n for n in nodes if isinstance(n, Cycles))
    assert "4 cycles" in _label(cycles)
    guard = next(n for n in nodes if isinstance(n, FTGuard))
    assert f"{guard.max_force:g} N" in _label(guard) and _kind(guard) == "Guard"
    timeout = next(n for n in nodes if isinstance(n, Timeout))
    assert f"{timeout.seconds:g} s" in _label(timeout)
    kinds = {n.name: _kind(n) for n in nodes}
    assert kinds["slot holds part"] == "Condition" and kinds["perceive"] == "Leaf"
    assert kinds["pivot clears"] == "Condition" and kinds["slot machined"] == "Condition"
    assert kinds["reposition"] == "Leaf" and kinds["plan pick"] == "Leaf"
    reposition_guard = next(n for n in nodes if n.name == "reposition ft guard")
    assert "60 N" in _label(reposition_guard)
    dot, png = write_pictures(prep.root, tmp_path)
    assert png.read_bytes().startswith(b"\x89PNG") and dot.stat().st_size > 0
