"""The grouped whitening against a dense reference: each group's covariance written out as an n x n matrix from its
definition and whitened with its symmetric inverse square root, or split along the eigenvectors of its shared part
(eigen-decomposition of the whole matrix, as the fit did before the thin factors)."""

import numpy as np
import pytest
import scipy.sparse

from wolfcal.camera.model import CameraModel
from wolfcal.fit import problem, solver
from wolfcal.fit.noise import GroupedWhitening, SharedErrors, row_groups
from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.sim.observations import synthetic_observations
from wolfcal.sim.scenario import synthetic_external_scenario, synthetic_scenario

TRIPOD = CameraModel(1920, 1080, np.array([[1400.0, 0, 959.5], [0, 1400.0, 539.5], [0, 0, 1]]), np.zeros(5))


def dense_covariance(shared: SharedErrors, rows: np.ndarray, sigma: float, scale: np.ndarray) -> np.ndarray:
    """C = sigma^2 diag(scale^2) + sigma_q^2 A A^T (rows of one reading) + tau^2 (rows of one label and axis)."""
    A, reading, label, axis = shared.A[rows], shared.reading[rows], shared.label[rows], shared.axis[rows]
    if reading.ndim == 1:  # one reading of every joint per row
        reading = np.repeat(reading[:, None], A.shape[1], axis=1)
    joints = sum(np.outer(A[:, j], A[:, j]) * (reading[:, None, j] == reading[None, :, j]) for j in range(A.shape[1]))
    same_error = (label[:, None] == label[None, :]) & (label[:, None] >= 0) & (axis[:, None] == axis[None, :])
    own = sigma**2 * np.diag(scale[rows] ** 2)
    return own + shared.sigma_q**2 * joints + shared.tau**2 * same_error


def dense_whitening(groups: list[np.ndarray], shared: SharedErrors, sigma: float, scale: np.ndarray) -> np.ndarray:
    """W (R, R): on each group's block (D^-1 C_g D^-1)^-1/2 D^-1 (D = diag(scale): the symmetric root when all rows
    have the block's noise level), zero rows and columns for rows in no group."""
    W = np.zeros((len(shared.A), len(shared.A)))
    for rows in groups:
        s = scale[rows]
        lam, V = np.linalg.eigh(dense_covariance(shared, rows, sigma, scale) / np.outer(s, s))
        W[np.ix_(rows, rows)] = (V / np.sqrt(lam)) @ V.T / s
    return W


