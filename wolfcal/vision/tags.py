"""AprilTag geometry, textures and sub-pixel detection (OpenCV aruco conventions).

Tag frame (OpenCV aruco): origin at the tag centre, x right and y up in the printed image, z out of the
printed face. Corners in aruco order: top-left (-s/2, s/2, 0), top-right (s/2, s/2, 0), bottom-right (s/2,
-s/2, 0), bottom-left (-s/2, -s/2, 0), s = edge of the black square [m]. Pixels follow OpenCV: the centre of
the top-left pixel is (0, 0).

Detection is OpenCV's aruco detector (minDistanceToBorder = 0: the default loses strongly distorted tags near
the image border); its corners are then refined by `_refine_edges` ("edges"): for each corner, sub-pixel
points of the two black-square edges next to it (area method on intensity profiles across the edge, unbiased
for pixel-integrated and symmetrically blurred steps), a parabola per edge fitted near the corner (lens
distortion bends whole edges, so only a local fit is exact), and the tangents intersected.

Why (bench/bench_vision.py: tag36h11 of 0.08 m at 0.3-1.2 m, tilted up to 50 deg, anywhere in the image,
noise sigma 2; a 2048x1536 camera with strong barrel distortion, k1 = -0.286, and the same lens binned to
512x384; corner error |detected - projected truth| [px per corner], median / 95th percentile, 100 views):

    refinement          2048x1536        512x384
    edges (this)        0.023 / 0.13     0.037 / 0.13
    aruco SUBPIX        0.20  / 0.33     0.35  / 0.91
    aruco APRILTAG      0.67  / 1.10     0.62  / 0.84   (and ~1 s per full image)
    aruco CONTOUR       0.72  / 1.24     0.70  / 0.94
    none                0.64  / 1.09     0.69  / 1.14

Part of the "edges" error is aliasing in the rendered truth (4x4 supersampling): rendered at 16x16 it is
0.012 / 0.031 px (full) and 0.023 / 0.062 px (binned; tags there are 15-60 px wide). With a Gaussian blur of
sigma 1 px it is 0.019 / 0.13 px at full resolution (SUBPIX: 0.25 / 0.38). A large frontal tag rendered at
16x16 is found within 0.04 px (mean signed error < 0.003 px): renderer and detector share the pixel convention.
"""

from __future__ import annotations

import cv2
import numpy as np

from wolfcal.errors import WolfcalError

FAMILIES = {
    "tag36h11": cv2.aruco.DICT_APRILTAG_36h11,
    "tag36h10": cv2.aruco.DICT_APRILTAG_36h10,
    "tag25h9": cv2.aruco.DICT_APRILTAG_25h9,
    "tag16h5": cv2.aruco.DICT_APRILTAG_16h5,
}
REFINEMENTS = ("edges", "subpix", "apriltag", "contour", "none")


def _dictionary(family: str) -> cv2.aruco.Dictionary:
    """The OpenCV aruco dictionary of an AprilTag family name (e.g. "tag36h11")."""
    if family not in FAMILIES:
        raise WolfcalError(f"unknown tag family {family!r}; use one of {', '.join(FAMILIES)}")
    return cv2.aruco.getPredefinedDictionary(FAMILIES[family])


def tag_corners(size: float) -> np.ndarray:
    """(4, 3) corners of a tag with black-square edge `size` [m] in the tag frame, aruco order."""
    h = size / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def tag_cells(family: str) -> int:
    """Cells across the black square: data bits plus the 1-cell black border (8 for tag36h11)."""
    return _dictionary(family).markerSize + 2


def tag_texture(family: str, tag_id: int, border_cells: int = 1) -> np.ndarray:
    """uint8 image of a tag, one texel per cell: the black square (data bits inside a 1-cell black border)
    within `border_cells` of white quiet zone. Row 0 is the top of the printed tag, so as the texture of a
    `wolfcal.vision.render.PlanarTarget` it maps onto the tag frame.
    """
    dictionary = _dictionary(family)
    count = dictionary.bytesList.shape[0]
    if not 0 <= tag_id < count:
        raise WolfcalError(f"tag id {tag_id} is not in family {family} (ids 0..{count - 1})")
    cells = dictionary.markerSize + 2
    marker = cv2.aruco.generateImageMarker(dictionary, int(tag_id), cells, borderBits=1)
    return np.pad(marker, int(border_cells), constant_values=255)


def tag_texture_width(family: str, size: float, texture: np.ndarray) -> float:
    """Physical edge [m] of a `tag_texture` image whose black square has edge `size` [m]."""
    return size * texture.shape[1] / tag_cells(family)


