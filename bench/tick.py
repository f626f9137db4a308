"""Tick overhead of the cell's full tree (devices faked) against a plain py_trees tree of the same
shape and node count.

The cell's tree is built from the shipped configuration exactly as `cell sim` builds it; its
devices are fakes and every leaf's skill is replaced by one that stays RUNNING at no cost, so
what is timed is the tree itself: composites, the FT guards and timeouts checking before their
child, the retry and cycle decorators, the FT sampler writing the blackboard. The plain tree has
py_trees' own nodes in the same places (PassThrough decorators; leaves that return what the
cell's leaf returned on its first tick: Running, or Failure for a condition that failed), so
both trees tick the same path down to the same tip (checked), the first leaf of the cycle.

    python bench/tick.py [--ticks 20000]

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
    """Same shape with py_trees' own nodes, taking the same path as ``node`` after its first
    tick: a leaf that failed (a condition such as "slot holds part") fails, one that succeeded
    succeeds, any other keeps running.

    Why not Running everywhere: the shipped tree starts its cycle with a selector whose first
    child is a condition that fails; a Running leaf there stops the plain tree's selector at it,
    six levels above the cell tree's tip, and the comparison times two different paths."""
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
    if node.status == Status.FAILURE:
        return py_trees.behaviours.Failure(node.name)
    if node.status == Status.SUCCESS:
        return py_trees.behaviours.Success(node.name)
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
    root.tick_once()  # the path the cell tree takes, for the plain copy to take too
    plain = _plain_copy(root)
    count = sum(1 for _ in root.iterate())
    assert count == sum(1 for _ in plain.iterate())

    for r in (root, plain):  # warm-up
        _time_ticks(r, 500)
    tip, plain_tip = root.tip(), plain.tip()
    names = (tip.name if tip else None, plain_tip.name if plain_tip else None)
    assert tip is not None and names[0] == names[1], f"the trees tick different paths: {names}"
    cell = _time_ticks(root, args.ticks)
    base = _time_ticks(plain, args.ticks)
    log = TickLog(None)
    with_log = _time_ticks(root, args.ticks, lambda i, r: log.record(i, 0.0, r, None))
    m_cell, m_base, m_log = (statistics.median(x) for x in (cell, base, with_log))
    print(f"nodes: {count} (tip of both: {names[0]}); {args.ticks} ticks each")
    print(f"plain py_trees tree       median {m_base:7.1f} us   p95 "
          f"{sorted(base)[int(0.95 * len(base))]:7.1f} us")
    print(f"cell tree (faked devices) median {m_cell:7.1f} us   p95 "
          f"{sorted(cell)[int(0.95 * len(cell))]:7.1f} us   ratio {m_cell / m_base:.2f}x")
    print(f"cell tree + tick log      median {m_log:7.1f} us   p95 "
          f"{sorted(with_log)[int(0.95 * len(with_log))]:7.1f} us")


if __name__ == "__main__":
    main()
