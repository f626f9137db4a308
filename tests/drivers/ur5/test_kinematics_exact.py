"""The fast kinematics give the numbers of the plain numpy formulas, bit for bit.

Why bit for bit: the twin's arm runs these every control step and its contacts are chaotic, so a
difference in the last bit of one joint command changes trial outcomes. The references below
are the formulas as numpy evaluates them (what the twin ran before the float rewrite); the
rewrite keeps every numpy matrix product (BLAS rounds those its own way) and replaces the rest
by the same operations in the same order on floats.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drivers.pose import Pose
from drivers.ur5 import kinematics as kin


def _chain_ref(q: np.ndarray) -> tuple[list, list, tuple, tuple]:
    r, p = kin._BASE
    axes, origins = [], []
    for (r_o, p_o), about_z, angle in zip(kin._ORIGINS, kin._ABOUT_Z, q, strict=True):
        p = kin._apply(r, p, p_o)
        r = kin._mul(r, r_o)
        c, s = math.cos(angle), math.sin(angle)
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = r
        if about_z:
            axes.append((r2, r5, r8))
            r = (c * r0 + s * r1, c * r1 - s * r0, r2,
                 c * r3 + s * r4, c * r4 - s * r3, r5,
                 c * r6 + s * r7, c * r7 - s * r6, r8)  # fmt: skip
        else:
            axes.append((r1, r4, r7))
            r = (c * r0 - s * r2, r1, s * r0 + c * r2,
                 c * r3 - s * r5, r4, s * r3 + c * r5,
                 c * r6 - s * r8, r7, s * r6 + c * r8)  # fmt: skip
        origins.append(p)
    p = kin._apply(r, p, kin._TOOL0[1])
    return axes, origins, kin._mul(r, kin._TOOL0[0]), p


def _jacobian_ref(q: np.ndarray) -> tuple[np.ndarray, Pose]:
    axes, origins, r, p = _chain_ref(q)
    e = (p[0] + kin.TCP_Z * r[2], p[1] + kin.TCP_Z * r[5], p[2] + kin.TCP_Z * r[8])
    columns = []
    for (ax, ay, az), (ox, oy, oz) in zip(axes, origins, strict=True):
        dx, dy, dz = e[0] - ox, e[1] - oy, e[2] - oz
        columns.append((ay * dz - az * dy, az * dx - ax * dz, ax * dy - ay * dx, ax, ay, az))
    return np.array(columns).T, Pose(np.array(e), np.array(r).reshape(3, 3))


def _matrix_to_rotvec_ref(m: np.ndarray) -> np.ndarray:
    cos = min(max((m[0, 0] + m[1, 1] + m[2, 2] - 1.0) * 0.5, -1.0), 1.0)
    angle = float(np.arccos(cos))
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    if angle < 1e-6:
        return 0.5 * w
    if angle > np.pi - 1e-3:
        return Rotation.from_matrix(m).as_rotvec()
    return (angle / (2.0 * np.sin(angle))) * w


def _rotvec_to_matrix_ref(v: np.ndarray) -> np.ndarray:
    angle = float(np.sqrt(v @ v))
    if angle < 1e-12:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)


def _pose_error_ref(target: Pose, current: Pose) -> np.ndarray:
    rotation = _matrix_to_rotvec_ref(target.rotation @ current.rotation.T)
    return np.concatenate([target.position - current.position, rotation])


def _residual_ref(err: np.ndarray) -> float:
    return float(np.sqrt(err[:3] @ err[:3]) + kin.ROTATION_LENGTH * np.sqrt(err[3:] @ err[3:]))


def _dls_step_ref(jac: np.ndarray, err: np.ndarray, damping: float = 1e-3) -> np.ndarray:
    dq = jac.T @ np.linalg.solve(jac @ jac.T + damping**2 * np.eye(6), err)
    biggest = float(np.max(np.abs(dq)))
    if biggest > 0.3:
        dq *= 0.3 / biggest
    return dq


def _same(a: object, b: object) -> bool:
    x, y = np.asarray(a, float), np.asarray(b, float)
    return x.shape == y.shape and x.tobytes() == y.tobytes()


def _within_an_ulp(a: object, b: object, ulps: int = 1) -> bool:
    """Equal but for the last bits, for the formulas numpy evaluates with its own vector loops.

    numpy's small dots (with or without fused multiply-adds) and its SIMD sin/cos (not correctly
    rounded, unlike ``math``'s) depend on its build and the CPU: numpy 2.4 on this project's x86
    machines differs from the reference in the last bit of a residual and by up to 16 units in the
    last place of a Rodrigues matrix. So the reference's last bits there are the build's, not the
    formula's; the chains, Jacobians, errors and solver steps stay bit for bit.
    """
    x, y = np.asarray(a, float), np.asarray(b, float)
    tolerance = ulps * np.spacing(np.maximum(np.abs(y), 1.0))
    return x.shape == y.shape and bool(np.all(np.abs(x - y) <= tolerance))


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(7)


def test_jacobian_and_forward_kinematics_are_the_reference_bits(rng) -> None:
    for q in rng.uniform(-2 * math.pi, 2 * math.pi, (500, 6)):
        jac_ref, pose_ref = _jacobian_ref(q)
        jac, position, rotation = kin.jacobian_frame(q)
        assert _same(jac, jac_ref) and jac.strides == jac_ref.strides
        assert _same(position, pose_ref.position) and _same(rotation, pose_ref.rotation)
        jac2, pose = kin.jacobian(q)
        assert _same(jac2, jac_ref) and _same(pose.position, pose_ref.position)
        fk = kin.forward_kinematics(q)
        assert _same(fk.position, pose_ref.position) and _same(fk.rotation, pose_ref.rotation)


def test_rotations_errors_and_steps_are_the_reference_bits(rng) -> None:
    for _ in range(2000):
        q = rng.uniform(-2 * math.pi, 2 * math.pi, 6)
        jac, pose = _jacobian_ref(q)
        # Rotation vectors from nothing through tiny (the small-angle branch) to near a half turn.
        scale = float(rng.choice([0.0, 1e-13, 1e-9, 1e-7, 1e-4, 1e-2, 1.0, math.pi - 5e-4]))
        axis = rng.normal(size=3)
        v = scale * axis / np.linalg.norm(axis)
        turn = _rotvec_to_matrix_ref(v)
        assert _within_an_ulp(kin.rotvec_to_matrix(v), turn, ulps=32)
        assert _within_an_ulp(kin.rotvec_to_matrix(v.tolist()), turn, ulps=32)
        assert _same(kin.matrix_to_rotvec(turn), _matrix_to_rotvec_ref(turn))
        target = Pose(pose.position + rng.normal(size=3) * 10.0 ** rng.integers(-9, 0),
                      pose.rotation @ turn)  # fmt: skip
        err_ref = _pose_error_ref(target, pose)
        err = kin.pose_error(target, pose)
        assert _same(err, err_ref)
        assert _same(
            kin.frame_error_list(target.position, target.rotation, pose.position, pose.rotation),
            err_ref,
        )
        assert _within_an_ulp(kin.residual(err), _residual_ref(err_ref))
        assert _within_an_ulp(kin.residual(err.tolist()), _residual_ref(err_ref))
        for gain in (1.0, 1e3):  # a small step, and one cut to 0.3 rad
            assert _same(kin.dls_step(jac, gain * err), _dls_step_ref(jac, gain * err_ref))
        assert _same(kin.dls_step(jac, err, damping=0.01), _dls_step_ref(jac, err_ref, 0.01))


def test_solve_ik_is_the_reference_iteration(rng) -> None:
    def solve_ik_ref(target: Pose, seed: np.ndarray, iterations: int) -> tuple[np.ndarray, float]:
        q = np.array(seed, float)
        for _ in range(iterations):
            jac, pose = _jacobian_ref(q)
            err = _pose_error_ref(target, pose)
            if _residual_ref(err) < 1e-9:
                return q, _residual_ref(err)
            q = np.clip(q + _dls_step_ref(jac, err), -kin.ARM_LIMIT, kin.ARM_LIMIT)
        return q, _residual_ref(_pose_error_ref(target, _jacobian_ref(q)[1]))

    for _ in range(30):
        q = rng.uniform(-3, 3, 6)
        target = _jacobian_ref(q)[1]
        seed = q + rng.normal(size=6) * 0.1
        for iterations in (3, 50):
            q_ref, miss_ref = solve_ik_ref(target, seed, iterations)
            q_new, miss = kin.solve_ik(target, seed, iterations=iterations)
            assert _same(q_new, q_ref) and _within_an_ulp(miss, miss_ref)
