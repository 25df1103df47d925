"""wolfcal.graph.connected_components against a hand-made graph and against scipy.sparse.csgraph on random ones."""

from __future__ import annotations

import numpy as np
import scipy.sparse
from scipy.sparse.csgraph import connected_components as scipy_components

from wolfcal.graph import connected_components


def test_hand_made_graph():
    # 0-3, 3-5 (one component), 1 alone, 2-4 and a self loop on 6
    labels = connected_components(7, np.array([0, 3, 4, 6]), np.array([3, 5, 2, 6]))
    assert labels.tolist() == [0, 1, 2, 0, 2, 0, 3]


def test_no_edges_and_long_path():
    assert connected_components(3, np.zeros(0, int), np.zeros(0, int)).tolist() == [0, 1, 2]
    n = 3000
    order = np.random.default_rng(0).permutation(n)  # a path through the nodes in random order: one component
    assert not connected_components(n, order[:-1], order[1:]).any()


def test_same_numbering_as_scipy():
    rng = np.random.default_rng(7)
    for _ in range(200):
        n, m = int(rng.integers(1, 80)), int(rng.integers(0, 100))
        a, b = rng.integers(0, n, m), rng.integers(0, n, m)
        graph = scipy.sparse.coo_matrix((np.ones(m), (a, b)), shape=(n, n))
        assert np.array_equal(connected_components(n, a, b), scipy_components(graph, directed=False)[1])
