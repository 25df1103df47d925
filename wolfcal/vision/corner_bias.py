"""The corner detector's inward bias on small tags: blur and edge refinement move a small tag view's edges inward
(up to ~1 px at 4 m for 0.12-0.2 m floor tags), so its corners come out inside the true ones and the tag looks
smaller, i.e. farther away. A fit can take that bias as one unknown inset [px]: every edge of a tag view moved by
the inset along its inward normal."""

from __future__ import annotations

import numpy as np


def inset_directions(ring: np.ndarray) -> np.ndarray:
    """(V, 4, 2) how each corner of the tag views `ring` (V, 4, 2) [px, corners in order around the tag] moves when
    both edges that meet in it move inward by one pixel along their normals [px/px]. Zero for a view with a
    missing (NaN) corner."""
    centre = np.nanmean(ring, axis=1, keepdims=True)
    e_next, e_prev = np.roll(ring, -1, axis=1) - ring, ring - np.roll(ring, 1, axis=1)  # the edges at each corner

    def inward_normal(e: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            n = np.stack([-e[..., 1], e[..., 0]], axis=-1) / np.linalg.norm(e, axis=-1, keepdims=True)
        return n * np.sign(np.sum(n * (centre - ring), axis=-1, keepdims=True))

    whole = np.isfinite(ring).all(axis=(1, 2))
    A = np.nan_to_num(np.stack([inward_normal(e_next), inward_normal(e_prev)], axis=-2))  # (V, 4, 2, 2)
    A[~whole] = np.eye(2)
    move = np.linalg.solve(A, np.ones(ring.shape[:2] + (2, 1)))[..., 0]
    return np.where(whole[:, None, None], move, 0.0)
