"""Levenberg-Marquardt on the normal equations, for problems with few unknowns and many residuals.

scipy's trf decomposes the whole (R, P) Jacobian by SVD at every step; with R in the thousands and P in the tens
that dominates a fit. Here each step solves the (P, P) damped normal equations (J^T J + mu diag(J^T J)) dz = -J^T r
(Marquardt's scaling, Nielsen's damping update). Residuals and the normal equations J^T J, J^T r come from the
caller (`Problem`, which sums them over chunks of rows: the whole Jacobian is never needed).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class LMResult:
    x: np.ndarray
    cost: float  # 0.5 * sum of squared residuals at x
    nfev: int
    status: int  # > 0 converged (1: small step, 2: small cost change, 3: small gradient, 4: step within the
    # noise), 0: iteration limit


def levenberg_marquardt(
    fun: Callable[[np.ndarray], np.ndarray],
    normal: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    x0: np.ndarray,
    max_iterations: int = 200,
    xtol: float = 1e-8,
    ftol: float = 1e-8,
    gtol: float = 1e-8,
    cost_tol: float = 0.0,
    std_tol: float = 0.0,
) -> LMResult:
    """Minimise 0.5 * |fun(x)|^2 given normal(x) = (J^T J (P, P), J^T fun(x) (P,)) of its Jacobian J at x
    (solved densely: P up to a few thousand). Stops when a step lowers the cost by less than ftol * cost or
    cost_tol (absolute, the cost's unit), or (std_tol > 0, residuals whitened: J^T J is the inverse covariance of
    x) once an accepted step moves every unknown by at most std_tol times its standard deviation,
    sqrt(diag((J^T J)^-1)) at the step's start: the steps left are below what the data can tell,
    e.g. a robust loss's linear arms, along which steps of one size zigzag for a hundred evaluations while the
    solution moves by hundredths of its standard deviation."""
    x = np.asarray(x0, dtype=float).copy()
    r = fun(x)
    cost, nfev = float(r @ r), 1
    H, g = normal(x)
    scale = np.maximum(np.diag(H), 1e-12)
    mu, nu = 1e-4, 2.0
    for _ in range(max_iterations):
        if np.max(np.abs(g)) < gtol:
            return LMResult(x, 0.5 * cost, nfev, 3)
        try:
            dx = np.linalg.solve(H + mu * np.diag(scale), -g)
        except np.linalg.LinAlgError:
            mu, nu = mu * nu, nu * 2
            continue
        if np.linalg.norm(dx) < xtol * (np.linalg.norm(x) + xtol):
            return LMResult(x, 0.5 * cost, nfev, 1)
        x_new = x + dx
        r_new = fun(x_new)
        nfev += 1
        cost_new = float(r_new @ r_new)
        predicted = -(2.0 * g @ dx + dx @ H @ dx)
        rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if rho > 0 and np.isfinite(cost_new):
            small_change = cost - cost_new < max(ftol * cost, 2.0 * cost_tol, 1e-300)
            within_noise = std_tol > 0 and bool(np.all(np.abs(dx) <= std_tol * _marginal_std(H)))
            x, cost = x_new, cost_new
            if small_change:  # returned before the normal equations at x, which nothing would use
                return LMResult(x, 0.5 * cost, nfev, 2)
            if within_noise:
                return LMResult(x, 0.5 * cost, nfev, 4)
            H, g = normal(x)
            scale = np.maximum(scale, np.diag(H))
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            mu, nu = mu * nu, nu * 2.0
    return LMResult(x, 0.5 * cost, nfev, 0)


def _marginal_std(H: np.ndarray) -> np.ndarray:
    """sqrt(diag(H^-1)) of the normal matrix (0 where H is singular: no step counts as within the noise)."""
    try:
        return np.sqrt(np.maximum(np.diag(np.linalg.inv(H)), 0.0))
    except np.linalg.LinAlgError:
        return np.zeros(len(H))
