"""Names for the components of the vectors the skills read and command.

Why: a skill that writes ``wrench[2]`` or ``position[:2]`` holds a number a reader must decode;
``wrench[FZ]`` and ``position[XY]`` say what they mean, and the check that no skill module holds
an undeclared number (tests/skills/test_literals.py) can tell an index from a tuned constant.
"""

from __future__ import annotations

#: Cartesian components of a position, a velocity or a force (base or tool frame)
X, Y, Z = 0, 1, 2
#: the horizontal components, as a slice
XY = slice(X, Z)
#: the number of Cartesian components: the length of a point, a force or a torque
DIM = 3
#: the force of a wrench (Fx, Fy, Fz, Tx, Ty, Tz), as a slice
FORCE = slice(0, DIM)
#: the torque of a wrench, as a slice: a force and a torque of DIM components each
TORQUE = slice(DIM, 2 * DIM)
#: the length of a wrench: a force and a torque
WRENCH_DIM = 2 * DIM
#: force components of a wrench, by name
FX, FY, FZ = X, Y, Z

__all__ = ["DIM", "FORCE", "FX", "FY", "FZ", "TORQUE", "WRENCH_DIM", "X", "XY", "Y", "Z"]
