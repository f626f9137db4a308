"""The twin's state at every control step, as a CSV: what the fingers and the wrist really did.

Why: the cell's tick log holds what the skills saw through their devices; a question such as
"did the inner finger stop at H, or shove the part?" needs the twin's own opening, its noiseless
wrist load and the TCP at each step, side by side with the tick log's steps (``wall_s`` for
`cell emulate`, ``twin_s`` for `cell sim`). `cell sim --trace` and `cell emulate --trace` write
the same columns, so a run on the emulated devices can be laid over the same cell in the twin.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

HEADER = (
    "wall_s,twin_s,fx_n,fy_n,fz_n,tx_nm,ty_nm,tz_nm,opening_m,tcp_x_m,tcp_y_m,tcp_z_m,mode"
)


class TwinTrace:
    """One row after each step of ``world``: its clock, the wrist sensor's raw noiseless load
    (N, N*m; tool frame, not zeroed: the tool's weight included), the finger opening (m), the
    TCP (m, the robot's base frame) and what drives the arm. Buffered; :meth:`close` flushes."""

    def __init__(self, path: Path, world: Any, robot: Any) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)  # as --json and --record make theirs
        self._file = path.open("w", buffering=1 << 16)
        self._file.write(HEADER + "\n")
        self._world, self._robot = world, robot
        world.after_step(self.row)

    def row(self) -> None:
        if self._file.closed:
            return
        r = self._robot
        w = r.ft.sampled_true_load()
        tcp = r.arm.tool_pose().position
        self._file.write(
            f"{time.time():.4f},{self._world.clock.now():.4f},{w[0]:.3f},{w[1]:.3f},{w[2]:.3f},"
            f"{w[3]:.4f},{w[4]:.4f},{w[5]:.4f},{r.gripper.true_width():.5f},{tcp[0]:.5f},"
            f"{tcp[1]:.5f},{tcp[2]:.5f},{r.arm.mode}\n"
        )

    def close(self) -> None:
        self._file.close()


__all__ = ["HEADER", "TwinTrace"]
