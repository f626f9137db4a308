"""The UR5 on its controller: the :class:`drivers.arm.Arm` interface over ``ur_rtde``
(:mod:`drivers.ur5.arm`, through the thin :mod:`drivers.ur5.rtde_adapter`) and the dashboard
server client (:mod:`drivers.ur5.dashboard`); the arm's kinematics with this cell's tool, in plain
numpy, which the cell's reach check and the twin share (:mod:`drivers.ur5.kinematics`).

Importing this package does not import ``ur_rtde``; only :meth:`UR5Arm.connect` does.
"""

from drivers.ur5.arm import UR5Arm, UR5Settings
from drivers.ur5.dashboard import DashboardClient
from drivers.ur5.rtde_adapter import RTDEAdapter, URRTDEAdapter

__all__ = ["DashboardClient", "RTDEAdapter", "UR5Arm", "UR5Settings", "URRTDEAdapter"]
