"""The rendered D435: metric depth, pinhole geometry, D435-like noise, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.camera import Camera
from drivers.pose import Pose, rot_x
from sim.camera import DepthNoise, SimCamera, d435_intrinsics, default_tool_T_camera
from sim.world import SimWorld

HEIGHT = 0.5  # m, optical centre above the floor
BOX = (0.10, 0.06, 0.04)  # m, box on the floor under the camera
MARKER = (0.12, 0.08, 0.002)  # m, centre (x, y) and thickness of an off-axis flat tile
NOISE = DepthNoise()  # the default D435-like model
LOOK_DOWN = Pose(np.array([0.0, 0.0, HEIGHT]), rot_x(math.pi))  # optical z = world -z


def _box(world: SimWorld, half: list[float], centre: list[float], rgba: list[float]) -> int:
    p = world.p
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=rgba)
    return p.createMultiBody(0.0, col, vis, basePosition=centre)


def _scene(seed: int = 0) -> SimWorld:
    world = SimWorld(seed=seed)
    _box(world, [1.0, 1.0, 0.05], [0.0, 0.0, -0.05], [0.5, 0.5, 0.5, 1.0])
    _box(world, [0.5 * s for s in BOX], [0.0, 0.0, 0.5 * BOX[2]], [0.8, 0.1, 0.1, 1.0])
    t = MARKER[2]
    _box(world, [0.01, 0.01, 0.5 * t], [MARKER[0], MARKER[1], 0.5 * t], [0.1, 0.8, 0.1, 1.0])
    return world


def _camera(world: SimWorld, noise: DepthNoise | None = NOISE) -> SimCamera:
    """The default hand-eye offset, with the tool placed so the camera looks straight down."""
    tool = LOOK_DOWN @ default_tool_T_camera().inverse()
    return SimCamera(world, lambda: tool, noise=noise)


def _pixel(cam: SimCamera, world_point: list[float]) -> tuple[float, float, float]:
    """Pinhole projection ``(u, v, z)`` of a world point (pixels, pixels, m)."""
    x, y, z = cam.world_T_camera().inverse().transform(world_point)
    k = cam.intrinsics()
    return k.fx * x / z + k.cx, k.fy * y / z + k.cy, z


def _window_mean(depth: np.ndarray, u: float, v: float, r: int = 3) -> float:
    patch = depth[round(v) - r : round(v) + r + 1, round(u) - r : round(u) + r + 1]
    return float(patch[patch > 0].mean())


def test_frame_shape_dtypes_stamp_and_protocol() -> None:
    with _scene() as world:
        cam = _camera(world)
        assert isinstance(cam, Camera)
        for _ in range(5):
            world.step()
        frame = cam.capture()
        assert frame.rgb.shape == (480, 640, 3) and frame.rgb.dtype == np.uint8
        assert frame.depth.shape == (480, 640) and frame.depth.dtype == np.float32
        assert frame.stamp == pytest.approx(world.clock.now()) and frame.stamp > 0
    k = cam.intrinsics()
    assert (k.width, k.height, k.cx, k.cy) == (640, 480, 319.5, 239.5)
    assert 2 * math.degrees(math.atan(320 / k.fx)) == pytest.approx(69.0)
    assert 2 * math.degrees(math.atan(240 / k.fy)) == pytest.approx(42.0)
    assert cam.world_T_camera().distance(LOOK_DOWN)[0] < 1e-12


def test_depth_is_metric_along_the_optical_axis() -> None:
    with _scene() as world:
        depth = _camera(world).capture().depth
        cam = _camera(world)
        u, v, z_top = _pixel(cam, [0.0, 0.0, BOX[2]])
        assert z_top == pytest.approx(HEIGHT - BOX[2])
        assert _window_mean(depth, u, v) == pytest.approx(z_top, abs=0.003)
        # Floor well away from the box, off the optical axis: depth is z, not the ray length.
        u, v, z_floor = _pixel(cam, [-0.15, 0.10, 0.0])
        assert _window_mean(depth, u, v) == pytest.approx(HEIGHT, abs=0.005)


def test_back_projected_top_face_has_the_box_size() -> None:
    with _scene() as world:
        cam = _camera(world)
        depth = cam.capture().depth.astype(float)
        k = cam.intrinsics()
        top = HEIGHT - BOX[2]
        vs, us = np.nonzero(np.abs(depth - top) < 0.01)
        near_axis = (np.abs(us - k.cx) < 120) & (np.abs(vs - k.cy) < 120)
        vs, us = vs[near_axis], us[near_axis]
        z = float(np.median(depth[vs, us]))
        width_x = (us.max() - us.min() + 1) * z / k.fx  # optical x = world x
        width_y = (vs.max() - vs.min() + 1) * z / k.fy  # optical y = world -y
        assert width_x == pytest.approx(BOX[0], abs=0.003)
        assert width_y == pytest.approx(BOX[1], abs=0.003)


def test_image_is_not_mirrored_a_tile_appears_where_it_projects() -> None:
    with _scene() as world:
        cam = _camera(world, noise=None)
        frame = cam.capture()
        rgb = frame.rgb.astype(int)
        vs, us = np.nonzero((rgb[..., 1] > 2 * rgb[..., 0]) & (rgb[..., 1] > 2 * rgb[..., 2]))
        u, v, _ = _pixel(cam, [MARKER[0], MARKER[1], MARKER[2]])
        assert us.mean() == pytest.approx(u, abs=0.7)
        assert vs.mean() == pytest.approx(v, abs=0.7)
        assert u > cam.intrinsics().cx and v < cam.intrinsics().cy  # world +x right, +y up


def test_noise_has_the_d435_model_statistics() -> None:
    noise = DepthNoise()
    with _scene() as world:
        exact = _camera(world, noise=None).capture().depth
        noisy = _camera(world, noise=noise).capture().depth
    floor = (np.abs(exact - HEIGHT) < 1e-4) & (noisy > 0)
    err = (noisy - exact)[floor]
    assert abs(err.mean()) < 2e-4
    assert err.std() == pytest.approx(noise.sigma(HEIGHT), rel=0.05)
    dropped = np.mean(noisy[exact > 0] == 0)
    assert dropped == pytest.approx(noise.invalid_fraction, rel=0.3)


def test_background_and_beyond_far_read_zero() -> None:
    with SimWorld() as world:
        _box(world, [1.0, 1.0, 0.05], [0.0, 0.0, -0.05], [0.5, 0.5, 0.5, 1.0])
        high = Pose(np.array([0.0, 0.0, 2.5]), rot_x(math.pi))  # floor 2.5 m away, far = 2 m
        assert np.all(SimCamera(world, lambda: high, Pose()).capture().depth == 0)
        up = Pose(np.array([0.0, 0.0, 0.5]))  # looking at the sky
        assert np.all(SimCamera(world, lambda: up, Pose()).capture().depth == 0)


def test_same_seed_same_frames() -> None:
    frames = []
    for seed in (7, 7, 8):
        with _scene(seed) as world:
            frames.append(_camera(world).capture())
    assert np.array_equal(frames[0].depth, frames[1].depth)
    assert np.array_equal(frames[0].rgb, frames[1].rgb)
    assert not np.array_equal(frames[0].depth, frames[2].depth)


def test_intrinsics_helper_and_bad_range() -> None:
    k = d435_intrinsics()
    assert k.fx == pytest.approx(320 / math.tan(math.radians(34.5)))
    assert k.fy == pytest.approx(240 / math.tan(math.radians(21.0)))
    with SimWorld() as world, pytest.raises(ValueError, match="near"):
        SimCamera(world, Pose, near=0.5, far=0.2)


def test_links_crossing_the_near_plane_are_left_out_and_restored() -> None:
    # The eye-in-hand camera at a low, tilted grasp pose (joint angles read from an emulated
    # cell's Grasp): the finger boxes' bases lie in the camera's plane. TinyRenderer does not
    # clip at the near plane, so such a face is left out of the frame (and drawn again after).
    from sim.robot import SimRobot

    with SimWorld(seed=1) as world:
        robot = SimRobot(world)
        p = world.p
        grasp = (2.9348, -1.3795, 1.9178, -1.8303, -1.6298, 1.3677)
        for j, q in zip(range(1, 7), grasp, strict=True):
            p.resetJointState(robot.body_id, j, q)
        names = {p.getJointInfo(robot.body_id, j)[12].decode(): j
                 for j in range(p.getNumJoints(robot.body_id))}
        fingers = {names["finger_a"], names["finger_b"]}
        for j in fingers:
            p.resetJointState(robot.body_id, j, 0.04)
        floor = _box(world, [0.4, 0.4, 0.025], [0.45, 0.0, -0.225], [0.5, 0.5, 0.5, 1.0])
        cam = SimCamera(world, lambda: robot.world_pose(robot.arm.tool_pose()),
                        intrinsics=d435_intrinsics(64, 48), noise=None)
        rgba = {v[1]: v[7] for v in p.getVisualShapeData(robot.body_id)}
        hidden = cam._hide_links_crossing_near(cam.world_T_camera())
        try:
            assert fingers <= {link for body, link in hidden if body == robot.body_id}
            assert all(body == robot.body_id for body, _ in hidden)  # not the floor 0.2 m off
            assert all(v[7][3] == 0.0 for v in p.getVisualShapeData(robot.body_id)
                       if v[1] in fingers)
        finally:
            for body, link in hidden:
                p.changeVisualShape(body, link, rgbaColor=cam._colours[(body, link)])
        n = cam.links_hidden
        _, depth = cam.render(cam.world_T_camera())
        assert cam.links_hidden == 2 * n  # the same links, once more
        assert {v[1]: v[7] for v in p.getVisualShapeData(robot.body_id)} == rgba  # drawn again
        assert (depth > 0).mean() > 0.9 and floor >= 0  # the floor below is seen
