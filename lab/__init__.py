"""The lab: the experiments that reproduce and extend the paper on the twin, above the cell.

Why a package of its own, above ``cell/``: the application -- configuration, assembly, the tick
loop, the journal, the hardware backend and their commands -- must stay small and reviewable, and
must not depend on what only measures or trains: randomized pivot trials (``cell pivot``) and
their parallel sweep on Ray (``cell sweep``), the regrasp baseline (``cell compare``), the fault
soak (``cell soak``), bin perception scoring and training (``cell perceive``,
``cell train-perception``), the hand-eye calibration in the twin (``cell calibrate``), the
emulated devices the hardware path is tried against (``cell emulate``), and the statistics they
report. The lab imports the cell; the cell never imports the lab. Its commands join the ``cell``
command line as plugins (:func:`add_commands`, declared in pyproject.toml's
``pivot_cell.commands`` entry points).
"""

from __future__ import annotations

import argparse


def add_commands(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """The lab's subcommands, added to the ``cell`` command line (the entry point)."""
    from lab.calibrate_cmd import add_parser as add_calibrate
    from lab.compare_cmd import add_parser as add_compare
    from lab.emulate_cmd import add_parser as add_emulate
    from lab.perceive_cmd import add_parser as add_perceive
    from lab.pivot_cmd import add_parser as add_pivot
    from lab.soak_cmd import add_parser as add_soak
    from lab.sweep_cmd import add_parser as add_sweep
    from lab.train_perception_cmd import add_parser as add_train_perception

    for add in (add_pivot, add_sweep, add_calibrate, add_perceive, add_train_perception,
                add_compare, add_soak, add_emulate):
        add(sub)
