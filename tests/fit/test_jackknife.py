"""The grouped jackknife the field fit checks its std with: its covariance against the textbook's."""

import numpy as np

from wolfcal.fit.jackknife import jackknife_covariance, view_groups


def test_the_jackknife_of_a_mean_is_its_textbook_variance():
    """Leave-one-out means of n numbers: the jackknife's variance is the sample variance over n (exactly)."""
    x = np.random.default_rng(0).normal(3.0, 2.0, (9, 2))
    means = np.array([np.delete(x, k, axis=0).mean(axis=0) for k in range(len(x))])
    assert np.allclose(jackknife_covariance(means), np.cov(x.T) / len(x))


def test_views_are_dealt_into_groups_in_turn():
    assert view_groups(14).tolist() == [0, 1, 2, 3, 4, 5, 0, 1, 2, 3, 4, 5, 0, 1]
    assert view_groups(4).tolist() == [0, 1, 2, 3]
