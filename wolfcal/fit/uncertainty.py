"""How far to trust each estimated number: one function for the fit, the evaluation and pose planning.

Input: the Jacobian of the whitened data residuals with respect to the prior-normalised unknowns z (unit-variance
Gaussian priors on z). The posterior covariance of z is (J^T J + I)^-1, so each parameter's share of information
from the data is 1 - posterior variance (the prior's variance is 1). The condition number is that of the data
Jacobian with unit-norm columns (calibration practice: below 100).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from wolfcal.fit.columns import is_sparse

if TYPE_CHECKING:
    import scipy.sparse

CORRELATION_LIMIT = 0.9
# Condition numbers below which the information's eigenvalues give it to ~1e-7 (the smallest eigenvalue's rounding,
# ~P eps of the largest, relative to it: P eps cond^2 / 2); above, J's triangular factor when it can be had.
EIGEN_CONDITION_LIMIT = 1e4


@dataclass
class Uncertainty:
    std: np.ndarray  # (P,) [SI]
    covariance: np.ndarray  # (P, P) [SI]
    correlation: np.ndarray  # (P, P)
    data_share: np.ndarray  # (P,) in [0, 1]: information from the data rather than the prior
    condition_number: float

    def correlated_pairs(self, names: list[str], limit: float = CORRELATION_LIMIT) -> list[tuple[str, str, float]]:
        """Pairs with |correlation| above `limit`, strongest first."""
        i, j = np.triu_indices(len(names), k=1)
        strong = np.abs(self.correlation[i, j]) > limit
        pairs = [(names[a], names[b], float(self.correlation[a, b])) for a, b in zip(i[strong], j[strong])]
        return sorted(pairs, key=lambda p: -abs(p[2]))


def uncertainty(J_data: np.ndarray | scipy.sparse.spmatrix, prior_sigmas: np.ndarray) -> Uncertainty:
    """Uncertainty of the unknowns from the whitened data Jacobian (R, P) in prior-normalised units."""
    information = J_data.T @ J_data
    if is_sparse(J_data):
        return information_uncertainty(information.toarray(), prior_sigmas)
    return information_uncertainty(np.asarray(information), prior_sigmas, triangular_factor(J_data))


def triangular_factor(M: np.ndarray) -> np.ndarray:
    """R of M = Q R (M (m, n): R (min(m, n), n)); stacking R over further rows and factoring again gives the factor
    of all the rows (a Jacobian's chunk by chunk)."""
    return np.asarray(np.linalg.qr(M, mode="r"))


def information_uncertainty(
    information: np.ndarray,
    prior_sigmas: np.ndarray,
    triangular: np.ndarray | Callable[[], np.ndarray | None] | None = None,
    conditioned: np.ndarray | None = None,
) -> Uncertainty:
    """Uncertainty of the unknowns from the information J^T J (P, P) of the whitened data Jacobian J in
    prior-normalised units. The condition number from J's triangular factor R (J = Q R, (P, P)) when given, else
    from the information's eigenvalues (which lose what lies below 1e-8 of the largest singular value: a nearly
    singular problem reads infinite). `triangular` may be a function giving R (or None), called only where the
    eigenvalues would not do (a condition number from them of EIGEN_CONDITION_LIMIT or more): R costs a fit's
    whitened Jacobian formed and factored chunk by chunk, several times the cost of the normal equations.
    `conditioned`: (P,) bool, the unknowns whose columns the condition number covers (default all): not those only
    their priors hold apart by design (a field marking's place against the robot's)."""
    n = len(prior_sigmas)
    cov_z = np.linalg.inv(information + np.eye(n))
    d = np.sqrt(np.clip(np.diag(cov_z), 1e-300, None))
    keep = np.ones(n, bool) if conditioned is None else np.asarray(conditioned, bool)
    information = information[np.ix_(keep, keep)]
    norms = np.sqrt(np.clip(np.diag(information), 0.0, None))
    if not keep.any():
        condition = 1.0
    elif np.any(norms < 1e-12):
        condition = float("inf")
    else:
        if triangular is None or callable(triangular):
            e = np.linalg.eigvalsh(information / np.outer(norms, norms))
            condition = float(np.sqrt(e[-1] / e[0])) if e[0] > 0 else float("inf")
            triangular = triangular() if callable(triangular) and not condition < EIGEN_CONDITION_LIMIT else None
        if triangular is not None:  # singular values of the column-scaled Jacobian J / norms = Q (R / norms)
            s = np.linalg.svd(triangular[:, keep] / norms, compute_uv=False)
            condition = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    return Uncertainty(
        std=d * prior_sigmas,
        covariance=cov_z * np.outer(prior_sigmas, prior_sigmas),
        correlation=cov_z / np.outer(d, d),
        data_share=np.clip(1.0 - np.diag(cov_z), 0.0, 1.0),
        condition_number=condition,
    )
