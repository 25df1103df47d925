"""The normal equations summed over chunks of whole noise groups (bounded memory on long recordings) equal those of
the whole whitened Jacobian, and a fit with tiny chunks is the fit with one chunk: head camera with still poses seen
in several frames (groups of many rows, repeating detection errors) and an external camera with a pose per sample
(a sparse Jacobian)."""

from __future__ import annotations

import numpy as np
import pytest
from test_noise import TRIPOD, repeated_frames

from wolfcal.fit import problem
from wolfcal.fit.columns import ColumnMatrix
from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.fit.uncertainty import EIGEN_CONDITION_LIMIT, information_uncertainty, triangular_factor
from wolfcal.sim.scenario import synthetic_external_scenario

SLOW = pytest.mark.slow


def scenario(robot, camera, system: str):
    if system == "head, repeated frames":
        return repeated_frames(robot, camera, 3), FitOptions(free="leg", side="both")
    obs = synthetic_external_scenario(robot, TRIPOD, n=50, seed=22).obs
    return obs, FitOptions(free="leg", external_moving=True)


@pytest.mark.parametrize("system", ["head, repeated frames", pytest.param("external moving", marks=SLOW)])
def test_chunked_normal_equations_equal_the_whole_jacobians(robot, camera, monkeypatch, system):
    obs, options = scenario(robot, camera, system)
    fit = fit_observations(robot, obs, options)
    prob = fit.problem
    z = (fit.solution.values - prob.params.references) / prob.params.prior_sigmas
    J = prob.data_jacobian(z)
    J = J.toarray() if hasattr(J, "toarray") else J
    r = prob.residuals(z)[: -len(z)]
    H_whole, g_whole = J.T @ J, J.T @ r
    scale = np.max(np.abs(H_whole))
    sizes = np.bincount(prob.states[0].noise_model.group_of_row[prob.states[0].noise_model.rows])
    monkeypatch.setattr(problem, "CHUNK_ROWS", int(sizes.max() + sizes.min()))  # a few groups per chunk
    chunks = list(prob.states[0].noise_model.chunks(problem.CHUNK_ROWS))
    assert 1 < len(chunks) < len(sizes)
    H, g, R = prob.information(z, triangular=True)
    np.testing.assert_allclose(H, H_whole, atol=1e-12 * scale)
    np.testing.assert_allclose(g, g_whole, atol=1e-12 * np.max(np.abs(g_whole)))
    if R is not None:  # the triangular factor of the dense Jacobian: R^T R = J^T J
        np.testing.assert_allclose(R.T @ R, H_whole, atol=1e-12 * scale)
    assert (R is None) == (len(z) > problem.DENSE_LIMIT) == (system == "external moving")
    H_prior, g_prior = prob.normal_equations(z)
    np.testing.assert_allclose(H_prior, H + np.eye(len(z)), atol=1e-12 * scale)
    np.testing.assert_allclose(g_prior, g + z)


def test_a_fit_in_tiny_chunks_is_the_fit_in_one(robot, camera, monkeypatch):
    obs, options = scenario(robot, camera, "head, repeated frames")
    whole = fit_observations(robot, obs, options)
    monkeypatch.setattr(problem, "CHUNK_ROWS", 1)  # one group per chunk
    chunked = fit_observations(robot, obs, options)
    np.testing.assert_allclose(chunked.solution.values, whole.solution.values,
                               atol=1e-6 * float(np.min(whole.solution.std)))  # fmt: skip
    np.testing.assert_allclose(chunked.solution.std, whole.solution.std, rtol=1e-6)
    assert [b.outlier_views for b in chunked.solution.blocks] == [b.outlier_views for b in whole.solution.blocks]


def test_the_condition_number_from_the_eigenvalues_unless_nearly_singular():
    """Below EIGEN_CONDITION_LIMIT the information's eigenvalues give the condition number the triangular factor
    gives, without asking for the factor; above it (two columns nearly alike) the factor is asked for and used: the
    eigenvalues would lose the smallest singular value (1e-9 of the largest here)."""
    rng = np.random.default_rng(3)
    for spread, nearly_singular in ((1e-2, False), (1e-9, True)):
        J = rng.normal(0.0, 1.0, (400, 6)) * np.array([1.0, 10.0, 0.1, 3.0, 1.0, 1.0])
        J[:, 5] = J[:, 4] + spread * rng.normal(0.0, 1.0, 400)
        asked: list[bool] = []

        def factor(J: np.ndarray = J, asked: list[bool] = asked) -> np.ndarray:
            asked.append(True)
            return triangular_factor(J)

        exact = information_uncertainty(J.T @ J, np.ones(6), triangular_factor(J)).condition_number
        lazy = information_uncertainty(J.T @ J, np.ones(6), factor)
        assert bool(asked) == nearly_singular == (exact >= EIGEN_CONDITION_LIMIT)
        assert lazy.condition_number == pytest.approx(exact, rel=1e-7)


def test_noise_factors_multiply_as_scipy_sparse(robot, camera):
    """The noise groups' factors Q in numpy (wolfcal.fit.columns, batched by group shape) give scipy.sparse's
    products, and a chunk's factors are Q's columns and rows of its groups."""
    obs, options = scenario(robot, camera, "head, repeated frames")
    model = fit_observations(robot, obs, options).problem.states[0].noise_model
    Q, reference = model.Q, model.Q.as_scipy
    assert len(Q._groups) > 1 and Q.shape[1] > 0  # groups of several shapes
    rng = np.random.default_rng(0)
    x, M = rng.normal(size=(Q.shape[1], 3)), rng.normal(size=(Q.shape[0], 3))
    np.testing.assert_allclose(Q @ x, reference @ x, rtol=0, atol=1e-13)
    np.testing.assert_allclose(Q @ x[:, 0], reference @ x[:, 0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(Q.T @ M, reference.T @ M, rtol=0, atol=1e-13)
    np.testing.assert_allclose(Q.T @ M[:, 0], reference.T @ M[:, 0], rtol=0, atol=1e-13)
    sizes = np.bincount(model.group_of_row[model.rows])
    chunks = model.chunks(int(sizes.max() + sizes.min()))
    assert len(chunks) > 1
    for rows, part in chunks:
        groups = model.group_of_row[rows]
        columns = np.flatnonzero((model.group_of_column >= groups.min()) & (model.group_of_column <= groups.max()))
        np.testing.assert_array_equal(part.Q.as_scipy.toarray(), reference[rows][:, columns].toarray())
        # its products: those of a copy of its columns, exactly, from views of Q's values
        copy = ColumnMatrix(part.Q.data, part.Q.indices, part.Q.indptr, part.Q.shape[0])
        y, N = rng.normal(size=(part.Q.shape[1], 3)), rng.normal(size=(part.Q.shape[0], 3))
        np.testing.assert_array_equal(part.Q @ y, copy @ y)
        np.testing.assert_array_equal(part.Q.T @ N, copy.T @ N)
        assert all(any(np.shares_memory(v, w) for _, _, w in Q._groups) for _, _, v in part.Q._groups)
    assert sum(part.Q.shape[1] for _, part in chunks) == Q.shape[1]