def dense_split(groups: list[np.ndarray], shared: SharedErrors, sigma: float, scale: np.ndarray):
    """(R, R) each row's part outside its group's shared errors / sigma, and (K, R) the components along the
    eigenvectors of each group's shared part D^-1 S_g D^-1 with a non-zero eigenvalue l, / sqrt(sigma^2 + l)."""
    own, along = np.zeros((len(shared.A), len(shared.A))), []
    for rows in groups:
        s = scale[rows]
        lam, V = np.linalg.eigh(dense_covariance(shared, rows, 0.0, scale) / np.outer(s, s))
        on = lam > 1e-9 * max(lam.max(), 1e-300)
        Vs = V[:, on]
        own[np.ix_(rows, rows)] = (np.eye(len(rows)) - Vs @ Vs.T) / sigma / s
        block = np.zeros((int(on.sum()), len(shared.A)))
        block[:, rows] = Vs.T / np.sqrt(sigma**2 + lam[on])[:, None] / s
        along.append(block)
    return own, np.concatenate(along) if along else np.zeros((0, len(shared.A)))


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
    for tau, scale in ((0.0, np.ones(120)), (0.4, np.ones(120)), (0.4, np.repeat(rng.uniform(1, 3, 60), 2))):
        shared, pose = shared_errors(rng, 60, tau)
        keep = rng.random(60) > 0.1  # left-out units belong to no group
        groups = [np.flatnonzero(np.repeat((pose == p) & keep, 2)) for p in np.unique(pose[keep])]
        group_of_row = row_groups(pose, 2, keep)
        assert [np.flatnonzero(group_of_row == k).tolist() for k in range(len(groups))] == [g.tolist() for g in groups]
        whitening = GroupedWhitening(group_of_row, shared, scale)
        for sigma in (0.05, 0.3, 2.0):
            W = dense_whitening(groups, shared, sigma, scale)
            for g in groups:  # the definition: W_g^T W_g = C_g^-1
                C = dense_covariance(shared, g, sigma, scale)
                assert np.allclose(W[np.ix_(g, g)].T @ W[np.ix_(g, g)] @ C, np.eye(len(g)), atol=1e-8)
            r = rng.normal(0, 1.0, 120)
            M = rng.normal(0, 1.0, (120, 7))
            M_sparse = scipy.sparse.random(120, 40, density=0.1, random_state=4, format="csr")
            assert np.allclose(whitening.apply(r, sigma), W @ r, rtol=1e-10, atol=1e-10 * np.abs(W @ r).max())
            assert np.allclose(whitening.apply(M, sigma), W @ M, rtol=1e-10, atol=1e-10 * np.abs(W @ M).max())
            sparse = whitening.apply(M_sparse, sigma)
            assert scipy.sparse.issparse(sparse)
            assert np.allclose(sparse.toarray(), W @ M_sparse.toarray(), atol=1e-10 * np.abs(W).max())
            norms = [r[g] @ np.linalg.solve(dense_covariance(shared, g, sigma, scale), r[g]) for g in groups]
            assert np.allclose(whitening.group_norms(r, sigma), norms, rtol=1e-10)
            split = dense_split(groups, shared, sigma, scale)
            assert np.allclose(whitening.split(r, sigma)[:120], split[0] @ r, atol=1e-10)  # each row's own part
            shared_part = whitening.split(r, sigma)[120:]  # the shared errors' components: the eigenbasis's
            assert np.allclose(np.sort(np.abs(shared_part)), np.sort(np.abs(split[1] @ r)), atol=1e-8)
            assert np.allclose(np.sum(whitening.split(M, sigma) ** 2, axis=0), np.sum((W @ M) ** 2, axis=0))
            sparse_split = whitening.split(M_sparse, sigma)
            assert scipy.sparse.issparse(sparse_split)
            assert np.allclose(sparse_split.toarray(), whitening.split(M_sparse.toarray(), sigma), atol=1e-12)
            left_out = np.repeat(~keep, 2)
            assert np.all(whitening.apply(r, sigma)[left_out] == 0.0)


def test_split_normal_is_the_weighted_sum_over_the_split_rows():
    """The normal equations of the split rows summed without forming them (`split_normal`) agree with the sums written
    out over `split`'s rows: rows weighted 1, a few weighted otherwise (a robust fit's far rows, 0 for the Newton
    steps' rows beyond the loss's bend), many weighted otherwise (then formed), and with rows in no group."""
    rng = np.random.default_rng(8)
    for tau, scale in ((0.0, np.ones(120)), (0.4, np.repeat(rng.uniform(1, 3, 60), 2))):
        shared, pose = shared_errors(rng, 60, tau)
        for keep in (np.ones(60, dtype=bool), rng.random(60) > 0.1):
            whitening = GroupedWhitening(row_groups(pose, 2, keep), shared, scale)
            M = rng.normal(0, 1.0, (120, 7))
            for sigma in (0.05, 0.3):
                J = whitening.split(M, sigma)
                v = rng.normal(0, 1.0, len(J))
                for odd in (0, 5, 80):
                    weight = np.ones(len(J))
                    weight[rng.choice(len(J), odd, replace=False)] = rng.choice([0.0, 0.3], odd)
                    H, g = whitening.split_normal(M, sigma, weight, v)
                    H_ref, g_ref = J.T @ (weight[:, None] * J), J.T @ v
                    np.testing.assert_allclose(H, H_ref, rtol=1e-9, atol=1e-10 * np.abs(H_ref).max())
                    np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-10 * np.abs(g_ref).max())
                    assert np.array_equal(H, H.T)


