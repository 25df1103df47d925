"""Connected components of an undirected graph given by its edges, in numpy (the fit's noise groups: samples of
one still pose, readings linked by a shared detection error). scipy.sparse.csgraph does the same but loads
scipy.sparse, scipy.sparse.linalg and scipy.linalg with it, which a dense fit otherwise never imports (the
import would cost a fit from cached detections about as much as the rest of it; see `wolfcal.fit.columns`)."""

from __future__ import annotations

import numpy as np


def connected_components(n_nodes: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n_nodes,) component of each node, for the undirected edges a[i] - b[i] (node indices): components numbered
    0, 1, ... in the order of their smallest node (scipy.sparse.csgraph's numbering).

    Each node points to a smaller node of its component (or itself: a root); every round hooks the larger root of
    each edge whose ends have different roots onto the smaller one, then halves paths until every node points to
    its root. A root is its tree's smallest node, so at the end each component's label is its smallest node."""
    parent = np.arange(n_nodes)
    a, b = np.asarray(a, dtype=np.int64).ravel(), np.asarray(b, dtype=np.int64).ravel()
    while True:
        root_a, root_b = parent[a], parent[b]
        apart = root_a != root_b
        if not apart.any():
            break
        low, high = np.minimum(root_a[apart], root_b[apart]), np.maximum(root_a[apart], root_b[apart])
        np.minimum.at(parent, high, low)
        while True:  # every node to its root (pointer jumping)
            grand = parent[parent]
            if np.array_equal(grand, parent):
                break
            parent = grand
    return np.unique(parent, return_inverse=True)[1].ravel()
