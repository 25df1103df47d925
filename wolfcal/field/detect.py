"""Field-line points in a camera image: the centres of white stripes with green turf on both sides.

The image is scanned along rows and columns (every `step` pixels). A line point is the centre of a run of white
pixels bordered by green within a few pixels on both sides, no wider than a line can appear there: the expected
width of a field line at each pixel (from the nominal model, `expected_width_px`) bounds it, which rejects goal
posts, robots' white parts and the ball seen across their width. Only pixels below the field boundary are scanned:
each column's boundary is the row above which the pixels are mostly not turf and below which they mostly are, and
the field region is the convex upper envelope of these rows (a column's row replaced by the lowest of its
neighbours' first, so that green things beyond the carpet, people's clothes or a banner, do not lift it).
"White" is judged against the turf next to it, in the turf's own colour cast. The local turf is the green pixels
in a window of 1/16 of the image width, without those already 2 spreads brighter than the rest (under warm light
a wide yellowish line passes for green). A white pixel is brighter than the local turf by `BRIGHTER_SPREAD` times
the turf's brightness spread and by `MIN_BRIGHTER` of its brightness, and less green (`greenness`: green minus the
larger of red and blue, over green) by `LESS_GREEN_SPREAD` times that measure's spread and by `MIN_LESS_GREEN`. A
line under warm light looks yellow and in shade grey, but white mixed into turf always makes it brighter and less
green; a brighter tuft of grass keeps the turf's colour, and a speck of grass texture rarely stands out by several
times the turf's own spread on both measures.
Points come in OpenCV's pixel convention (centre of the top-left pixel at (0, 0)).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

GREEN_HUE = (30, 95)  # OpenCV hue range of turf (0-180)
MIN_GREEN_SATURATION = 50
BORDER_PX = 3  # green must lie within this many pixels of a run's ends
BRIGHTER_SPREAD = 3.0  # a white pixel is brighter than the local turf by this many times the turf's spread
MIN_BRIGHTER = 0.3  # ... and by at least this share of its brightness
LESS_GREEN_SPREAD = 2.0  # ... and less green by this many times the spread of the turf's greenness
MIN_LESS_GREEN = 0.06  # ... and by at least this much (see `greenness`)


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


def greenness(image: np.ndarray) -> np.ndarray:
    """(H, W) float: (green - max(red, blue)) / green of a BGR image; unchanged when a pixel is only brighter."""
    b, g, r = (image[..., k].astype(np.float32) for k in range(3))
    return (g - np.maximum(r, b)) / np.maximum(g, 1.0)


def field_region(green: np.ndarray) -> np.ndarray:
    """(H, W) bool: below the field boundary (see the module docstring)."""
    h, w = green.shape
    closed = cv2.morphologyEx(green.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((7, 7), np.uint8))
    if not closed.any():
        return np.zeros_like(green)
    # the row splitting each column into mostly not turf above and mostly turf below: argmax of the running sum
    # of +1 per non-turf and -1 per turf pixel from the top (row 0 when the column is turf from the top)
    score = np.vstack([np.zeros((1, w)), np.cumsum(1.0 - 2.0 * closed, axis=0)])
    top = score.argmax(axis=0)
    has = top < h
    span = max(3, (w // 50) | 1)
    top = cv2.dilate(np.where(has, top, 0).astype(np.float32)[None], np.ones((1, span), np.uint8))[0]  # lowest
    columns = np.flatnonzero(has)
    if not len(columns):
        return np.zeros_like(green)
    points = np.column_stack([columns, top[columns]]).astype(np.int32)
    points = np.vstack([points, [[columns[-1], h - 1], [columns[0], h - 1]]]).astype(np.int32)
    region = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(region, cv2.convexHull(points), 1)
    return region.astype(bool)


def _local_turf(values: np.ndarray, green: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation (H, W) of `values` over the turf pixels in a size x size window (NaN where the
    window holds almost no turf)."""
    weight = cv2.blur(green.astype(np.float32), (size, size))
    safe = np.maximum(weight, 1e-3)
    mean = cv2.blur(values * green, (size, size)) / safe
    spread = np.sqrt(np.maximum(cv2.blur(values * values * green, (size, size)) / safe - mean * mean, 0.0))
    valid = weight > 0.05
    return np.where(valid, mean, np.nan), np.where(valid, spread, np.nan)


def white_mask(image: np.ndarray, green: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) bool: white against the local turf (see the module docstring), and (H, W) brightness above the local
    turf [grey levels] (0 where no turf is near)."""
    value = image.max(axis=2).astype(np.float32)
    colour = greenness(image)
    size = max(15, (image.shape[1] // 16) | 1)
    turf_value, value_spread = _local_turf(value, green, size)
    with np.errstate(invalid="ignore"):
        plain = green & ~(value - turf_value > 2.0 * value_spread)  # a wide yellowish line is not turf
    turf_value, value_spread = _local_turf(value, plain, size)
    turf_colour, colour_spread = _local_turf(colour, plain, size)
    brighter = value - turf_value
    less_green = turf_colour - colour
    with np.errstate(invalid="ignore"):
        white = (brighter > np.maximum(MIN_BRIGHTER * turf_value, BRIGHTER_SPREAD * value_spread)) & (
            less_green > np.maximum(MIN_LESS_GREEN, LESS_GREEN_SPREAD * colour_spread)
        )
    return white, np.nan_to_num(brighter)


def detect_line_points(image: np.ndarray, expected_width_px: np.ndarray | None = None, step: int = 4) -> LinePoints:
    """Line points of a BGR image.

    `expected_width_px`: (2, H, W) the width a field line would have at each pixel across rows (index 0: a row
    scan's run length for a line perpendicular to it) and across columns (index 1) [px], from the nominal camera
    pose; None accepts runs up to 4 % of the image width.
    """
    green = turf_mask(image)
    white, contrast = white_mask(image, green)
    white &= field_region(green)
    limit = None if expected_width_px is None else 3.0 * expected_width_px + 2.0
    default_limit = 0.04 * image.shape[1]
    found: list[np.ndarray] = []
    rows_flag: list[np.ndarray] = []
    for along_rows in (True, False):
        w_map = white if along_rows else white.T
        g_map = green if along_rows else green.T
        c_map = contrast if along_rows else contrast.T
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
