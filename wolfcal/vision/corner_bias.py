"""The corner detector's inward bias on small tags: blur and edge refinement move a small tag view's edges inward
(up to ~1 px at 4 m for 0.12-0.2 m floor tags), so its corners come out inside the true ones and the tag looks
smaller, i.e. farther away. A fit can take that bias as one unknown inset [px]: every edge of a tag view moved by
the inset along its inward normal."""

from __future__ import annotations

import numpy as np

from wolfcal.vision.outline import mean_side

REFERENCE_EDGE_PX = 40.0  # apparent tag edge [px] at which the inset is stated; smaller views count less
CORNER_INSET = "floor.corner_inset"  # the fit's parameter name for the inset [px] (in result.yaml)


def edge_normals(ring: np.ndarray) -> np.ndarray:
    """(V, 4, 2, 2) the inward unit normals (rows: the edge to the next corner, the edge from the previous one) of
    the two edges that meet in each corner of the tag views `ring` (V, 4, 2) [px, corners in order around the tag];
    the identity for a view with a missing (NaN) corner. A corner's offset along them is its distance from the two
    edges' lines: a detector finds edges, and where two meet at a sharp angle (a strongly foreshortened far tag)
    the corner slides along them by pixels while its distance from each stays within tenths of a pixel."""
    centre = np.nanmean(ring, axis=1, keepdims=True)
    e_next, e_prev = np.roll(ring, -1, axis=1) - ring, ring - np.roll(ring, 1, axis=1)  # the edges at each corner

    def inward_normal(e: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            n = np.stack([-e[..., 1], e[..., 0]], axis=-1) / np.linalg.norm(e, axis=-1, keepdims=True)
        return n * np.sign(np.sum(n * (centre - ring), axis=-1, keepdims=True))

    whole = np.isfinite(ring).all(axis=(1, 2))
    N = np.nan_to_num(np.stack([inward_normal(e_next), inward_normal(e_prev)], axis=-2))
    N[~whole] = np.eye(2)
    return N


def inset_directions(ring: np.ndarray) -> np.ndarray:
    """(V, 4, 2) how each corner of the tag views `ring` (V, 4, 2) [px, corners in order around the tag] moves when
    both edges that meet in it move inward by one pixel along their normals (`edge_normals`) [px/px]. Zero for a
    view with a missing (NaN) corner."""
    whole = np.isfinite(ring).all(axis=(1, 2))
    move = np.linalg.solve(edge_normals(ring), np.ones(ring.shape[:2] + (2, 1)))[..., 0]
    return np.where(whole[:, None, None], move, 0.0)


def apparent_edges(ring: np.ndarray) -> np.ndarray:
    """(V,) mean edge length [px] of tag views `ring` (V, 4, 2) [px], over the edges whose two corners are known
    (`outline.mean_side`); REFERENCE_EDGE_PX for a view without a known edge."""
    side = mean_side(ring)
    return np.where(np.isnan(side), REFERENCE_EDGE_PX, side)


def small_view_weight(edge: np.ndarray) -> np.ndarray:
    """Weight of a tag view's corners by its apparent edge [px]: 1 at or above REFERENCE_EDGE_PX, edge /
    REFERENCE_EDGE_PX below (a small view counts as much as one REFERENCE_EDGE_PX wide, no more)."""
    return 1.0 / np.maximum(1.0, REFERENCE_EDGE_PX / edge)


def inset_moves(ring: np.ndarray) -> np.ndarray:
    """(V, 4, 2) how each detected corner of the views `ring` (V, 4, 2) [px] moves per pixel of inset [px/px]: the
    inset applies in full at REFERENCE_EDGE_PX apparent edge and shrinks as 1/edge above (`inset_directions`)."""
    scale = np.minimum(1.0, REFERENCE_EDGE_PX / apparent_edges(ring))
    return inset_directions(ring) * scale[:, None, None]
