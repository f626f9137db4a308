"""Where the pivot happens in the world: the part's vertical plane and the poses of Fig. 10.

The maneuver is planar (Sec. II-B). Its plane contains the part's axis ``u`` (towards the open
end) and the vertical ``up``; ``s`` runs along ``u`` from the part's centre, ``h`` up from the
floor. In that plane the mechanics' points are ``S = (a - l, 2b)``, ``H = (a, 2b - delta)`` and
the pivot ``P_c = G = (-a, 0)`` (the far bottom corner).

Tool frame (see ``drivers``): ``z`` along the fingers (approach), ``x`` the closing line from the
finger in the hole (H finger, on -x) towards the outer finger (S finger, on +x). At the grasp
``x = (-cos alpha) u + (sin alpha) up`` -- alpha is the angle between the part's axis and the
closing line, as in the mechanics -- and ``z = (-sin alpha) u - (cos alpha) up``.

With equal fingers the two fingertips sit at the same depth along ``z``; the S finger's tip rests
on the top surface, so the H finger reaches ``e_H = l sin(alpha) - delta cos(alpha)`` past the
rim contact H (negative would mean it misses the lip).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from drivers.parts import Section
from drivers.pose import Pose
from skills.axes import Z

#: rad between two poses of a listed tilt path: a straight move over 2 deg of the arc strays
#: about 15 um from it at a 0.1 m radius, far inside the fingers' give
TILT_PATH_STEP = math.radians(2.0)
#: The tool's z component below which the fingers count as horizontal: they then never reach
#: the rim's height, and the grasp cannot say where H lies along the part
HORIZONTAL_Z = 1e-6


def _rotation_about(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    return Rotation.from_rotvec(np.asarray(axis, float) * angle).as_matrix()


@dataclass(frozen=True)
class PivotFrame:
    """The pivot plane of one lying part: centre (m, world), yaw of ``u`` (rad), floor height."""

    section: Section
    center: NDArray[np.float64]
    yaw: float
    floor_z: float = 0.0

    @property
    def u(self) -> NDArray[np.float64]:
        return np.array([math.cos(self.yaw), math.sin(self.yaw), 0.0])

    @property
    def up(self) -> NDArray[np.float64]:
        return np.array([0.0, 0.0, 1.0])

    @property
    def normal(self) -> NDArray[np.float64]:
        """``up x u``: the tool's y axis; the tilt lifts the open end about ``-normal``."""
        return np.cross(self.up, self.u)

    def point(self, s: float, h: float) -> NDArray[np.float64]:
        """World point at ``s`` along the axis from the centre and ``h`` above the floor (m)."""
        base = np.array([self.center[0], self.center[1], self.floor_z])
        return base + s * self.u + h * self.up

    @property
    def pivot(self) -> NDArray[np.float64]:
        """``P_c``: the far bottom corner G, the centre of the Tilt (Fig. 10)."""
        return self.point(-self.section.a, 0.0)

    def opening(self, l_a: float, alpha: float) -> float:
        """Distance between the finger faces at the grasp (m)."""
        l = 2.0 * self.section.a * l_a  # exact: l = 2 a l_a, the paper's definition of l_a
        return l * math.cos(alpha) + self.section.delta * math.sin(alpha)

    def hook_depth(self, l_a: float, alpha: float) -> float:
        """``e_H``: how far the H finger reaches past the rim contact along the finger (m)."""
        l = 2.0 * self.section.a * l_a  # exact: l = 2 a l_a, the paper's definition of l_a
        return l * math.sin(alpha) - self.section.delta * math.cos(alpha)

    def grasp_rotation(self, alpha: float) -> NDArray[np.float64]:
        x = -math.cos(alpha) * self.u + math.sin(alpha) * self.up
        z = -math.sin(alpha) * self.u - math.cos(alpha) * self.up
        return np.column_stack([x, np.cross(z, x), z])

    def grasp_pose(self, l_a: float, alpha: float, tip_offset: float) -> Pose:
        """``P_i``: TCP pose at the grasp. ``tip_offset``: TCP to fingertip along z (m)."""
        a, b = self.section.a, self.section.b
        l = 2.0 * a * l_a  # exact: l = 2 a l_a, the paper's definition of l_a
        rot = self.grasp_rotation(alpha)
        s_point = self.point(a - l, 2.0 * b)  # exact: S on the top surface, at D = 2b
        half = 0.5 * self.opening(l_a, alpha)  # exact: the TCP lies midway between the pads
        tcp = s_point - half * rot[:, 0] - tip_offset * rot[:, Z]
        return Pose(tcp, rot)

    def located(self, tool: Pose, jaw_width: float) -> PivotFrame:
        """This frame slid along ``u`` so that H lies where the closed grasp puts it.

        After closing, the inner finger's pad face passes through the rim contact H at height
        ``2b - delta``: that fixes the part's real position along its axis and with it the
        pivot of the Tilt. An arc about a pivot a few millimetres off squeezes the part between
        S and the floor as theta grows (a 3 mm error gives about 1.3 mm of interference at S by
        60 deg), which rigid fingers cannot absorb.
        """
        x, z = tool.rotation[:, 0], tool.rotation[:, Z]
        if abs(z[Z]) < HORIZONTAL_Z:
            return self
        face = tool.position - 0.5 * jaw_width * x  # exact: the TCP lies midway between the pads
        h_contact = self.floor_z + 2.0 * self.section.b - self.section.delta  # exact: D = 2b
        face = face + ((h_contact - face[Z]) / z[Z]) * z
        shift = float(np.dot(face - self.point(0.0, 0.0), self.u)) - self.section.a
        return replace(self, center=np.asarray(self.center, float) + shift * self.u)

    def tilt_pose(self, grasp: Pose, theta: float) -> Pose:
        """The grasp carried along the arc about ``P_c`` by ``theta`` (rad): the open end rises."""
        r = _rotation_about(-self.normal, theta)
        p = self.pivot + r @ (grasp.position - self.pivot)
        return Pose(p, r @ grasp.rotation)

    def tilt_path(self, grasp: Pose, theta: float, step: float = TILT_PATH_STEP) -> list[Pose]:
        n = max(1, int(math.ceil(theta / step)))
        return [self.tilt_pose(grasp, theta * k / n) for k in range(1, n + 1)]

    def radius(self, grasp: Pose) -> float:
        """``r`` of Fig. 10: distance of the TCP from the pivot (m)."""
        return float(np.linalg.norm(grasp.position - self.pivot))


def rotate_about_point(
    pose: Pose, point: NDArray[np.float64], axis: NDArray[np.float64], angle: float
) -> Pose:
    """``pose`` rotated by ``angle`` (rad) about the line through ``point`` along ``axis``."""
    r = _rotation_about(axis, angle)
    return Pose(point + r @ (pose.position - point), r @ pose.rotation)
