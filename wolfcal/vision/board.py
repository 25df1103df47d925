"""Calibration board geometry: checkerboard and ChArUco object points, textures and the target frame.

Board frame (OpenCV's): x along the columns of corners, y along the rows (down the printed sheet), z = 0 on
the board [m]. A checkerboard's origin is its first inner corner; a ChArUco board's origin is the top-left
corner of its top-left square (as `cv2.aruco.CharucoBoard` puts it). `cols` x `rows` always count inner
corners, so a ChArUco board of 5 x 7 squares is `cols=4, rows=6`.

Textures are uint8 images with a white margin of `margin` squares and an integer number of pixels per square,
so every square edge falls on a texel edge; the target frame of `wolfcal.vision.render` (texture centred on
its origin, x right, y up the sheet) relates to the board frame by `T_target_board`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.vision.target_size import check_printed_edge


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    """'4X4_50', 'DICT_5X5_100', 'apriltag_36h11', '36h11' ... -> an OpenCV aruco dictionary."""
    key = name.upper().removeprefix("DICT_")
    if re.fullmatch(r"\d+H\d+", key):
        key = f"APRILTAG_{key}"
    value = getattr(cv2.aruco, f"DICT_{key}", None)
    if value is None:
        known = sorted(n.removeprefix("DICT_") for n in dir(cv2.aruco) if n.startswith("DICT_") and n.isupper())
        raise WolfcalError(f"unknown marker dictionary {name!r}; use one of {', '.join(known)}")
    return cv2.aruco.getPredefinedDictionary(value)


def parse_board_size(text: str) -> tuple[int, int]:
    """'9x6' -> (9, 6) inner corners; a clear message for anything else."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX*]\s*(\d+)\s*", text)
    if not match or min(int(match[1]), int(match[2])) < 2:
        raise WolfcalError(f"board size {text!r}: give inner corners as COLSxROWS, e.g. --board 9x6")
    return int(match[1]), int(match[2])


@dataclass(frozen=True)
class Board:
    """A planar calibration board; `cols` x `rows` inner corners, `square` edge [m]."""

    cols: int
    rows: int
    square: float
    dictionary: str | None = None  # ChArUco marker dictionary; None for a plain checkerboard
    marker: float | None = None  # ChArUco marker edge [m] (default 0.75 * square)
    legacy: bool = False  # ChArUco layout of OpenCV < 4.6 (differs for an even number of square rows)

    def __post_init__(self) -> None:
        if self.square <= 0:
            raise WolfcalError(f"square size must be positive, got {self.square} m")
        if self.is_charuco and self.marker_length >= self.square:
            raise WolfcalError(f"marker size {self.marker_length} m must be smaller than the square {self.square} m")

    @property
    def is_charuco(self) -> bool:
        return self.dictionary is not None

    @property
    def marker_length(self) -> float:
        """Side of a ChArUco marker [m]: as given, else 0.75 of the square."""
        return self.marker if self.marker is not None else 0.75 * self.square

    @property
    def squares(self) -> tuple[int, int]:
        """Number of squares (across, down)."""
        return self.cols + 1, self.rows + 1

    @property
    def n_corners(self) -> int:
        """Inner corners of the board (cols x rows)."""
        return self.cols * self.rows

    def describe(self) -> str:
        kind = f"ChArUco {self.dictionary}{' legacy' if self.legacy else ''}" if self.is_charuco else "checkerboard"
        return f"{kind} {self.cols}x{self.rows} inner corners, {self.square * 1000:g} mm squares"

    def charuco(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV ChArUco board (only for ChArUco boards)."""
        assert self.dictionary is not None
        board = cv2.aruco.CharucoBoard(self.squares, self.square, self.marker_length, aruco_dictionary(self.dictionary))
        board.setLegacyPattern(self.legacy)
        return board

    def object_points(self) -> np.ndarray:
        """(cols * rows, 3) corner positions in the board frame [m]; row-major, index = corner id."""
        if self.is_charuco:
            return np.asarray(self.charuco().getChessboardCorners(), float).reshape(-1, 3)
        j, i = np.mgrid[0 : self.rows, 0 : self.cols]
        return np.column_stack([i.ravel(), j.ravel(), np.zeros(i.size)]) * self.square

    def texture(self, px_per_square: int, margin: float = 1.0) -> np.ndarray:
        """uint8 image of the board with a white margin of `margin` squares (rounded to whole pixels)."""
        sx, sy = self.squares
        pad = int(round(margin * px_per_square))
        if self.is_charuco:
            board = self.charuco().generateImage((sx * px_per_square, sy * px_per_square), marginSize=0)
        else:
            cells = (np.add.outer(np.arange(sy), np.arange(sx)) % 2).astype(np.uint8) * 255  # top-left black
            board = np.kron(cells, np.ones((px_per_square, px_per_square), np.uint8))
        return cv2.copyMakeBorder(board, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)

    def texture_size(self, px_per_square: int, margin: float = 1.0) -> tuple[float, float]:
        """Physical (width, height) [m] of `texture(px_per_square, margin)`."""
        pad = round(margin * px_per_square) / px_per_square
        sx, sy = self.squares
        return (sx + 2 * pad) * self.square, (sy + 2 * pad) * self.square

    def T_target_board(self, px_per_square: int, margin: float = 1.0) -> np.ndarray:
        """(4, 4) board frame -> target frame of the texture (origin at its centre, y up the sheet)."""
        width, height = self.texture_size(px_per_square, margin)
        pad = round(margin * px_per_square) / px_per_square * self.square
        first = 0.0 if self.is_charuco else self.square  # board origin from the board's top-left edge
        T = np.diag([1.0, -1.0, -1.0, 1.0])
        T[0, 3] = pad + first - width / 2
        T[1, 3] = height / 2 - pad - first
        return T


def make_board(
    size: str, square: float, dictionary: str | None = None, marker: float | None = None, legacy: bool = False
) -> Board:
    """A board from command-line values ('9x6', square [m], ChArUco dictionary, marker [m], legacy layout)."""
    cols, rows = parse_board_size(size)
    check_printed_edge(square, "--square")
    if marker is not None:
        check_printed_edge(marker, "--marker")
    if dictionary is None and (marker is not None or legacy):
        raise WolfcalError("--marker and --legacy describe ChArUco boards: add --charuco DICTIONARY")
    board = Board(cols, rows, square, dictionary, marker, legacy)
    if dictionary is not None:  # a ChArUco board
        needed = (cols + 1) * (rows + 1) // 2
        available = len(aruco_dictionary(dictionary).bytesList)
        if needed > available:
            raise WolfcalError(
                f"a {cols + 1}x{rows + 1}-square ChArUco board needs {needed} markers; {dictionary} "
                f"has {available}: choose a larger dictionary"
            )
    return board
