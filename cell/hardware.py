"""The hardware backend: the real UR5, 2F-85, FT300 and D435 behind the same interfaces.

Opened only after the configuration validated. Until the real drivers land (issue 7), this
refuses with the reason instead of pretending.
"""

from __future__ import annotations

from typing import Any

from trees.yaml_lines import ConfigError


def open_hardware(prep: Any) -> Any:
    raise ConfigError(
        prep.doc.source,
        prep.doc.line_of(("cell", "backend")),
        "cell.backend",
        "the hardware drivers (ur_rtde, Robotiq Modbus, RealSense) are not in this build yet; "
        "nothing was opened or moved",
    )