def test_a_long_still_pose_is_never_a_dense_block():
    """A still pose of 8000 rows (4000 corners: 100 frames of 40): the factors stay thin (rows x shared errors)
    and whitening it agrees with the definition on the part that can be checked densely (a group of the same
    kind, 400 rows)."""
    rng = np.random.default_rng(5)
    for units in (200, 4000):
        frames = units // 40
        A = np.tile(rng.normal(0, 300.0, (80, 4)), (frames, 1))  # the same pose in every frame
        label = np.tile(np.arange(40), frames)  # each corner's detection error repeats in every frame
        shared = SharedErrors(A=A, sigma_q=1.5e-3, reading=np.zeros(2 * units, dtype=int),
                              label=np.repeat(label, 2), axis=np.tile(np.arange(2), units), tau=0.1)  # fmt: skip
        whitening = GroupedWhitening(np.zeros(2 * units, dtype=int), shared)
        assert whitening.Q.nnz <= 2 * units * (4 + 80)
        if units == 200:
            r = rng.normal(0, 1.0, 2 * units)
            W = dense_whitening([np.arange(2 * units)], shared, 0.2, np.ones(2 * units))
            assert np.allclose(whitening.apply(r, 0.2), W @ r, atol=1e-9)


def test_a_reading_per_joint_is_shared_by_the_rows_that_read_that_joint_alike():
    """Floor samples: the legs (joints 0-2) hold one reading in all 10 samples, the head (joints 3, 4) reads anew in
    each; 4 corners (8 rows) per sample, one group. The whitening is the definition's."""
    rng = np.random.default_rng(7)
    sample = np.repeat(np.arange(10), 8)
    reading = np.stack([np.zeros(80, int)] * 3 + [sample] * 2, axis=1)
    shared = SharedErrors(A=rng.normal(0, 300.0, (80, 5)), sigma_q=1.5e-3, reading=reading,
                          label=np.full(80, -1), axis=np.tile(np.arange(2), 40))  # fmt: skip
    whitening = GroupedWhitening(np.zeros(80, dtype=int), shared)
    r = rng.normal(0, 1.0, 80)
    for sigma in (0.1, 1.0):
        W = dense_whitening([np.arange(80)], shared, sigma, np.ones(80))
        assert np.allclose(whitening.apply(r, sigma), W @ r, atol=1e-9 * np.abs(W @ r).max())
        C = dense_covariance(shared, np.arange(80), sigma, np.ones(80))
        assert np.isclose(whitening.group_norms(r, sigma)[0], r @ np.linalg.solve(C, r), rtol=1e-9)
    # the legs' error is one for all samples: 3 shared columns for them, 2 per sample for the head
    assert len(whitening.s2) == 3 + 2 * 10


