"""How well the views cover the image and the poses a calibration needs (after ROS camera_calibration).

Each view gets four numbers in [0, 1]: X and Y (where the board sits in the image), Size (sqrt of the share of
the image the board covers) and Skew (how far the board is tilted from facing the camera). Coverage of a
parameter is its spread over the kept views divided by the spread ROS asks for (0.7, 0.7, 0.4, 0.5), capped
at 1. `ViewSelector` keeps a frame of a stream only when the board is still and the view differs from every
kept one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from wolfcal.intrinsics.detect import Detection
from wolfcal.vision.board import Board

PARAM_NAMES = ("X", "Y", "Size", "Skew")
PARAM_RANGES = np.array([0.7, 0.7, 0.4, 0.5])
MIN_DISTANCE = 0.2  # L1 distance in (X, Y, Size, Skew) a new view must have from every kept view
STILL_FRACTION = 0.0015  # a board is still if its corners moved less than this share of the image diagonal
GRID = 3  # the image is split into GRID x GRID regions for the "no corners here" warning
REGION_NAMES = [
    ["top-left", "top", "top-right"],
    ["left", "centre", "right"],
    ["bottom-left", "bottom", "bottom-right"],
]


def outline(detection: Detection, board: Board) -> np.ndarray:
    """(4, 2) image positions of the outer corners of the corner grid (TL, TR, BR, BL), by homography."""
    obj = board.object_points()
    lo, hi = obj[:, :2].min(axis=0), obj[:, :2].max(axis=0)
    H, _ = cv2.findHomography(obj[detection.ids, :2], detection.corners)
    quad = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]], np.float64)
    return cv2.perspectiveTransform(quad.reshape(-1, 1, 2), H).reshape(4, 2)


def view_params(detection: Detection, board: Board) -> np.ndarray:
    """(X, Y, Size, Skew) of one view, each in [0, 1] (ROS camera_calibration's definitions)."""
    width, height = detection.image_size
    quad = outline(detection, board)
    x, y = quad[:, 0], quad[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    border = np.sqrt(area)
    mean = detection.corners.mean(axis=0)
    px = np.clip((mean[0] - border / 2) / max(width - border, 1.0), 0, 1)
    py = np.clip((mean[1] - border / 2) / max(height - border, 1.0), 0, 1)
    a, b = quad[0] - quad[1], quad[2] - quad[1]  # the angle at the top-right corner
    angle = np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1, 1))
    skew = min(1.0, 2 * abs(np.pi / 2 - angle))
    return np.array([px, py, np.sqrt(area / (width * height)), skew])


def empty_regions(views: list[Detection], image_size: tuple[int, int]) -> list[str]:
    """Names of the GRID x GRID image regions in which no corner of any view fell."""
    counts = region_counts(views, image_size)
    return [REGION_NAMES[r][c] for r in range(GRID) for c in range(GRID) if counts[r, c] == 0]


def region_counts(views: list[Detection], image_size: tuple[int, int]) -> np.ndarray:
    """(GRID, GRID) number of corners per image region (row 0 = top)."""
    width, height = image_size
    counts = np.zeros((GRID, GRID), int)
    if views:
        uv = np.concatenate([v.corners for v in views])
        col = np.clip((uv[:, 0] + 0.5) * GRID // width, 0, GRID - 1).astype(int)
        row = np.clip((uv[:, 1] + 0.5) * GRID // height, 0, GRID - 1).astype(int)
        np.add.at(counts, (row, col), 1)
    return counts


@dataclass
class Coverage:
    """Parameters of the kept views and what is still missing."""

    params: list[np.ndarray] = field(default_factory=list)

    def progress(self) -> np.ndarray:
        """(4,) coverage of X, Y, Size, Skew in [0, 1]."""
        if not self.params:
            return np.zeros(4)
        p = np.array(self.params)
        return np.minimum(np.ptp(p, axis=0) / PARAM_RANGES, 1.0)

    def is_new(self, params: np.ndarray) -> bool:
        return all(np.abs(params - q).sum() > MIN_DISTANCE for q in self.params)

    def complete(self, min_views: int) -> bool:
        return len(self.params) >= min_views and bool(np.all(self.progress() >= 1.0))

    def hints(self) -> list[str]:
        """Where to move the board next, in words."""
        if not self.params:
            return ["hold the board in front of the camera, all of it in view"]
        p = np.array(self.params)
        lo, hi = p.min(axis=0), p.max(axis=0)
        done = self.progress() >= 1.0
        hints = []
        if not done[0]:
            hints.append(
                "move the board to the left edge of the image"
                if lo[0] > 1 - hi[0]
                else "move the board to the right edge of the image"
            )
        if not done[1]:
            hints.append(
                "move the board to the top of the image"
                if lo[1] > 1 - hi[1]
                else "move the board to the bottom of the image"
            )
        if not done[2]:
            hints.append("bring the board closer" if hi[2] < 0.5 else "move the board farther away")
        if not done[3]:
            hints.append("tilt the board (left/right and up/down, about 30-45 degrees)")
        return hints


@dataclass
class ViewSelector:
    """Stream frame filter: keep still, new views; `status` says what happened to the last frame."""

    board: Board
    coverage: Coverage = field(default_factory=Coverage)
    kept: list[Detection] = field(default_factory=list)
    status: str = "waiting for frames"
    _previous: Detection | None = None

    def offer(self, detection: Detection | None) -> bool:
        """Consider one frame's detection (None: no board); True if the view was kept."""
        previous, self._previous = self._previous, detection
        if detection is None:
            self.status = "no board in view"
            return False
        if not self._still(previous, detection):
            self.status = "board moving: hold it still"
            return False
        params = view_params(detection, self.board)
        if not self.coverage.is_new(params):
            self.status = "view too similar to one already kept: move the board"
            return False
        self.coverage.params.append(params)
        self.kept.append(detection)
        self.status = f"kept view {len(self.kept)}"
        return True

    @staticmethod
    def _still(previous: Detection | None, current: Detection) -> bool:
        if previous is None or previous.image_size != current.image_size:
            return False
        common, i, j = np.intersect1d(previous.ids, current.ids, return_indices=True)
        if len(common) < 0.8 * len(current.ids):
            return False
        motion = np.linalg.norm(previous.corners[i] - current.corners[j], axis=1).mean()
        return bool(motion < STILL_FRACTION * np.hypot(*current.image_size))
