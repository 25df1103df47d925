"""How well line points found in a rendered view match its truth: the share of points that lie on a line, the
share of the visible lines' crossings with the scan lines that were found, and how far the points lie from the
true line centres."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.field.detect import LinePoints
from wolfcal.field.ground import ground_points, ground_step
from wolfcal.field.model import FieldLines, distance_to_lines


@dataclass(frozen=True)
class DetectionQuality:
    """Detection figures of one or more views."""

    points: int
    on_line: int  # points within 1 px of a truth line pixel
    crossings: int  # truth line runs on the scanned rows and columns
    found: int  # of those, runs with a point inside
    centre_error_px: np.ndarray  # (on_line,) distance of each point on a line to the line's centre [px]

    @property
    def precision(self) -> float:
        return self.on_line / self.points if self.points else 1.0

    @property
    def recall(self) -> float:
        return self.found / self.crossings if self.crossings else 1.0


def detection_quality(
    points: LinePoints,
    line_mask: np.ndarray,
    camera: CameraModel,
    T_field_camera: np.ndarray,
    lines: FieldLines,
    step: int,
    max_run_px: float,
) -> DetectionQuality:
    """Score points found with scan `step` against a view's truth (`FieldView.line_mask`); truth runs longer than
    `max_run_px` (a line seen along the scan) are not counted as crossings."""
    near_line = cv2.dilate(line_mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    pixel = np.round(points.uv).astype(int)
    on = near_line[pixel[:, 1], pixel[:, 0]] if len(pixel) else np.zeros(0, bool)
    crossings = found = 0
    for along_rows, mask in ((True, line_mask), (False, line_mask.T)):
        mine = points.uv[points.along_rows == along_rows]
        for line in range(0, mask.shape[0], step):
            edges = np.flatnonzero(np.diff(np.concatenate([[0], mask[line].astype(np.int8), [0]])))
            runs = [(s, e) for s, e in zip(edges[0::2], edges[1::2]) if e - s <= max_run_px]
            at = mine[:, 0] if along_rows else mine[:, 1]
            on_this = (mine[:, 1] if along_rows else mine[:, 0]) == line
            crossings += len(runs)
            found += sum(bool(np.any(on_this & (at >= s - 1) & (at <= e))) for s, e in runs)
    good = points.uv[on]
    distance = distance_to_lines(lines, ground_points(camera, T_field_camera, good))
    steps = ground_step(camera, T_field_camera, good)
    error_px = distance / np.maximum(np.nanmin(steps, axis=1), 1e-9)
    return DetectionQuality(len(pixel), int(on.sum()), crossings, found, error_px)