class DenseWhitening:
    """The reference whitening of a whole fit: each group's shared part written out as an n x n matrix, scaled by
    the rows' own noise levels D and eigen-decomposed (V, l), applied as dense matrices: W_g = V diag(1 / sqrt(sigma^2
    + l)) V^T D^-1 (`apply`), or split into each row's part outside the eigenvectors with l > 0, (I - V_s V_s^T) D^-1
    / sigma, and the components along them, V_s^T D^-1 / sqrt(sigma^2 + l) (`split`, the robust fit's numbers)."""

    def __init__(self, group_of_row: np.ndarray, shared: SharedErrors, row_scale: np.ndarray) -> None:
        self.group_of_row, self.shared, self.row_scale = group_of_row, shared, row_scale
        self.groups = [np.flatnonzero(group_of_row == k) for k in range(group_of_row.max() + 1)]
        self.eigen = [
            np.linalg.eigh(dense_covariance(shared, rows, 0.0, row_scale) / np.outer(row_scale[rows], row_scale[rows]))
            for rows in self.groups
        ]
        self.cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    def matrices(self, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """W (R, R), the split's own part (R, R) and shared part (K, R), and each row's free share 1 - h (R,)."""
        if sigma not in self.cache:
            R = len(self.shared.A)
            W, own, free, along = np.zeros((R, R)), np.zeros((R, R)), np.zeros(R), [np.zeros((0, R))]
            for rows, (lam, V) in zip(self.groups, self.eigen):
                lam = np.clip(lam, 0, None)
                d = self.row_scale[rows]
                W[np.ix_(rows, rows)] = (V / np.sqrt(sigma**2 + lam)) @ V.T / d
                Vs = V[:, lam > 1e-9 * max(lam.max(), 1e-300)]
                own[np.ix_(rows, rows)] = (np.eye(len(rows)) - Vs @ Vs.T) / sigma / d
                free[rows] = 1.0 - np.sum(Vs**2, axis=1)
                block = np.zeros((Vs.shape[1], R))
                block[:, rows] = Vs.T / np.sqrt(sigma**2 + lam[lam > 1e-9 * max(lam.max(), 1e-300)])[:, None] / d
                along.append(block)
            self.cache[sigma] = (W, own, np.concatenate(along), free)
        return self.cache[sigma]

    def apply(self, M, sigma: float):
        W = self.matrices(sigma)[0]
        return scipy.sparse.csr_matrix(W @ M.toarray()) if scipy.sparse.issparse(M) else W @ M

    def split(self, M, sigma: float):
        _, own, along, _ = self.matrices(sigma)
        S = np.concatenate([own, along])
        return scipy.sparse.csr_matrix(S @ M.toarray()) if scipy.sparse.issparse(M) else S @ M

    def standardized(self, r: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """Per row and per eigenspace of each group's shared part (eigenvalues within 1e-9 of the largest are one;
        the eigenvalue 0: the row's own part): the row's projection / its standard deviation, weight its share."""
        values, weights = [], []
        for rows, (lam, V) in zip(self.groups, self.eigen):
            lam = np.clip(lam, 0, None)
            y = V.T @ (r[rows] / self.row_scale[rows])
            tol = 1e-9 * max(lam.max(), 1e-300)
            space = np.cumsum(np.concatenate([[True], np.diff(lam) > tol]))  # lam ascending
            space[lam <= tol] = 0
            for k in np.unique(space):
                Vk = V[:, space == k]
                projection, share = Vk @ y[space == k], np.sum(Vk**2, axis=1)
                on = share > (1e-6 if k == 0 else 1e-12)
                level = sigma if k == 0 else np.sqrt(sigma**2 + lam[space == k].mean())
                values.append(projection[on] / np.sqrt(share[on]) / level)
                weights.append(share[on])
        return np.concatenate(values), np.concatenate(weights)

    def chunks(self, max_rows: int):
        yield np.arange(len(self.group_of_row)), self  # one chunk: rows in no group are zero rows

    def split_normal(self, M: np.ndarray, sigma: float, weight: np.ndarray, v: np.ndarray):
        J = self.split(M, sigma)  # the definition: the weighted sums over the split rows written out
        return J.T @ (weight[:, None] * J), J.T @ v

    def standardizer(self, r: np.ndarray):
        return lambda sigma: self.standardized(r, sigma)

    def group_norms(self, r: np.ndarray, sigma: float) -> np.ndarray:
        w = self.matrices(sigma)[0] @ r
        return np.array([np.sum(w[rows] ** 2) for rows in self.groups])


def repeated_frames(robot, camera, frames: int):
    """Still poses each seen in `frames` frames (independent pixel noise, the same joint readings): the corners of
    one pose share a repeating detection error, so a noise group spans all frames of its pose."""
    scenario = synthetic_scenario(robot, camera, n=8, seed=23, offsets="all")
    obs = scenario.obs
    visible = np.zeros((obs.n_samples, len(robot.config.tag_ids)), dtype=bool)
    visible[obs.sample_index, [robot.config.tag_ids.index(t) for t in obs.tag_ids]] = True
    q_true, visible = np.repeat(scenario.q_true, frames, axis=0), np.repeat(visible, frames, axis=0)
    return synthetic_observations(robot, camera, scenario.truth, q_true, visible, 0.15, np.random.default_rng(24))


SLOW = pytest.mark.slow


@pytest.mark.parametrize("system", ["head", "head, repeated frames", pytest.param("external moving", marks=SLOW)])
def test_a_fit_is_the_same_as_with_the_dense_whitening(robot, camera, monkeypatch, system):
    """Every noise model of the fit (per-round groups, per-view outlier groups, the noise-level search, the robust
    loss and the reported uncertainty) through the dense reference instead: the same fit to numerical precision.
    Head camera: leg preset, outlier samples; still poses seen in several frames (repeating detection errors);
    external camera with a pose per sample: a sparse Jacobian (more unknowns than DENSE_LIMIT)."""
    options = FitOptions(free="leg", side="both")
    if system == "head":
        obs = synthetic_scenario(robot, camera, n=20, seed=21, offsets="all", outlier_fraction=0.1).obs
    elif system == "head, repeated frames":
        obs = repeated_frames(robot, camera, 4)
    else:
        obs = synthetic_external_scenario(robot, TRIPOD, n=50, seed=22).obs
        options = FitOptions(free="leg", external_moving=True)
    # every solve converged fully: the early stops (ROUND_COST_TOL, ROUND_STD_TOL, FINAL_STD_TOL) leave a solve
    # within a fraction of a standard deviation of its optimum, and where exactly depends on rounding
    for name in ("ROUND_COST_TOL", "ROUND_STD_TOL", "FINAL_STD_TOL"):
        monkeypatch.setattr(solver, name, 0.0)
    thin = fit_observations(robot, obs, options)
    monkeypatch.setattr(problem, "GroupedWhitening", DenseWhitening)
    monkeypatch.setattr(solver, "GroupedWhitening", DenseWhitening)
    dense = fit_observations(robot, obs, options)
    assert (len(thin.params) > problem.DENSE_LIMIT) == (system == "external moving")
    for a, b in zip(thin.solution.blocks, dense.solution.blocks):
        assert a.outlier_views == b.outlier_views
        assert a.sigma == pytest.approx(b.sigma, rel=1e-9)
    assert np.all(np.abs(thin.solution.values - dense.solution.values) < 1e-6 * dense.solution.std)
    np.testing.assert_allclose(thin.solution.std, dense.solution.std, rtol=1e-7)


def test_per_view_statistics_and_noise_level_are_those_of_the_dense_whitening(robot, camera, monkeypatch):
    """At a fit's solution (head camera, outlier samples): each view's outlier statistic is its squared Mahalanobis
    norm under its own covariance written out from the definition (whatever the whitening's basis), and the
    noise-level search reads the same robust scale through the thin factors as through the dense eigenbasis."""
    obs = synthetic_scenario(robot, camera, n=20, seed=21, offsets="all", outlier_fraction=0.1).obs
    fit = fit_observations(robot, obs, FitOptions(free="leg", side="both"))
    state = fit.problem.states[0]
    params = fit.problem.params
    lin = fit.problem.evaluate((fit.solution.values - params.references) / params.prior_sigmas)[0]
    block, r = state.block, lin.residual.ravel()
    shared = state.shared_errors(lin)
    views = row_groups(block.view_of_unit, block.dim)
    thin_rms = solver.view_rms(state, lin)
    for v in (0, 7, block.n_views - 1):
        rows = np.flatnonzero(views == v)
        C = dense_covariance(shared, rows, state.sigma, state.row_scale)
        assert thin_rms[v] ** 2 * len(rows) == pytest.approx(r[rows] @ np.linalg.solve(C, r[rows]), rel=1e-9)
    flagged = solver.flag_outliers(state, lin)
    assert flagged.any()  # the outlier samples' views: the statistic is used where it matters
    thin_scale = [solver.residual_scale(state, lin.residual, sigma, 10.0) for sigma in (0.05, 0.2, 1.0)]
    monkeypatch.setattr(solver, "GroupedWhitening", DenseWhitening)
    np.testing.assert_allclose(solver.view_rms(state, lin), thin_rms, rtol=1e-9)
    assert np.array_equal(solver.flag_outliers(state, lin), flagged)
    state.whitening = DenseWhitening(state.noise_model.group_of_row, state.noise_model.shared, state.row_scale)
    dense_scale = [solver.residual_scale(state, lin.residual, sigma, 10.0) for sigma in (0.05, 0.2, 1.0)]
    np.testing.assert_allclose(thin_scale, dense_scale, rtol=1e-9)


def test_a_level_set_after_the_solve_decomposes_the_groups_again(robot, camera):
    """After the solve, setting a level that needs the groups decomposed again (the repeating detection error's
    size follows the level) rebuilds the factors at that size; setting the solve's level back gives its model."""
    fit = fit_observations(robot, repeated_frames(robot, camera, 4), FitOptions(free="leg", side="both"))
    state = fit.problem.states[0]
    assert np.any(state.noise_model.shared.label >= 0)  # a repeating detection error: its size follows the level
    sigma, s2 = state.sigma, state.noise_model.s2.copy()
    assert state.set_sigma(4.0 * sigma)
    assert state.noise_model.shared.tau == pytest.approx(state.sigma)
    assert state.set_sigma(sigma)
    np.testing.assert_allclose(state.noise_model.s2, s2, rtol=1e-9)