def _to_gray(image: np.ndarray) -> np.ndarray:
    """8-bit gray view of a gray, BGR or BGRA image (8- or 16-bit)."""
    image = np.asarray(image)
    if image.dtype == np.uint16:
        image = (image // 257).astype(np.uint8)
    elif image.dtype != np.uint8:
        raise WolfcalError(f"images must be 8- or 16-bit, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    return image


def _detector(family: str, refine: str) -> cv2.aruco.ArucoDetector:
    """A fresh detector per call: OpenCV detectors are not documented as thread-safe."""
    params = cv2.aruco.DetectorParameters()
    # The default (3 px) loses tags up to ~40 px from the image border under strong distortion (4% of the
    # bench views); partially visible tags are dropped in `detect_tags` instead.
    params.minDistanceToBorder = 0
    params.cornerRefinementMethod = {
        "edges": cv2.aruco.CORNER_REFINE_SUBPIX,  # a good start for the edge refinement
        "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
        "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
        "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
        "none": cv2.aruco.CORNER_REFINE_NONE,
    }[refine]
    return cv2.aruco.ArucoDetector(_dictionary(family), params)


def _edge_offsets(profiles: np.ndarray, t: np.ndarray, dark: float, light: float, window: float) -> np.ndarray:
    """Edge position along t [px] of each dark -> light profile (N, S) sampled at t; NaN if it has no edge.

    Area method: within `window` px (less near the profile's ends, at least 0.75 px) of the mid-grey crossing
    nearest the profile centre, the edge lies where the dark area ends: edge = t_start + sum((light - I) /
    (light - dark)) * dt. Unlike the crossing of interpolated samples it is unbiased for a box-filtered
    (pixel-integrated) or symmetrically blurred step.
    """
    step = t[1] - t[0]
    above = profiles >= 0.5 * (dark + light)
    change = above[:, 1:] & ~above[:, :-1]  # dark -> light between samples k and k + 1
    centre = (len(t) - 1) / 2
    dist = np.where(change, np.abs(np.arange(len(t) - 1) + 0.5 - centre), np.inf)
    k = np.argmin(dist, axis=1)
    ok = np.isfinite(dist[np.arange(len(k)), k])
    cross = t[k] + step / 2
    reach = np.minimum(window, np.minimum(cross - t[0], t[-1] - cross) - step)  # stay inside the profile
    ok &= reach >= 0.75
    inside = np.abs(t[None, :] - cross[:, None]) <= reach[:, None]
    start = np.where(inside, t[None, :], np.inf).min(axis=1) - step / 2
    dark_part = np.clip((light - profiles) / (light - dark), -0.5, 1.5)
    edge = start + (dark_part * inside).sum(axis=1) * step
    return np.where(ok, edge, np.nan)


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
    off = _edge_offsets(profiles, t, dark, light, window)
    good = np.isfinite(off)
    if good.sum() < 4:
        return None
    offset, slope = _edge_tangent(d[keep][good], off[good])
    return corner + offset * n, e + slope * n


def _refine_edges(img: np.ndarray, corners: np.ndarray, cells: int, iterations: int = 2) -> np.ndarray:
    """Refine (4, 2) corners [px] in a float32 image by fitting the two black-square edges next to each
    corner, near that corner.

    Edge profiles start max(2 px, 0.3 cell) from the corner (clear of where blur rounds the corner off),
    reach along the edge for 2.5 cells and across it for one cell (2-6 px) each way; the edge is measured
    within half a cell (1-2.5 px) of it, so it sees the black border and the white quiet zone only. The fit
    is local (a parabola per edge), which keeps the corner exact under lens distortion that bends whole
    edges. A corner whose edges cannot be measured (image border, low contrast) keeps its previous estimate.
    """
    corners = corners.astype(float).copy()
    for _ in range(iterations):
        cell = np.mean(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)) / cells
        half = float(np.clip(cell, 2.0, 6.0))
        t = np.arange(-half, half + 1e-9, 0.25)
        d = np.arange(max(2.0, 0.3 * cell), max(2.5 * cell, 4.0) + 1e-9, 0.5)
        window = float(np.clip(0.5 * cell, 1.0, 2.5))  # small tags: keep clear of data bits and background
        centre = corners.mean(axis=0)
        new = corners.copy()
        for k in range(4):
            c = corners[k]
            lines = [_edge_line(img, c, corners[(k + j) % 4], c - centre, t, d, window) for j in (1, -1)]
            if lines[0] is None or lines[1] is None:
                continue
            p = _intersect(*lines[0], *lines[1])
            if p is not None and np.linalg.norm(p - c) < 0.5 * cell + 1.0:
                new[k] = p
        corners = new
    return corners


def detect_tags(
    image: np.ndarray, family: str = "tag36h11", ids: set[int] | None = None, refine: str = "edges"
) -> dict[int, np.ndarray]:
    """Detect tags of `family` in a gray or BGR image -> {id: (4, 2) corners [px]} (aruco order, OpenCV
    pixel centres).

    Only `ids` are kept (all if None); an id seen more than once is dropped (ambiguous), and so is a tag
    with a corner within 1 px of the image border (cut off). `refine` selects the corner refinement; the
    default ("edges") is the most accurate (see the module docstring).
    """
    if refine not in REFINEMENTS:
        raise ValueError(f"unknown refinement {refine!r}; use one of {', '.join(REFINEMENTS)}")
    gray = _to_gray(image)
    corners, found, _ = _detector(family, refine).detectMarkers(gray)
    if found is None:
        return {}
    found_ids = [int(i) for i in np.asarray(found).ravel()]
    result: dict[int, np.ndarray] = {}
    cells = tag_cells(family)
    h, w = gray.shape
    img = gray.astype(np.float32)
    for tag_id, c in zip(found_ids, corners, strict=True):
        if found_ids.count(tag_id) > 1 or (ids is not None and tag_id not in ids):
            continue
        c = np.asarray(c, dtype=np.float64).reshape(4, 2)
        if (c < 1.0).any() or (c[:, 0] > w - 2).any() or (c[:, 1] > h - 2).any():
            continue  # cut by the image border
        result[tag_id] = _refine_edges(img, c, cells) if refine == "edges" else c
    return result
