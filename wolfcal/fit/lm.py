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
    status: int  # > 0 converged (1: small step, 2: small cost change, 3: small gradient, 4: the undamped step
    # within the noise), 0: iteration limit


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
    std: np.ndarray | None = None,
    damping: float = 1e-4,
) -> LMResult:
    """Minimise 0.5 * |fun(x)|^2 given normal(x) = (H (P, P), g (P,)): the cost's curvature (J^T J of fun's
    Jacobian J, or a better one) and its gradient J^T fun(x) at x (solved densely: P up to a few thousand). Stops
    when a step lowers the cost by less than ftol * cost or cost_tol (absolute, the cost's unit), or (std_tol > 0,
    residuals whitened) once the undamped step -H^-1 g from x moves every unknown by at most std_tol times its
    standard deviation (`std` (P,), else sqrt(diag(H^-1))): the optimum of the local model lies within what the
    data can tell."""
    x = np.asarray(x0, dtype=float).copy()
    r = fun(x)
    cost, nfev = float(r @ r), 1
    H, g = normal(x)
    scale = np.maximum(np.diag(H), 1e-12)
    mu, nu, fresh = damping, 2.0, True  # fresh: H, g were computed at x since the last check
    for _ in range(max_iterations):
        if np.max(np.abs(g)) < gtol:
            return LMResult(x, 0.5 * cost, nfev, 3)
        if fresh and std_tol > 0 and _within_noise(H, g, std_tol, std):
            return LMResult(x, 0.5 * cost, nfev, 4)
        fresh = False
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
            x, cost = x_new, cost_new
            if small_change:  # returned before the normal equations at x, which nothing would use
                return LMResult(x, 0.5 * cost, nfev, 2)
            H, g = normal(x)
            fresh = True
            scale = np.maximum(scale, np.diag(H))
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            mu, nu = mu * nu, nu * 2.0
    return LMResult(x, 0.5 * cost, nfev, 0)


def _within_noise(H: np.ndarray, g: np.ndarray, std_tol: float, std: np.ndarray | None) -> bool:
    """Whether the undamped step from here, -H^-1 g, moves every unknown by at most std_tol times its standard
    deviation (`std`, else sqrt(diag(H^-1))): the model's optimum lies within the noise. (The damped step is no
    measure of that: under heavy damping it is short far from the optimum.) False where H is singular."""
    try:
        covariance = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return False
    if std is None:
        std = _diagonal_std(covariance)
    return bool(np.all(np.abs(covariance @ g) <= std_tol * std))


def marginal_std(H: np.ndarray) -> np.ndarray:
    """(P,) sqrt(diag(H^-1)) of a normal matrix (P, P) (priors included: invertible): each unknown's standard
    deviation, what `levenberg_marquardt`'s std_tol counts in."""
    return _diagonal_std(np.linalg.inv(H))


def _diagonal_std(covariance: np.ndarray) -> np.ndarray:
    return np.sqrt(np.maximum(np.diag(covariance), 0.0))
