"""Tag view outlines in an image: corners (V, 4, 2) [px] in order around the tag (aruco order), NaN for a corner
that was not seen. Free of OpenCV: the fit's tag-view weights (`corner_bias`) and the corner refinement (`edges`)
share it."""

from __future__ import annotations

import numpy as np


def mean_side(corners: np.ndarray) -> np.ndarray:
    """(V,) mean length [px] of the sides of tag views `corners` (V, 4, 2) [px], over the sides whose two corners
    are known (finite); NaN for a view without one."""
    sides = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)  # (V, 4), NaN next to a missing corner
    known = np.isfinite(sides)
    if known.all():
        return sides.mean(axis=1)
    count = known.sum(axis=1)
    return np.where(count > 0, np.where(known, sides, 0.0).sum(axis=1) / np.maximum(count, 1), np.nan)
