"""The eye-in-hand RGB-D camera of the twin: a D435 rendered by PyBullet's software renderer.

:class:`SimCamera` implements :class:`drivers.camera.Camera`. It renders 640 x 480 RGB and depth
with ``ER_TINY_RENDERER`` (no display, no GPU needed) through a projection matrix built from the
pinhole intrinsics, so pixel ``(u, v)`` of a point at ``(x, y, z)`` in the optical frame is
``(fx x / z + cx, fy y / z + cy)`` exactly as for the real camera; perception code cannot tell
them apart by geometry. Depth is metric (m) along the optical axis, 0 where invalid: beyond
``far``, background, or a dropped pixel of the noise model.

Frames: the optical frame is ``z`` forward, ``x`` right, ``y`` down (the driver's convention).
Its pose in the world (the robot-base frame) is ``base_T_tool() @ tool_T_camera()``; the tool
pose comes from a callable so the camera works with or without the robot model.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from drivers.camera import Frame, Intrinsics
from drivers.pose import Pose
from sim.world import SimWorld

#: OpenGL's camera looks along -z with y up; the optical frame is this rotated by pi about x.
_OPTICAL_T_GL = np.diag([1.0, -1.0, -1.0])


def d435_intrinsics(
    width: int = 640, height: int = 480, hfov_deg: float = 69.0, vfov_deg: float = 42.0
) -> Intrinsics:
    """Pinhole intrinsics (pixels) with the D435 colour stream's field of view (deg).

    The project keeps the 69 x 42 deg field of view at 640 x 480, so pixels are not square:
    ``fx = 320 / tan(34.5 deg)``, ``fy = 240 / tan(21 deg)``; the principal point is the image
    centre in the pixel-centre convention (``cx = 319.5``, ``cy = 239.5``).
    """
    return Intrinsics(
        width=width,
        height=height,
        fx=0.5 * width / math.tan(math.radians(0.5 * hfov_deg)),
        fy=0.5 * height / math.tan(math.radians(0.5 * vfov_deg)),
        cx=0.5 * (width - 1),
        cy=0.5 * (height - 1),
    )


@dataclass(frozen=True)
class DepthNoise:
    """A D435-like depth error: ``sigma(z) = sigma0 + k z^2`` (m) plus dropped pixels.

    Stereo depth error grows with the square of the range; at 0.5 m this gives 1.25 mm.
    ``invalid_fraction`` of the pixels read 0 (no stereo match), chosen at random each frame.
    """

    sigma0: float = 0.0008  #: m
    k: float = 0.0018  #: 1/m
    invalid_fraction: float = 0.003

    def sigma(self, z: NDArray[np.floating] | float) -> NDArray[np.floating] | float:
        """Standard deviation (m) of the depth at range ``z`` (m)."""
        return self.sigma0 + self.k * np.square(z)


def default_tool_T_camera() -> Pose:
    """The camera 0.08 m off the tool axis on ``-y`` and 0.05 m back along tool ``z``.

    The optical axis is parallel to the tool's ``z`` (the approach direction), so the camera looks
    where the fingers go; optical ``x``/``y`` are the tool's ``x``/``y``.
    """
    return Pose(np.array([0.0, -0.08, -0.05]), np.eye(3))


def projection_matrix(intr: Intrinsics, near: float, far: float) -> NDArray[np.float64]:
    """OpenGL projection (4x4, row-major) reproducing the pinhole model of ``intr`` exactly.

    PyBullet's TinyRenderer samples pixel column ``i``, row ``j`` (rows from the top) at the
    integer viewport point ``(i, H - 1 - j)`` of its bottom-up viewport ``[0, W] x [0, H]``
    (measured: a sharp edge flips a pixel at the predicted sub-pixel position). The principal
    point terms put pinhole ``(u, v) = (i, j)`` there, so a point projecting to ``(cx, cy)`` is
    seen by pixel ``(cx, cy)``, not half a pixel off.
    """
    w, h = intr.width, intr.height
    return np.array(
        [
            [2.0 * intr.fx / w, 0.0, 1.0 - 2.0 * intr.cx / w, 0.0],
            [0.0, 2.0 * intr.fy / h, 2.0 * (intr.cy + 1.0) / h - 1.0, 0.0],
            [0.0, 0.0, -(far + near) / (far - near), -2.0 * far * near / (far - near)],
            [0.0, 0.0, -1.0, 0.0],
        ]
    )


def view_matrix(world_T_optical: Pose) -> NDArray[np.float64]:
    """OpenGL view matrix (4x4, row-major): world -> OpenGL camera frame."""
    rot = world_T_optical.rotation @ _OPTICAL_T_GL
    m = np.eye(4)
    m[:3, :3] = rot.T
    m[:3, 3] = -rot.T @ world_T_optical.position
    return m


class SimCamera:
    """A rendered D435 on the tool (implements :class:`drivers.camera.Camera`).

    ``base_T_tool`` returns the current tool pose in the world (m, rad); ``tool_T_camera`` is the
    hand-eye calibration (default :func:`default_tool_T_camera`). ``near`` / ``far`` (m) bound the
    rendered range; nothing closer than ``near`` is seen (the D435's minimum range is similar).
    ``noise=None`` gives exact depth. All randomness comes from ``world.rng``.

    ``mount_error``: where the camera really sits in the frame of the calibrated mount (a
    hand-eye calibration's error, :meth:`sim.uncertainty.Draws.mount_error`). Frames are
    rendered from the true mount, ``tool_T_camera @ mount_error``, while :meth:`tool_T_camera`
    keeps reporting the calibrated one, as a real cell's calibration does: whatever perceives
    with it sees the scene off by the error, through the geometry, nothing added afterwards.
    """

    def __init__(
        self,
        world: SimWorld,
        base_T_tool: Callable[[], Pose],
        tool_T_camera: Pose | None = None,
        intrinsics: Intrinsics | None = None,
        noise: DepthNoise | None = DepthNoise(),
        near: float = 0.1,
        far: float = 2.0,
        mount_error: Pose | None = None,
    ) -> None:
        if not 0.0 < near < far:
            raise ValueError(f"need 0 < near < far, got near={near} m, far={far} m")
        self.world = world
        self._base_T_tool = base_T_tool
        #: frames handed out by :meth:`capture` so far (a judge counts which skill looked)
        self.frames_taken = 0
        self._tool_T_camera = (
            tool_T_camera if tool_T_camera is not None else default_tool_T_camera()
        )
        #: the mount the frames are rendered from (the calibrated one, off by ``mount_error``)
        self._true_tool_T_camera = (
            self._tool_T_camera if mount_error is None else self._tool_T_camera @ mount_error
        )
        self._intrinsics = intrinsics if intrinsics is not None else d435_intrinsics()
        self.noise = noise
        self.near = near
        self.far = far
        self._projection = projection_matrix(self._intrinsics, near, far).T.ravel().tolist()
        # (body, link) -> its rgba; None: the link draws nothing (asked once, not every frame)
        self._colours: dict[tuple[int, int], list[float] | None] = {}
        #: links left out of the frames rendered so far because they crossed the near plane
        self.links_hidden = 0

    def intrinsics(self) -> Intrinsics:
        """Colour-aligned intrinsics (pixels); depth is rendered aligned to colour."""
        return self._intrinsics

    def tool_T_camera(self) -> Pose:
        """Pose of the optical frame in the tool frame (m, rad): the calibrated mount."""
        return self._tool_T_camera

    def true_tool_T_camera(self) -> Pose:
        """Where the optical frame really is in the tool frame (m, rad): the calibrated mount
        off by ``mount_error`` (the twin's truth, for tests and the judge)."""
        return self._true_tool_T_camera

    def world_T_camera(self) -> Pose:
        """Pose of the optical frame in the world (robot-base) frame now (m, rad): where the
        frames are rendered from (the true mount)."""
        return self._base_T_tool() @ self._true_tool_T_camera

    def capture(self) -> Frame:
        """Render the scene now; ``stamp`` is the simulation time (s). Never times out."""
        self.frames_taken += 1
        rgb, depth = self.render(self.world_T_camera())
        if self.noise is not None:
            depth = self._add_noise(depth)
        return Frame(rgb=rgb, depth=depth.astype(np.float32), stamp=self.world.clock.now())

    def render(self, world_T_optical: Pose) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
        """Noise-free RGB (H, W, 3) uint8 and metric depth (H, W) m, 0 = nothing within ``far``."""
        intr = self._intrinsics
        p = self.world.p
        hidden = self._hide_links_crossing_near(world_T_optical)
        try:
            _, _, rgba, zbuf, _ = p.getCameraImage(
                intr.width,
                intr.height,
                viewMatrix=view_matrix(world_T_optical).T.ravel().tolist(),
                projectionMatrix=self._projection,
                shadow=0,
                renderer=p.ER_TINY_RENDERER,
                flags=p.ER_NO_SEGMENTATION_MASK,
            )
        finally:
            for key in hidden:
                p.changeVisualShape(*key, rgbaColor=self._colours[key])
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(intr.height, intr.width, 4)[..., :3].copy()
        zbuf = np.asarray(zbuf, dtype=np.float64).reshape(intr.height, intr.width)
        n, f = self.near, self.far
        depth = f * n / (f - (f - n) * zbuf)  # OpenGL depth buffer -> distance along z (m)
        depth[(zbuf >= 1.0 - 1e-7) | (depth >= f)] = 0.0
        return rgb, depth

    def _hide_links_crossing_near(self, world_T_optical: Pose) -> list[tuple[int, int]]:
        """Make every link whose bounding box spans the near plane transparent for one render.

        Why: TinyRenderer does not clip triangles at the near plane. A face with a vertex at or
        behind the camera's plane projects across the whole image: the twin's finger boxes, whose
        bases lie in the eye-in-hand camera's plane, came out as one white wall at the near plane
        and took 11 s to rasterise (measured at a closed grasp; 0.07 s with the finger left out).
        A real D435 sees such a link only where it is in front of the lens, mostly closer than
        its minimum range (no depth there), so leaving it out costs the perception nothing; the
        count is kept in :attr:`links_hidden`.
        """
        p = self.world.p
        rot, pos = world_T_optical.rotation, world_T_optical.position
        hidden: list[tuple[int, int]] = []
        for i in range(p.getNumBodies()):
            body = p.getBodyUniqueId(i)
            for link in range(-1, p.getNumJoints(body)):
                lo, hi = p.getAABB(body, link)
                corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                    for z in (lo[2], hi[2])])
                depth = (corners - pos) @ rot[:, 2]  # along the optical axis
                if depth.min() >= self.near or depth.max() <= 0.0:
                    continue  # wholly beyond the near plane, or wholly behind the camera
                key = (body, link)
                if key not in self._colours:
                    shapes = [v for v in p.getVisualShapeData(body) if v[1] == link]
                    self._colours[key] = list(shapes[0][7]) if shapes else None
                rgba = self._colours[key]
                if rgba is None:
                    continue  # nothing drawn
                p.changeVisualShape(body, link, rgbaColor=[rgba[0], rgba[1], rgba[2], 0.0])
                hidden.append(key)
        self.links_hidden += len(hidden)
        return hidden

    def _add_noise(self, depth: NDArray[np.float64]) -> NDArray[np.float64]:
        """Gaussian range-dependent error and dropped pixels (draws a fixed amount per frame)."""
        assert self.noise is not None
        rng = self.world.rng
        gauss = rng.standard_normal(depth.shape)
        drop = rng.random(depth.shape) < self.noise.invalid_fraction
        valid = depth > 0.0
        out = np.where(valid, depth + gauss * self.noise.sigma(depth), 0.0)
        out[drop | (out < 0.0)] = 0.0
        return out
