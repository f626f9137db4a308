"""The UR5's kinematics with the cell's tool (pure numpy, no simulator): the chain against the
UR5's Denavit-Hartenberg forward kinematics, the Jacobian, the TCP, the home pose and the IK."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drivers.pose import Pose
from drivers.ur5 import kinematics as kin

# UR5 Denavit-Hartenberg parameters (Universal Robots' published values), m and rad.
DH_D = (0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823)
DH_A = (0.0, -0.425, -0.39225, 0.0, 0.0, 0.0)
DH_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)


def dh_flange(q: np.ndarray) -> np.ndarray:
    """base_T_flange from the standard DH convention, independent of the URDF chain."""
    m = np.eye(4)
    for theta, d, a, alpha in zip(q, DH_D, DH_A, DH_ALPHA, strict=True):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        m = m @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0, sa, ca, d],
                [0, 0, 0, 1],
            ]
        )
    return m


def test_fk_matches_dh_for_random_joints() -> None:
    rng = np.random.default_rng(0)
    for q in rng.uniform(-2 * math.pi, 2 * math.pi, (200, 6)):
        ours = kin.flange_matrix(q)
        ref = dh_flange(q)
        assert np.linalg.norm(ours[:3, 3] - ref[:3, 3]) < 1e-6
        assert np.abs(ours[:3, :3] - ref[:3, :3]).max() < 1e-9


def test_tcp_is_on_the_tool_z_axis_past_the_fingertips_minus_5_mm() -> None:
    q = np.random.default_rng(1).uniform(-3, 3, 6)
    flange, tcp = kin.forward_kinematics(q, tcp=False), kin.forward_kinematics(q)
    offset = flange.inverse() @ tcp
    assert np.allclose(offset.position, [0, 0, kin.TCP_Z], atol=1e-12)
    assert np.allclose(offset.rotation, np.eye(3), atol=1e-12)
    # puck, gripper body, fingers open, the linkage's advance to closed, less 5 mm
    assert kin.TCP_Z == pytest.approx(0.0375 + 0.09 + 0.055 + 0.0132 - 0.005, abs=1e-4)


def test_jacobian_matches_finite_differences() -> None:
    q = np.random.default_rng(2).uniform(-3, 3, 6)
    jac, pose = kin.jacobian(q)
    eps = 1e-7
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = eps
        moved = kin.forward_kinematics(q + dq)
        lin = (moved.position - pose.position) / eps
        ang = Rotation.from_matrix(moved.rotation @ pose.rotation.T).as_rotvec() / eps
        assert np.allclose(jac[:3, i], lin, atol=1e-6)
        assert np.allclose(jac[3:, i], ang, atol=1e-6)


def test_home_points_the_tool_down_in_front() -> None:
    home = kin.forward_kinematics(kin.HOME_JOINTS)
    d, angle = home.distance(kin.HOME_TCP)
    assert d < 1e-8 and angle < 1e-8
    assert kin.HOME_TCP.position[0] == pytest.approx(0.5)
    assert np.allclose(kin.HOME_TCP.rotation[:, 2], [0, 0, -1])


def test_solve_ik_reaches_a_pose_in_front_and_reports_one_out_of_reach() -> None:
    tilt = Rotation.from_euler("y", 0.3).as_matrix()
    target = kin.HOME_TCP @ Pose(np.array([0.05, -0.1, 0.08]), tilt)
    q, miss = kin.solve_ik(target, kin.HOME_JOINTS)
    assert miss < 1e-8
    d, angle = kin.forward_kinematics(q).distance(target)
    assert d < 1e-8 and angle < 1e-7
    far = Pose(np.array([1.2, 0.0, 0.3]), kin.HOME_TCP.rotation)  # the UR5 reaches 0.85 m
    _, miss = kin.solve_ik(far, kin.HOME_JOINTS, iterations=200)
    assert miss > kin.REACH_TOLERANCE
