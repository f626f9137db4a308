"""Rigid transforms in SI units, shared by every interface.

A :class:`Pose` is a position (m) and a rotation (3x3 matrix) of a frame in a parent frame; the
UR controller's axis-angle vectors and PyBullet's quaternions convert through it. It is a small
value type on purpose: skills do geometry with it and devices exchange it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class Pose:
    """``position`` (m, shape 3) and ``rotation`` (3x3; columns: the frame's axes in the parent)."""

    position: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    rotation: NDArray[np.float64] = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=float).reshape(3)
        r = np.asarray(self.rotation, dtype=float).reshape(3, 3)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(r))):
            raise ValueError("pose must be finite")
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "rotation", r)

    @classmethod
    def from_quaternion(cls, position: ArrayLike, quat_xyzw: ArrayLike) -> Pose:
        return cls(np.asarray(position, float), Rotation.from_quat(quat_xyzw).as_matrix())

    @classmethod
    def from_rotvec(cls, position: ArrayLike, rotvec: ArrayLike) -> Pose:
        """From the UR controller's ``[x, y, z, rx, ry, rz]`` convention (axis-angle, rad)."""
        return cls(np.asarray(position, float), Rotation.from_rotvec(rotvec).as_matrix())

    @property
    def quaternion(self) -> NDArray[np.float64]:
        """``(x, y, z, w)``, PyBullet's order."""
        return Rotation.from_matrix(self.rotation).as_quat()

    @property
    def rotvec(self) -> NDArray[np.float64]:
        return Rotation.from_matrix(self.rotation).as_rotvec()

    def __matmul__(self, other: Pose) -> Pose:
        """Compose: ``parent_T_child = parent_T_mid @ mid_T_child``."""
        return Pose(self.position + self.rotation @ other.position, self.rotation @ other.rotation)

    def inverse(self) -> Pose:
        rt = self.rotation.T
        return Pose(-rt @ self.position, rt)

    def transform(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map points (..., 3) from this frame into the parent frame."""
        return np.asarray(points, float) @ self.rotation.T + self.position

    def distance(self, other: Pose) -> tuple[float, float]:
        """``(translation m, rotation rad)`` between two poses."""
        dr = Rotation.from_matrix(self.rotation.T @ other.rotation).magnitude()
        return float(np.linalg.norm(self.position - other.position)), float(dr)

    def interpolate(self, other: Pose, s: float) -> Pose:
        """Straight line in position, slerp in rotation; ``s`` in [0, 1]."""
        rel = Rotation.from_matrix(self.rotation.T @ other.rotation).as_rotvec()
        rot = self.rotation @ Rotation.from_rotvec(s * rel).as_matrix()
        return Pose(self.position + s * (other.position - self.position), rot)


def rot_x(angle: float) -> NDArray[np.float64]:
    return Rotation.from_euler("x", angle).as_matrix()


def rot_y(angle: float) -> NDArray[np.float64]:
    return Rotation.from_euler("y", angle).as_matrix()


def rot_z(angle: float) -> NDArray[np.float64]:
    return Rotation.from_euler("z", angle).as_matrix()
