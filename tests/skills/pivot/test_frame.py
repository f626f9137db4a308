"""Fig. 10's geometry: the grasp pose puts the fingers on S and H, the Tilt is an arc about P_c."""

import math

import numpy as np
import pytest

from drivers.parts import Section, delta_round
from skills.pivot.frame import PivotFrame, rotate_about_point

SECTION = Section(0.034, 0.017, delta_round(0.034, 0.028, 0.020))


def frame(yaw: float = 0.3) -> PivotFrame:
    return PivotFrame(SECTION, np.array([0.5, 0.1, 0.017]), yaw, floor_z=0.0)


@pytest.mark.parametrize("yaw", [0.0, 0.3, -2.0])
def test_grasp_pose_puts_the_fingers_on_s_and_h(yaw: float) -> None:
    f = frame(yaw)
    la, alpha, tip = 0.9, math.radians(16.3), 0.005
    pose = f.grasp_pose(la, alpha, tip)
    x, z = pose.rotation[:, 0], pose.rotation[:, 2]
    assert np.allclose(pose.rotation.T @ pose.rotation, np.eye(3))
    assert np.linalg.det(pose.rotation) == pytest.approx(1.0)
    opening = f.opening(la, alpha)
    a, b, d = SECTION.a, SECTION.b, SECTION.delta
    # the S finger's inner tip corner is on the top surface at l from the open end
    s_tip = pose.position + 0.5 * opening * x + tip * z
    assert np.allclose(s_tip, f.point(a - 2 * a * la, 2 * b), atol=1e-12)
    # H lies on the H finger's inner face, e_H behind its tip
    h = f.point(a, 2 * b - d)
    h_face = pose.position - 0.5 * opening * x
    rel = h - h_face
    assert abs(rel @ x) < 1e-12  # on the face plane
    assert abs(rel @ pose.rotation[:, 1]) < 1e-12  # in the pivot plane
    assert tip - rel @ z == pytest.approx(f.hook_depth(la, alpha))
    # fingers point down, tilted by alpha from the vertical
    assert z[2] == pytest.approx(-math.cos(alpha))


def test_tilt_is_an_arc_about_the_pivot_that_lifts_the_open_end() -> None:
    f = frame()
    grasp = f.grasp_pose(0.9, 0.3, 0.005)
    r = f.radius(grasp)
    path = f.tilt_path(grasp, math.pi / 2)
    assert len(path) == 45
    for pose in path:
        assert np.linalg.norm(pose.position - f.pivot) == pytest.approx(r)
    # the open end's rim H ends straight above the pivot side at the part's full length
    h = f.point(SECTION.a, 2 * SECTION.b - SECTION.delta)
    end = f.tilt_pose(grasp, math.pi / 2)
    h_end = end.transform(grasp.inverse().transform(h))
    assert h_end[2] == pytest.approx(2 * SECTION.a)
    assert (h_end - f.pivot) @ f.u == pytest.approx(-(2 * SECTION.b - SECTION.delta))


def test_rotate_about_point_keeps_the_point() -> None:
    f = frame()
    pose = f.grasp_pose(0.9, 0.3, 0.005)
    point = pose.position + np.array([0.01, 0.02, -0.03])
    turned = rotate_about_point(pose, point, f.normal, 0.7)
    local = pose.inverse().transform(point)
    assert np.allclose(turned.transform(local), point)
