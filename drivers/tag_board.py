"""The AprilTag calibration board: a fixture of the cell, described once for the hand-eye
calibration (``skills.perception.calibration``) that detects it and the twin (``sim/tag_board.py``)
that renders it -- both import it from here, below either."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

#: The tag family of every board: AprilTag 36h11 (8 x 8 cells with the black border).
TAG_DICTIONARY = cv2.aruco.DICT_APRILTAG_36h11
TAG_CELLS = 8  # 6 x 6 data bits + a one-cell black border on each side


def tag_dictionary() -> cv2.aruco.Dictionary:
    return cv2.aruco.getPredefinedDictionary(TAG_DICTIONARY)


# ----------------------------------------------------------------------------------- the board
@dataclass(frozen=True)
class TagBoard:
    """A ``columns`` x ``rows`` grid of AprilTag 36h11 markers (sizes in m).

    ``marker_size``: side of a marker's black square (the outer edge of its border);
    ``marker_gap``: white space between neighbouring markers; ``margin``: white space around the
    grid to the plate's edge (a detector needs some white outside the outer markers).
    ``first_id``: id of the top-left marker; the marker in row ``r`` (from the top) and column
    ``c`` has id ``first_id + r * columns + c``.
    """

    columns: int = 4
    rows: int = 3
    marker_size: float = 0.04
    marker_gap: float = 0.01
    margin: float = 0.01
    first_id: int = 0

    def __post_init__(self) -> None:
        if self.columns < 1 or self.rows < 1:
            raise ValueError(
                f"board: needs at least 1 x 1 markers, got {self.columns} x {self.rows}"
            )
        for name in ("marker_size", "marker_gap", "margin"):
            value = getattr(self, name)
            if not math.isfinite(value) or value < 0 or (name == "marker_size" and value == 0):
                raise ValueError(f"board: {name}: must be a finite size in m, got {value!r}")
        count = tag_dictionary().bytesList.shape[0]
        if self.first_id < 0 or self.first_id + self.columns * self.rows > count:
            raise ValueError(
                f"board: first_id: ids {self.first_id}..{self.first_id + self.count - 1} are not "
                f"all in AprilTag 36h11 (0..{count - 1})"
            )

    @property
    def count(self) -> int:
        """Number of markers."""
        return self.columns * self.rows

    @property
    def ids(self) -> NDArray[np.int_]:
        """Marker ids, row by row from the top left."""
        return np.arange(self.first_id, self.first_id + self.count)

    @property
    def grid_size(self) -> tuple[float, float]:
        """Width and height (m) of the marker grid."""
        pitch = self.marker_size + self.marker_gap
        return (
            self.columns * pitch - self.marker_gap,
            self.rows * pitch - self.marker_gap,
        )

    @property
    def size(self) -> tuple[float, float]:
        """Width (along ``x``) and height (along ``y``) of the whole plate (m), margins included."""
        w, h = self.grid_size
        return (w + 2 * self.margin, h + 2 * self.margin)

    def marker_corners(self) -> NDArray[np.float64]:
        """``(count, 4, 3)``: each marker's corners in the board frame (m), in :attr:`ids` order.

        Corner order is OpenCV's: top-left, top-right, bottom-right, bottom-left as the printed
        board is seen (clockwise in the image), ``z = 0``.
        """
        s, pitch = self.marker_size, self.marker_size + self.marker_gap
        w, h = self.grid_size
        out = np.zeros((self.count, 4, 3))
        for r in range(self.rows):
            for c in range(self.columns):
                x0, y0 = -0.5 * w + c * pitch, 0.5 * h - r * pitch  # top-left corner
                out[r * self.columns + c, :, :2] = [
                    [x0, y0],
                    [x0 + s, y0],
                    [x0 + s, y0 - s],
                    [x0, y0 - s],
                ]
        return out

    def corners_of(self, marker_id: int) -> NDArray[np.float64]:
        """``(4, 3)`` corners (m, board frame) of one marker; ``KeyError`` if not on the board."""
        index = int(marker_id) - self.first_id
        if not 0 <= index < self.count:
            raise KeyError(f"marker {marker_id} is not on the board")
        return self.marker_corners()[index]


def render_board(board: TagBoard, pixels_per_metre: float = 2000.0) -> NDArray[np.uint8]:
    """The printable board: a grey image (H, W) uint8, white plate and black markers.

    Pixel ``(0, 0)`` is the plate's top-left corner; the image spans exactly :attr:`TagBoard.size`
    at ``pixels_per_metre``. Marker edges fall on whole pixels: exactly where every size times
    ``pixels_per_metre`` is a whole number (2000 px/m with the default board: 10 px per tag cell),
    otherwise rounded (up to half a pixel). Each marker needs at least 2 px per tag cell.
    """
    ppm = float(pixels_per_metre)
    if not (math.isfinite(ppm) and ppm > 0):
        raise ValueError(f"pixels_per_metre: must be > 0, got {pixels_per_metre!r}")
    side = int(round(board.marker_size * ppm))
    if side < 2 * TAG_CELLS:
        raise ValueError(
            f"pixels_per_metre: {ppm:g} gives {side} px per marker; need >= {2 * TAG_CELLS}"
        )
    w, h = board.size
    image = np.full((int(round(h * ppm)), int(round(w * ppm))), 255, np.uint8)
    dictionary = tag_dictionary()
    pitch = board.marker_size + board.marker_gap
    for r in range(board.rows):
        for c in range(board.columns):
            marker = cv2.aruco.generateImageMarker(
                dictionary, board.first_id + r * board.columns + c, side, borderBits=1
            )
            u0 = int(round((board.margin + c * pitch) * ppm))
            v0 = int(round((board.margin + r * pitch) * ppm))
            image[v0 : v0 + side, u0 : u0 + side] = marker
    return image


__all__ = ["TAG_CELLS", "TAG_DICTIONARY", "TagBoard", "render_board", "tag_dictionary"]
