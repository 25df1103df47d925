"""Field-line points in a camera image: the centres of white stripes with green turf on both sides.

The image is scanned along rows and columns (every `step` pixels). A line point is the centre of a run of white
pixels bordered by green within a few pixels on both sides, no wider than a line can appear there: the expected
width of a field line at each pixel (from the nominal model, `expected_width_px`) bounds it, which rejects goal
posts, robots' white parts and the ball seen across their width. Only pixels below the field boundary (the convex
upper envelope of the green turf) are scanned, so people, walls and anything beyond the carpet are never read.
"White" is relative to the turf next to it (its local brightness), so uneven light and shadows do not hide lines.
Points come in OpenCV's pixel convention (centre of the top-left pixel at (0, 0)).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

GREEN_HUE = (30, 95)  # OpenCV hue range of turf (0-180)
MIN_GREEN_SATURATION = 50
MAX_WHITE_SATURATION = 90
BORDER_PX = 3  # green must lie within this many pixels of a run's ends


@dataclass(frozen=True)
class LinePoints:
    """Line points found in one image."""

    uv: np.ndarray  # (N, 2) pixels
    along_rows: np.ndarray  # (N,) bool: found on a row scan (else a column scan)


def turf_mask(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels whose colour is turf green."""
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    return (h >= GREEN_HUE[0]) & (h <= GREEN_HUE[1]) & (s >= MIN_GREEN_SATURATION) & (v >= 30)


def field_region(green: np.ndarray) -> np.ndarray:
    """(H, W) bool: below the field boundary, the convex upper envelope of each column's first long green run."""
    h, w = green.shape
    closed = cv2.morphologyEx(green.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((7, 7), np.uint8))
    window = max(8, h // 40)
    share = cv2.blur(closed.astype(np.float32), (1, window), anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
    dense = share >= 0.7
    has = dense.any(axis=0)
    if not has.any():
        return np.zeros_like(green)
    top = np.where(has, dense.argmax(axis=0), h)
    columns = np.flatnonzero(has)
    points = np.column_stack([columns, top[columns]]).astype(np.int32)
    points = np.vstack([points, [[columns[-1], h - 1], [columns[0], h - 1]]]).astype(np.int32)
    region = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(region, cv2.convexHull(points), 1)
    return region.astype(bool)


def detect_line_points(image: np.ndarray, expected_width_px: np.ndarray | None = None, step: int = 4) -> LinePoints:
    """Line points of a BGR image.

    `expected_width_px`: (2, H, W) the width a field line would have at each pixel across rows (index 0: a row
    scan's run length for a line perpendicular to it) and across columns (index 1) [px], from the nominal camera
    pose; None accepts runs up to 4 % of the image width.
    """
    green = turf_mask(image)
    region = field_region(green)
    value = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)[..., 2].astype(np.float32)
    saturation = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)[..., 1]
    size = max(15, (image.shape[1] // 16) | 1)
    weight = cv2.blur(green.astype(np.float32), (size, size))
    turf_level = cv2.blur(value * green, (size, size)) / np.maximum(weight, 1e-3)
    turf_level = np.where(weight > 0.05, turf_level, np.nan)
    contrast = value - turf_level
    white = (saturation <= MAX_WHITE_SATURATION) & (contrast > np.maximum(35.0, 0.3 * np.nan_to_num(turf_level)))
    white &= region
    limit = None if expected_width_px is None else 3.0 * expected_width_px + 2.0
    default_limit = 0.04 * image.shape[1]
    found: list[np.ndarray] = []
    rows_flag: list[np.ndarray] = []
    for along_rows in (True, False):
        w_map = white if along_rows else white.T
        g_map = green if along_rows else green.T
        c_map = np.nan_to_num(contrast if along_rows else contrast.T)
        lim = None if limit is None else (limit[0] if along_rows else limit[1].T)
        for line in range(0, w_map.shape[0], step):
            centres = _runs(w_map[line], g_map[line], c_map[line], lim[line] if lim is not None else default_limit)
            if len(centres):
                uv = np.column_stack([centres, np.full(len(centres), line, float)])
                found.append(uv if along_rows else uv[:, ::-1])
                rows_flag.append(np.full(len(centres), along_rows))
    if not found:
        return LinePoints(np.zeros((0, 2)), np.zeros(0, bool))
    return LinePoints(np.vstack(found), np.concatenate(rows_flag))


def _runs(white: np.ndarray, green: np.ndarray, contrast: np.ndarray, limit: np.ndarray | float) -> np.ndarray:
    """Sub-pixel centres of white runs along one scan line that have green on both sides and fit `limit`."""
    padded = np.concatenate([[False], white, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    starts, ends = edges[0::2], edges[1::2]  # run = [start, end)
    if not len(starts):
        return np.zeros(0)
    n = len(white)
    green_before = np.array([green[max(0, s - BORDER_PX) : s].any() for s in starts])
    green_after = np.array([green[e : min(n, e + BORDER_PX)].any() for e in ends])
    centre_index = np.clip((starts + ends) // 2, 0, n - 1)
    allowed = limit[centre_index] if isinstance(limit, np.ndarray) else np.full(len(starts), limit)
    keep = green_before & green_after & (ends - starts <= allowed)
    centres = []
    for s, e in zip(starts[keep], ends[keep]):
        lo, hi = max(0, s - 1), min(n, e + 1)
        positions = np.arange(lo, hi, dtype=float)
        # above the straight line through the turf just outside the run: turf brighter on one side (a mowing
        # stripe, a shadow's edge) must not pull the centre toward it
        left, right = max(0, s - 2), min(n - 1, e + 1)
        baseline = np.interp(positions, [left, right], [contrast[left], contrast[right]])
        weights = np.maximum(contrast[lo:hi] - baseline, 0.0)
        centres.append(float(weights @ positions / weights.sum()) if weights.sum() > 0 else (s + e - 1) / 2)
    return np.asarray(centres)
