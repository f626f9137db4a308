"""Tick overhead of the cell's full tree (devices faked) against a plain py_trees tree of the same
shape and node count.

The cell's tree is built from the shipped configuration exactly as `cell sim` builds it; its
devices are fakes and every leaf's skill is replaced by one that stays RUNNING at no cost, so
what is timed is the tree itself: composites, the FT guards and timeouts checking before their
child, the retry and cycle decorators, the FT sampler writing the blackboard. The plain tree has
py_trees' own nodes in the same places (PassThrough decorators, Running leaves).

    python bench/tick.py [--ticks 20000] [--leaf N]

``--leaf`` picks which leaf is active (the tip), default the deepest guarded one (grasp).
Targets: median <= 200 us and <= 1.5x the plain tree.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import py_trees
from py_trees.behaviour import Behaviour
from py_trees.common import Status

from cell.assemble import prepare
from cell.config import default_config_path, load_config
from cell.runner import TickLog
from drivers.machine import TimedMachine
from skills.status import RUNNING

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the fakes live in tests/
from tests.trees.helpers import make_ctx  # noqa: E402
from trees.behaviours import SkillBehaviour


class _Idle:
    def tick(self):  # type: ignore[no-untyped-def]
        return RUNNING

    def halt(self) -> None:
        pass


def _plain_copy(node: Behaviour) -> Behaviour:
    """Same shape with py_trees' own nodes."""
    kids = list(node.children)
    if isinstance(node, py_trees.composites.Parallel):
        copies = [_plain_copy(c) for c in kids]
        return py_trees.composites.Parallel(
            node.name,
            policy=py_trees.common.ParallelPolicy.SuccessOnSelected(children=[copies[-1]]),
            children=copies,
        )
    if isinstance(node, py_trees.composites.Sequence):
        return py_trees.composites.Sequence(node.name, True, [_plain_copy(c) for c in kids])
    if isinstance(node, py_trees.composites.Selector):
        return py_trees.composites.Selector(node.name, True, [_plain_copy(c) for c in kids])
    if isinstance(node, py_trees.decorators.Decorator):
        return py_trees.decorators.PassThrough(node.name, _plain_copy(kids[0]))
    return py_trees.behaviours.Running(node.name)


def _time_ticks(root: Behaviour, ticks: int, after=None) -> list[float]:  # type: ignore[no-untyped-def]
    out = []
    for i in range(ticks):
        t0 = time.perf_counter_ns()
        root.tick_once()
        if after is not None:
            after(i, root)
        out.append((time.perf_counter_ns() - t0) / 1e3)
        assert root.status == Status.RUNNING
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ticks", type=int, default=20000)
    args = ap.parse_args()

    config, doc = load_config(default_config_path())
    prep = prepare(config, doc)
    fake = make_ctx()
    prep.ctx.devices = fake.devices
    prep.ctx.machine = TimedMachine(fake.devices.clock, 5.0)
    for node in prep.root.iterate():
        if isinstance(node, SkillBehaviour):
            node.make_skill = lambda: _Idle()  # type: ignore[method-assign]
        elif isinstance(node, py_trees.behaviour.Behaviour) and not node.children and (
            node.name == "plan pick"
        ):
            node.update = lambda: Status.RUNNING  # type: ignore[method-assign]
    root = prep.root
    root.setup_with_descendants()
    plain = _plain_copy(root)
    count = sum(1 for _ in root.iterate())
    assert count == sum(1 for _ in plain.iterate())

    for r in (root, plain):  # warm-up
        _time_ticks(r, 500)
    cell = _time_ticks(root, args.ticks)
    base = _time_ticks(plain, args.ticks)
    log = TickLog(None)
    with_log = _time_ticks(root, args.ticks, lambda i, r: log.record(i, 0.0, r, None))
    m_cell, m_base, m_log = (statistics.median(x) for x in (cell, base, with_log))
    tip = root.tip()
    print(f"nodes: {count} (tip: {tip.name if tip else '-'}); {args.ticks} ticks each")
    print(f"plain py_trees tree       median {m_base:7.1f} us   p95 "
          f"{sorted(base)[int(0.95 * len(base))]:7.1f} us")
    print(f"cell tree (faked devices) median {m_cell:7.1f} us   p95 "
          f"{sorted(cell)[int(0.95 * len(cell))]:7.1f} us   ratio {m_cell / m_base:.2f}x")
    print(f"cell tree + tick log      median {m_log:7.1f} us   p95 "
          f"{sorted(with_log)[int(0.95 * len(with_log))]:7.1f} us")


if __name__ == "__main__":
    main()
