"""The grouped whitening against a dense reference: each group's covariance written out as an n x n matrix from its
definition and whitened with its symmetric inverse square root (eigen-decomposition of the whole matrix)."""

import numpy as np
import scipy.sparse

from wolfcal.fit.noise import GroupedWhitening, SharedErrors, split_rows


def dense_covariance(shared: SharedErrors, rows: np.ndarray, sigma: float) -> np.ndarray:
    """C = sigma^2 I + sigma_q^2 A A^T (rows of one reading) + tau^2 (rows of one label and axis), n x n."""
    A, reading, label, axis = shared.A[rows], shared.reading[rows], shared.label[rows], shared.axis[rows]
    same_reading = reading[:, None] == reading[None, :]
    same_error = (label[:, None] == label[None, :]) & (label[:, None] >= 0) & (axis[:, None] == axis[None, :])
    return sigma**2 * np.eye(len(rows)) + shared.sigma_q**2 * (A @ A.T) * same_reading + shared.tau**2 * same_error


def dense_whitening(groups: list[np.ndarray], shared: SharedErrors, sigma: float) -> np.ndarray:
    """W (R, R): C_g^-1/2 on each group's block, zero rows and columns for rows in no group."""
    W = np.zeros((len(shared.A), len(shared.A)))
    for rows in groups:
        lam, V = np.linalg.eigh(dense_covariance(shared, rows, sigma))
        W[np.ix_(rows, rows)] = (V / np.sqrt(lam)) @ V.T
    return W


def shared_errors(rng: np.random.Generator, units: int, tau: float) -> tuple[SharedErrors, np.ndarray]:
    """A block of 2-row units: still poses of 1-9 units (a few of them seen in several frames, so that units of one
    pose share a repeating detection error), joint sensitivities of 5 joints of which one moves nothing."""
    pose = np.sort(rng.integers(0, units // 4, units))
    A = rng.normal(0, 300.0, (2 * units, 5))
    A[:, 3] = 0.0
    A[np.repeat(pose == 0, 2)] = 0.0  # units the joints do not move (a tag fixed to the base)
    label = np.where(rng.random(units) < 0.7, pose * 3 + rng.integers(0, 3, units), -1)
    shared = SharedErrors(A=A, sigma_q=1.5e-3, reading=np.repeat(pose, 2), label=np.repeat(label, 2),
                          axis=np.tile(np.arange(2), units), tau=tau)  # fmt: skip
    return shared, pose


def test_whitening_is_the_symmetric_inverse_square_root_of_each_groups_covariance():
    rng = np.random.default_rng(3)
    for tau in (0.0, 0.4):
        shared, pose = shared_errors(rng, 60, tau)
        keep = rng.random(60) > 0.1  # left-out units belong to no group
        groups = split_rows(pose, 2, keep)
        whitening = GroupedWhitening(groups, shared)
        for sigma in (0.05, 0.3, 2.0):
            W = dense_whitening(groups, shared, sigma)
            r = rng.normal(0, 1.0, 120)
            M = rng.normal(0, 1.0, (120, 7))
            M_sparse = scipy.sparse.random(120, 40, density=0.1, random_state=4, format="csr")
            assert np.allclose(whitening.apply(r, sigma), W @ r, rtol=1e-10, atol=1e-10 * np.abs(W @ r).max())
            assert np.allclose(whitening.apply(M, sigma), W @ M, rtol=1e-10, atol=1e-10 * np.abs(W @ M).max())
            sparse = whitening.apply(M_sparse, sigma)
            assert scipy.sparse.issparse(sparse)
            assert np.allclose(sparse.toarray(), W @ M_sparse.toarray(), atol=1e-10 * np.abs(W).max())
            norms = [r[g] @ np.linalg.solve(dense_covariance(shared, g, sigma), r[g]) for g in groups]
            assert np.allclose(whitening.group_norms(r, sigma), norms, rtol=1e-10)
            assert np.allclose(whitening.whitened(r, sigma), (W @ r)[np.concatenate(groups)], atol=1e-10)
            left_out = np.repeat(~keep, 2)
            assert np.all(whitening.apply(r, sigma)[left_out] == 0.0)


def test_a_long_still_pose_is_never_a_dense_block():
    """A still pose of 20000 rows (10000 corners: 250 frames of 40): the factors stay thin (rows x shared errors)
    and whitening it agrees with the definition on the part that can be checked densely (a group of the same
    kind, 400 rows)."""
    rng = np.random.default_rng(5)
    for units in (200, 10000):
        frames = units // 40
        A = np.tile(rng.normal(0, 300.0, (80, 4)), (frames, 1))  # the same pose in every frame
        label = np.tile(np.arange(40), frames)  # each corner's detection error repeats in every frame
        shared = SharedErrors(A=A, sigma_q=1.5e-3, reading=np.zeros(2 * units, dtype=int),
                              label=np.repeat(label, 2), axis=np.tile(np.arange(2), units), tau=0.1)  # fmt: skip
        whitening = GroupedWhitening([np.arange(2 * units)], shared)
        assert whitening.Q.nnz <= 2 * units * (4 + 80)
        if units == 200:
            r = rng.normal(0, 1.0, 2 * units)
            W = dense_whitening([np.arange(2 * units)], shared, 0.2)
            assert np.allclose(whitening.apply(r, 0.2), W @ r, atol=1e-9)
