"""AprilTag geometry, textures and sub-pixel detection (OpenCV aruco conventions).

Tag frame (OpenCV aruco): origin at the tag centre, x right and y up in the printed image, z out of the
printed face. Corners in aruco order: top-left (-s/2, s/2, 0), top-right (s/2, s/2, 0), bottom-right (s/2,
-s/2, 0), bottom-left (-s/2, -s/2, 0), s = edge of the black square [m]. Pixels follow OpenCV: the centre of
the top-left pixel is (0, 0).

Detection is OpenCV's aruco detector (minDistanceToBorder = 0: the default loses strongly distorted tags near
the image border); its corners are then refined by `wolfcal.vision.edges.refine_tags` ("edges"): for each
corner, sub-pixel points of the two black-square edges next to it (area method on intensity profiles across
the edge, unbiased for pixel-integrated and symmetrically blurred steps), a parabola per edge fitted near the
corner (lens distortion bends whole edges, so only a local fit is exact), and the tangents intersected.

Why: on rendered views (a 2048x1536 camera with strong barrel distortion and the same lens binned to 512x384) the
edge refinement's corners are several times closer to the projected truth than those of OpenCV's refinements
(SUBPIX, APRILTAG, CONTOUR), and a large frontal tag is found without bias: renderer and detector share the pixel
convention. The figures: docs/accuracy.md (`python bench/run.py --parts detection`).

Tags are searched for at full resolution. Searching at half resolution (AprilTag's quad_decimate) and refining at
full resolution would halve OpenCV's cost at 2048x1536 with the same corners on large tags, but loses small tags
(under about 45 px side): they form no candidate outline there (the one-cell white margin is under 2 px), and
neither reading the rejected candidates again at full resolution nor a full-resolution pass with the smallest
threshold window brings them all back. Decimating safely needs each tag's smallest expected size, i.e. a bound on
its distance, which floor tags (0.5-5 m, seen at a grazing angle) and external cameras lack.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.vision.edges import refine_tags
from wolfcal.vision.outline import mean_side

FAMILIES = {
    "tag36h11": cv2.aruco.DICT_APRILTAG_36h11,
    "tag36h10": cv2.aruco.DICT_APRILTAG_36h10,
    "tag25h9": cv2.aruco.DICT_APRILTAG_25h9,
    "tag16h5": cv2.aruco.DICT_APRILTAG_16h5,
}
REFINEMENTS = ("edges", "subpix", "apriltag", "contour", "none")
# Candidates with a shorter outline are not looked at [px]: a tag of 10 px side (1.25 px per tag36h11 cell). Rendered
# tags of 8-10 px are found 1-4 times in 20 at 512x384, 12 px 12 times in 20; OpenCV's own limit, 3 % of the image's
# longer side, is 15 px at 512x384, so below 1300 px wide this limit is the one that counts and spares the detector
# the noise contours of small adaptive-threshold windows (faster, with the same tags and corners found in
# simulated 512x384 captures).
MIN_TAG_PERIMETER_PX = 40.0


def _dictionary(family: str) -> cv2.aruco.Dictionary:
    """The OpenCV aruco dictionary of an AprilTag family name (e.g. "tag36h11")."""
    if family not in FAMILIES:
        raise WolfcalError(f"unknown tag family {family!r}; use one of {', '.join(FAMILIES)}")
    return cv2.aruco.getPredefinedDictionary(FAMILIES[family])


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


def _detector(family: str, refine: str, longest_side: int = 0) -> cv2.aruco.ArucoDetector:
    """A fresh detector per call (OpenCV detectors are not documented as thread-safe) for images whose longer
    side is `longest_side` [px] (0: OpenCV's relative outline limit alone)."""
    params = cv2.aruco.DetectorParameters()
    if longest_side > 0:
        params.minMarkerPerimeterRate = max(params.minMarkerPerimeterRate, MIN_TAG_PERIMETER_PX / longest_side)
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


def detect_tags(
    image: np.ndarray, family: str = "tag36h11", ids: set[int] | None = None, refine: str = "edges"
) -> dict[int, np.ndarray]:
    """Detect tags of `family` in a gray or BGR image -> {id: (4, 2) corners [px]} (aruco order, OpenCV
    pixel centres).

    Only `ids` are kept (all if None); an id seen more than once is dropped (ambiguous), and so is a tag
    with a corner within 1 px of the image border (cut off). `refine` selects the corner refinement; the
    default ("edges") is the most accurate (see the module docstring).
    """
    return detect_tags_many([image], family, ids, refine)[0]


def detect_tags_many(
    images: Sequence[np.ndarray], family: str = "tag36h11", ids: set[int] | None = None, refine: str = "edges"
) -> list[dict[int, np.ndarray]]:
    """`detect_tags` of each image, the corners of all of them refined in one pass (faster for many small
    images: `wolfcal.vision.edges.refine_tags`)."""
    return refine_found([find_tags(_to_gray(image), {family: ids}, refine) for image in images])


Crop = tuple[np.ndarray, tuple[int, int]]  # a float32 crop of an image and its origin (x, y) [px]


@dataclass
class PendingTags:
    """The tags OpenCV found in one 8-bit gray image, per family: {id: (4, 2) corners [px]}, and, when the corners are
    still to be refined ("edges"), the crop of the image each tag is refined in (in the same order)."""

    tags: dict[str, dict[int, np.ndarray]]  # family -> tag id -> corners
    crops: dict[str, list[Crop]]  # family -> one crop per tag (families to refine only)

    def count(self) -> int:
        """Tags still to be refined."""
        return sum(len(self.tags[family]) for family in self.crops)

    def nbytes(self) -> int:
        """Bytes the crops hold."""
        return sum(crop.nbytes for crops in self.crops.values() for crop, _ in crops)


def find_tags(gray: np.ndarray, families: Mapping[str, set[int] | None], refine: str = "edges") -> PendingTags:
    """OpenCV's tags of each family {family: ids to keep (None: all)} in an 8-bit gray image, as `detect_tags` keeps
    them, each with its crop for `refine_found` when `refine` is "edges" (the crops hold all the refinement reads:
    the image need not be kept)."""
    if refine not in REFINEMENTS:
        raise ValueError(f"unknown refinement {refine!r}; use one of {', '.join(REFINEMENTS)}")
    tags = {family: _found(gray, family, ids, refine) for family, ids in families.items()}
    crops = {}
    if refine == "edges":
        crops = {family: [_tags_crop(gray, c[None], tag_cells(family)) for c in found.values()]
                 for family, found in tags.items()}  # fmt: skip
    return PendingTags(tags, crops)


def refine_found(found: Sequence[PendingTags]) -> list[dict[int, np.ndarray]]:
    """Each image's tags {id: (4, 2) corners [px]} (all families), the corners still to be refined refined
    (`wolfcal.vision.edges.refine_tags`: all tags of a family in one pass, each tag in a crop of its own: the tags
    of one image can lie far apart, e.g. on both feet, and the crop around both was up to 2.3 of the 3.1 megapixels of
    a 2048x1536 image, converted to float for nothing). The per-call cost of the refinement is numpy's, not the
    pixels': 37 tags of 24 images at 2048x1536 in one call took half the CPU of a call per image."""
    out: list[dict[int, np.ndarray]] = [{} for _ in found]
    for family in dict.fromkeys(f for image in found for f in image.tags):
        rows = [(k, tag_id) for k, image in enumerate(found) for tag_id in image.tags.get(family, {})]
        if not rows:
            continue
        corners = np.stack([found[k].tags[family][tag_id] for k, tag_id in rows])
        if any(family in image.crops for image in found):
            crops = [crop for image in found for crop in image.crops.get(family, [])]
            origins = np.array([origin for _, origin in crops], dtype=float)[:, None]  # (T, 1, 2)
            corners = refine_tags([crop for crop, _ in crops], np.arange(len(crops)), corners - origins,
                                  tag_cells(family)) + origins  # fmt: skip
        for (k, tag_id), c in zip(rows, corners):
            out[k][tag_id] = c
    return out


def _tags_crop(gray: np.ndarray, corners: np.ndarray, cells: int) -> Crop:
    """float32 crop of `gray` holding all that `refine_tags` samples around the tags `corners` (T, 4, 2) [px] of
    `cells` cells across, and its origin (x, y) [px]; the whole image if the crop would reach all its borders.

    The refinement's profiles reach at most 6 px beyond a tag's outline, and a corner moves at most half a cell and
    1 px per iteration (2), so a margin of 12 px and two cells holds them all. The crop is clipped to the image: the
    refinement drops profiles beyond the crop's border exactly where they leave the image. Converting only the crop
    spares a float copy of the whole image.
    """
    h, w = gray.shape
    cell = mean_side(corners).max() / cells
    margin = 12.0 + 2.0 * cell
    low = np.maximum(np.floor(corners.reshape(-1, 2).min(axis=0) - margin), 0).astype(int)
    high = np.minimum(np.ceil(corners.reshape(-1, 2).max(axis=0) + margin) + 1, [w, h]).astype(int)
    if low[0] == 0 and low[1] == 0 and high[0] == w and high[1] == h:
        return gray.astype(np.float32), (0, 0)
    return gray[low[1] : high[1], low[0] : high[0]].astype(np.float32), (int(low[0]), int(low[1]))


def _found(gray: np.ndarray, family: str, ids: set[int] | None, refine: str) -> dict[int, np.ndarray]:
    """OpenCV's detections of `family` in an 8-bit gray image that `detect_tags` keeps: {id: (4, 2) corners}."""
    corners, found, _ = _detector(family, refine, max(gray.shape)).detectMarkers(gray)
    if found is None:
        return {}
    found_ids = [int(i) for i in np.asarray(found).ravel()]
    kept: dict[int, np.ndarray] = {}
    h, w = gray.shape
    for tag_id, c in zip(found_ids, corners, strict=True):
        if found_ids.count(tag_id) > 1 or (ids is not None and tag_id not in ids):
            continue
        c = np.asarray(c, dtype=np.float64).reshape(4, 2)
        if (c < 1.0).any() or (c[:, 0] > w - 2).any() or (c[:, 1] > h - 2).any():
            continue  # cut by the image border
        kept[tag_id] = c
    return kept
