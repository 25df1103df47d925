"""Solve the problem and report how far to trust each number.

Rounds: robust trf solve -> flag outlier tag views (one tag in one sample whose whitened RMS is far above the
others': a misdetected tag, or every tag of a sample with a stale joint reading; they get zero weight) -> estimate
the corner noise from the whitened inlier residuals (the encoder noise is a known property of the servos and stays
fixed) -> rebuild the weights at the new estimate; until the outlier set and the noise level settle. Then the
uncertainty at the solution: posterior covariance (J^T J)^-1 in prior-normalised units, so each parameter's share
of information from the data is 1 - posterior variance / prior variance; correlated pairs; condition number of
the column-scaled data Jacobian (calibration practice: below 100).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from wolfcal.fit.problem import Problem
from wolfcal.observations import rms_by

# Bounds of the estimated corner noise [px]. The floor is the detector's systematic error: its corner errors of
# 0.02-0.05 px repeat across poses for each tag corner (they do not average out), and tag mounts absorb part of them,
# so the residuals alone would understate it (measured: bench/bench_vision.py, tests/test_other_robot.py).
MIN_SIGMA_PX = 0.05
MAX_SIGMA_PX = 50.0
CORRELATION_LIMIT = 0.9
MAD_TO_SIGMA = 1.4826
OUTLIER_FACTOR = 4.0


@dataclass
class Solution:
    values: np.ndarray  # (P,) [SI]
    std: np.ndarray  # (P,) [SI]
    covariance: np.ndarray  # (P, P) [SI]
    correlation: np.ndarray  # (P, P)
    data_share: np.ndarray  # (P,) in [0, 1]: information from the data rather than the prior
    condition_number: float
    sigma_px: float  # corner noise per axis of the final noise model [px]
    sigma_q: float  # joint reading noise of the final noise model [rad]
    sample_rms_before: np.ndarray  # (S,) [px] per-axis RMS with the nominal model
    sample_rms_after: np.ndarray  # (S,)
    outlier_samples: np.ndarray  # (S,) bool: every tag seen in the sample was left out
    outlier_views: list[tuple[int, int]]  # (sample, tag id) of each tag view left out
    rms_before_px: float  # inlier corners, per axis, nominal model
    rms_after_px: float
    max_after_px: float
    n_corners: int
    evaluations: int
    converged: bool

    def correlated_pairs(self, names: list[str], limit: float = CORRELATION_LIMIT) -> list[tuple[str, str, float]]:
        i, j = np.triu_indices(len(names), k=1)
        strong = np.abs(self.correlation[i, j]) > limit
        pairs = [(names[a], names[b], float(self.correlation[a, b])) for a, b in zip(i[strong], j[strong])]
        return sorted(pairs, key=lambda p: -abs(p[2]))


def flag_outliers(problem: Problem, z: np.ndarray, floor_px: float) -> np.ndarray:
    """(V,) views (one tag in one sample) that the noise model explains far worse than the others (whitened RMS
    above 4x the median) and that are off by more than `floor_px` in pixels."""
    n_views = len(problem.view_sample)
    r = problem.pixel_residuals(z)
    t = rms_by(problem.view_of_corner, problem.whiten(r).reshape(-1, 2), n_views)
    pixels = rms_by(problem.view_of_corner, r, n_views)
    median = np.median(t)
    return (t > OUTLIER_FACTOR * median) & (pixels > floor_px)


def residual_scale(problem: Problem, residuals_px: np.ndarray) -> float:
    """Robust scale of the whitened inlier residuals (1 when the noise model fits), corrected for the degrees of
    freedom the free parameters take."""
    w = problem.whiten(residuals_px)[np.repeat(problem.inlier_corners, 2)]
    n_params = len(problem.params)
    if w.size <= n_params:
        return 1.0
    return float(MAD_TO_SIGMA * np.median(np.abs(w)) * np.sqrt(w.size / (w.size - n_params)))


def estimate_pixel_noise(problem: Problem, z: np.ndarray) -> float:
    """Set sigma_px so that the whitened inlier residuals have unit scale, holding the encoder noise (a known
    property of the servos) fixed; bisection on log(sigma_px). Returns the residual scale reached."""
    r = problem.pixel_residuals(z)  # z is fixed: only the weights change during the search
    lo, hi = np.log(MIN_SIGMA_PX), np.log(MAX_SIGMA_PX)
    for _ in range(14):
        problem.set_noise(float(np.exp(0.5 * (lo + hi))))
        if residual_scale(problem, r) > 1.0:
            lo = np.log(problem.sigma_px)
        else:
            hi = np.log(problem.sigma_px)
    problem.set_noise(float(np.exp(hi)))
    return residual_scale(problem, r)


def central_jacobian(fun: Callable[[np.ndarray], np.ndarray], z: np.ndarray, step: float = 1e-6) -> np.ndarray:
    columns = []
    for i in range(len(z)):
        dz = np.zeros_like(z)
        dz[i] = step
        columns.append((fun(z + dz) - fun(z - dz)) / (2 * step))
    return np.stack(columns, axis=1)


def solve(
    problem: Problem,
    outlier_floor_px: float = 1.0,
    max_rounds: int = 5,
    progress: Callable[[str], None] | None = None,
) -> Solution:
    say = progress or (lambda _msg: None)
    n_params = len(problem.params)
    z = np.zeros(n_params)
    r_before = problem.pixel_residuals(z)
    rms_before_samples = problem.obs.per_sample_rms(r_before)
    evaluations, converged = 0, False
    for round_index in range(max_rounds):
        result = least_squares(problem.residuals, z, method="trf", x_scale=1.0, max_nfev=100 * (n_params + 1))
        z, evaluations, converged = result.x, evaluations + result.nfev, result.status > 0
        problem.linearize(z)
        outliers = flag_outliers(problem, z, outlier_floor_px)
        changed = not np.array_equal(outliers, problem.excluded)
        problem.exclude(outliers)
        previous = problem.sigma_px
        scale = estimate_pixel_noise(problem, z)
        say(
            f"round {round_index + 1}: {int(outliers.sum())} outlier tag view(s), noise model "
            f"{problem.sigma_px:.3f} px per corner + {problem.sigma_q * 1000:.3f} mrad per joint "
            f"(residual scale {scale:.2f})"
        )
        if not changed and abs(problem.sigma_px / previous - 1.0) < 0.1:
            break  # the last solve used (nearly) this noise model and inlier set
    else:
        result = least_squares(problem.residuals, z, method="trf", x_scale=1.0)
        z, evaluations = result.x, evaluations + result.nfev
    J = central_jacobian(problem.residuals, z)
    n_data = J.shape[0] - n_params
    cov_z = np.linalg.pinv(J.T @ J)
    d = np.sqrt(np.clip(np.diag(cov_z), 1e-300, None))
    sig = problem.params.prior_sigmas
    J_data = J[:n_data]
    norms = np.linalg.norm(J_data, axis=0)
    if np.any(norms < 1e-12):
        condition = float("inf")
    else:
        s = np.linalg.svd(J_data / norms, compute_uv=False)
        condition = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    inlier = problem.inlier_corners
    kept_views = np.bincount(problem.view_sample[~problem.excluded], minlength=problem.obs.n_samples)
    r_after = problem.pixel_residuals(z)
    return Solution(
        values=z * sig,
        std=d * sig,
        covariance=cov_z * np.outer(sig, sig),
        correlation=cov_z / np.outer(d, d),
        data_share=np.clip(1.0 - np.diag(cov_z), 0.0, 1.0),
        condition_number=condition,
        sigma_px=problem.sigma_px,
        sigma_q=problem.sigma_q,
        sample_rms_before=rms_before_samples,
        sample_rms_after=problem.obs.per_sample_rms(r_after),
        outlier_samples=kept_views == 0,
        outlier_views=[
            (int(s), int(t)) for s, t in zip(problem.view_sample[problem.excluded], problem.view_tag[problem.excluded])
        ],
        rms_before_px=float(np.sqrt(np.mean(r_before[inlier] ** 2))),
        rms_after_px=float(np.sqrt(np.mean(r_after[inlier] ** 2))),
        max_after_px=float(np.max(np.abs(r_after[inlier]))) if inlier.any() else 0.0,
        n_corners=int(inlier.sum()),
        evaluations=evaluations,
        converged=converged and result.status > 0,
    )
