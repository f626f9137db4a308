"""The wrist force-torque sensor interface (a Robotiq FT300 or its twin)."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@runtime_checkable
class ForceTorqueSensor(Protocol):
    def wrench(self) -> NDArray[np.float64]:
        """Newest ``[Fx, Fy, Fz, Tx, Ty, Tz]`` in the tool frame (N, N*m), bias removed.

        It is the load the tool puts on the sensor: gravity of the gripper is part of it until
        :meth:`bias` is called with the gripper at rest.
        """
        ...

    def bias(self) -> None:
        """Take the current reading as zero (do it at rest, before contact)."""
        ...

    def age(self) -> float:
        """Seconds since the newest sample; a large value means a stale stream."""
        ...
