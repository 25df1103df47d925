"""The per-edge corner refinement that `wolfcal.vision.edges.refine_edges` replaced (one remap and one
polynomial fit per edge, in a Python loop), kept as the reference the vectorised version must equal. The edge
position along each profile is the shared `edge_offsets` (the old copy here was the same code)."""

from __future__ import annotations

import cv2
import numpy as np

from wolfcal.vision.edges import edge_offsets


def _edge_tangent(d: np.ndarray, off: np.ndarray) -> tuple[float, float]:
    """Fit the edge offset off(d) across an edge vs distance d from the corner -> (offset, slope) at d = 0.

    A parabola when the points span more than 8 px (it absorbs the bend of the edge under lens distortion,
    which a line would extrapolate into a bias of ~curvature * span^2 / 12), a line otherwise. Points off the
    first fit by more than max(0.3 px, 4 median deviations) (dirt, glare, a wrong crossing) are dropped.
    """
    degree = 2 if d.max() - d.min() > 8.0 else 1
    coeffs = np.polynomial.polynomial.polyfit(d, off, degree)
    residual = np.abs(off - np.polynomial.polynomial.polyval(d, coeffs))
    inlier = residual <= max(0.3, 4.0 * float(np.median(residual)))
    if inlier.sum() > degree + 2 and not inlier.all():
        coeffs = np.polynomial.polynomial.polyfit(d[inlier], off[inlier], degree)
    return float(coeffs[0]), float(coeffs[1])


def _intersect(p1: np.ndarray, d1: np.ndarray, p2: np.ndarray, d2: np.ndarray) -> np.ndarray | None:
    """Intersection of the lines p1 + s d1 and p2 + s d2 (None if nearly parallel)."""
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 1e-6:
        return None
    s = np.linalg.solve(A, p2 - p1)
    return p1 + s[0] * d1


def _edge_line(
    img: np.ndarray,
    corner: np.ndarray,
    other: np.ndarray,
    outward: np.ndarray,
    t: np.ndarray,
    d: np.ndarray,
    window: float,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Tangent (point, direction) at `corner` of the tag edge towards the corner `other`, from sub-pixel
    edge points at distances `d` [px] along it (profiles sampled at offsets `t` [px] across it, edge found
    within `window` px of the mid-grey crossing); None if there are too few."""
    e = other - corner
    length = np.linalg.norm(e)
    e /= length
    n = np.array([-e[1], e[0]])
    n = n if np.dot(n, outward) >= 0 else -n  # positive offsets point out of the tag (dark -> light)
    d = d[d < 0.45 * length]
    pts = corner + d[:, None, None] * e + t[None, :, None] * n  # (M, S, 2)
    h, w = img.shape
    inside = (pts[..., 0] >= 0) & (pts[..., 0] <= w - 1) & (pts[..., 1] >= 0) & (pts[..., 1] <= h - 1)
    keep = inside.all(axis=1)
    if keep.sum() < 4:
        return None
    pts = pts[keep].astype(np.float32)
    profiles = cv2.remap(img, pts[..., 0], pts[..., 1], cv2.INTER_LINEAR)
    dark, light = np.percentile(profiles, [10, 90])
    if light - dark < 10:
        return None
    off = edge_offsets(profiles, t, dark, light, window)
    good = np.isfinite(off)
    if good.sum() < 4:
        return None
    offset, slope = _edge_tangent(d[keep][good], off[good])
    return corner + offset * n, e + slope * n


def _refine_edges(img: np.ndarray, corners: np.ndarray, cells: int, iterations: int = 2) -> np.ndarray:
    """Refine (4, 2) corners [px] in a float32 image by fitting the two black-square edges next to each
    corner, near that corner.

    Edge profiles start max(2 px, 0.3 cell) from the corner (clear of where blur rounds the corner off; at an
    acute corner further, so that they stay clear of the other edge), reach along the edge for 2.5 cells and
    across it for one cell across that edge (2-6 px, at most 2 px beyond the window) each way; the edge is
    measured within half that cell (1-2.5 px) of it, so it sees the black border and the white quiet zone only.
    Every profile on its own, two iterations (the vectorised version's bins and settled tags aside). The fit
    is local (a parabola per edge), which keeps the corner exact under lens distortion that bends whole
    edges. A corner whose edges cannot be measured (image border, low contrast) keeps its previous estimate.
    """
    corners = corners.astype(float).copy()
    for _ in range(iterations):
        cell = np.mean(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)) / cells
        centre = corners.mean(axis=0)
        new = corners.copy()
        for k in range(4):
            c = corners[k]
            lines = []
            for j in (1, -1):
                e = corners[(k + j) % 4] - c
                e /= np.linalg.norm(e)
                f = corners[(k - j) % 4] - c  # the other edge at this corner
                f /= np.linalg.norm(f)
                n = np.array([-e[1], e[0]])
                n = n if np.dot(n, c - centre) >= 0 else -n
                across = max(np.dot(c - q, n) for q in corners) / cells  # one cell across this edge [px]
                window = float(np.clip(0.5 * across, 1.0, 2.5))  # keep clear of data bits and background
                half = min(float(np.clip(across, 2.0, 6.0)), window + 2.0)
                t = np.arange(-half, half + 1e-9, 0.25)
                cos = float(np.dot(e, f))
                clear = (1.0 + (window + 1.0) * max(cos, 0.0)) / np.sqrt(max(1.0 - cos * cos, 1e-6))
                first = max(2.0, 0.3 * cell, clear)  # acute corner: profiles clear of the other edge
                d = np.arange(first, max(2.5 * cell, 4.0, first + 4.0) + 1e-9, 0.5)
                lines.append(_edge_line(img, c, corners[(k + j) % 4], c - centre, t, d, window))
            if lines[0] is None or lines[1] is None:
                continue
            p = _intersect(*lines[0], *lines[1])
            if p is not None and np.linalg.norm(p - c) < 0.5 * cell + 1.0:
                new[k] = p
        corners = new
    return corners
