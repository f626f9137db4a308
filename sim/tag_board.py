"""The AprilTag calibration board in the twin: a thin static plate with the board printed on top.

:func:`place_tag_board` renders the board (:func:`skills.perception.calibration.render_board`),
writes it as a PNG to a cache directory and puts it on the top face of a thin box lying on a
surface. The visual is an explicit box mesh: its top face carries texture coordinates ``(0, 0)``
at the board's ``(-x, -y)`` corner and ``(1, 1)`` at ``(+x, +y)``. PyBullet's TinyRenderer takes
``v = 0`` as the image's bottom row, so the image appears the right way round: its top edge
towards the board's ``+y``, not mirrored (checked by rendering and detecting the board, see
``tests/skills/perception/test_calibration.py``). PyBullet's own ``GEOM_BOX`` visual was not
used: it tiles the texture by the box's size instead of stretching it over a face. The other
faces sample the plate's white margin.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np

from drivers.pose import Pose, rot_z
from drivers.tag_board import TagBoard, render_board
from sim.world import SimWorld

#: Plate thickness (m): a printed board glued on a stiff sheet.
BOARD_THICKNESS = 0.003
#: Texture resolution (px/m): 10 px per tag cell on the default board's 40 mm markers.
TEXTURE_PPM = 2000.0


def texture_path(board: TagBoard, pixels_per_metre: float, cache_dir: Path | None = None) -> Path:
    """The board's PNG in ``cache_dir`` (default: ``pivot-cell-textures`` in the temp dir),
    rendered on first use."""
    folder = cache_dir or Path(tempfile.gettempdir()) / "pivot-cell-textures"
    key = hashlib.sha1(repr((board, float(pixels_per_metre))).encode()).hexdigest()[:16]
    path = folder / f"tag_board_{key}.png"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(suffix=".png", dir=folder)
        os.close(fd)
        try:
            if not cv2.imwrite(tmp, render_board(board, pixels_per_metre)):
                raise OSError(f"cannot write the board texture {tmp}")
            os.chmod(tmp, 0o644)  # mkstemp makes it private; other users may share the cache
            os.replace(tmp, path)  # atomic: parallel processes never read half a file
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)
    return path


def _plate_mesh(
    half: tuple[float, float, float], white_uv: tuple[float, float]
) -> tuple[list[list[float]], list[int], list[list[float]], list[list[float]]]:
    """Vertices, indices (counter-clockwise seen from outside), uvs and normals of a box centred
    on the origin; the top face (``+z``) spans the texture, the others sample ``white_uv``."""
    hx, hy, hz = half
    vertices: list[list[float]] = []
    uvs: list[list[float]] = []
    normals: list[list[float]] = []
    indices: list[int] = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            u_axis = np.zeros(3)
            u_axis[(axis + 1) % 3] = 1.0
            v_axis = np.cross(normal, u_axis)  # (u, v, normal) right-handed: CCW from outside
            h = np.array([hx, hy, hz])
            centre = normal * h
            first = len(vertices)
            for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                corner = centre + su * u_axis * h + sv * v_axis * h
                vertices.append(corner.tolist())
                normals.append(normal.tolist())
                if axis == 2 and sign > 0:  # the printed face: board (-x, -y) -> uv (0, 0)
                    uvs.append([0.5 * (1.0 + corner[0] / hx), 0.5 * (1.0 + corner[1] / hy)])
                else:
                    uvs.append(list(white_uv))
            indices += [first, first + 1, first + 2, first, first + 2, first + 3]
    return vertices, indices, uvs, normals


def place_tag_board(
    world: SimWorld,
    board: TagBoard,
    xy: tuple[float, float],
    yaw: float = 0.0,
    surface_z: float = 0.0,
    thickness: float = BOARD_THICKNESS,
    pixels_per_metre: float = TEXTURE_PPM,
    cache_dir: Path | None = None,
) -> tuple[int, Pose]:
    """Lay ``board`` face up on a surface at height ``surface_z`` (m), centred on ``xy`` (m),
    turned by ``yaw`` (rad) about the vertical; a static body.

    Returns its body id and ``world_T_board``: the board frame (see
    :class:`~skills.perception.calibration.TagBoard`) on the printed face, ``z`` up. With the
    robot base at the world origin (as :func:`sim.cell_layout.build_cell` assumes) this is
    ``base_T_board``.
    """
    if not (math.isfinite(thickness) and thickness > 0):
        raise ValueError(f"thickness: must be > 0 m, got {thickness!r}")
    p = world.p
    w, h = board.size
    half = (0.5 * w, 0.5 * h, 0.5 * thickness)
    # A point of the white margin (or the top-left corner of a board without one).
    white_uv = (0.5 * board.margin / w, 0.5)
    vertices, indices, uvs, normals = _plate_mesh(half, white_uv)
    visual = p.createVisualShape(
        p.GEOM_MESH, vertices=vertices, indices=indices, uvs=uvs, normals=normals
    )
    collision = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half))
    world_T_board = Pose(np.array([xy[0], xy[1], surface_z + thickness]), rot_z(yaw))
    body = p.createMultiBody(
        baseMass=0.0,
        baseCollisionShapeIndex=collision,
        baseVisualShapeIndex=visual,
        basePosition=[xy[0], xy[1], surface_z + 0.5 * thickness],
        baseOrientation=world_T_board.quaternion.tolist(),
    )
    texture = p.loadTexture(str(texture_path(board, pixels_per_metre, cache_dir)))
    p.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=[1.0, 1.0, 1.0, 1.0])
    return body, world_T_board
