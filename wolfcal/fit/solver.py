"""Solve the problem and report how far to trust each number.

Rounds: robust Levenberg-Marquardt solve (analytic Jacobian) -> per block, flag outlier views (one tag in one
image: its residuals, whitened with the covariance of that view alone so that no other view's error leaks in, far
above the other views' and off by more than the block's floor; they get zero weight) -> per block, estimate the
noise level from the whitened inlier residuals (the encoder noise is a known property of the servos and stays
fixed) -> rebuild the weights at the new estimate; until the outlier sets and noise levels settle. Then a full
solve under the final noise model, and `uncertainty` at its solution.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wolfcal.fit.blocks import Linearization
from wolfcal.fit.lm import levenberg_marquardt
from wolfcal.fit.noise import GroupedWhitening, row_groups
from wolfcal.fit.options import NOISE_FLOOR_PX
from wolfcal.fit.problem import MAD_TO_SIGMA, BlockState, Problem
from wolfcal.fit.uncertainty import Uncertainty, uncertainty
from wolfcal.observations import rms_by

# Bounds of a block's estimated noise per unit; the pixel floor is the fit's setting (`FitOptions.noise_floor_px`,
# see there why).
MIN_SIGMA = {"px": NOISE_FLOOR_PX, "m": 1e-5}
MAX_SIGMA = {"px": 50.0, "m": 0.1}
# A round's solve (before its outlier and noise update) stops once a step gains less than this in cost (half the
# whitened sum of squares): within about 0.05 standard deviations of the round's optimum, where the robust loss's
# linear arms would otherwise take many small steps. The solve after the last round converges fully.
ROUND_COST_TOL = 1e-3


@dataclass
class BlockResult:
    """What one measurement block says about the fit, in its own unit."""

    name: str
    system: str
    unit: str  # 'px' | 'm'
    sigma: float  # noise per measured number of the final noise model [unit]
    rms_before: float  # inlier units, per axis, nominal model [unit]
    rms_after: float
    max_after: float  # largest inlier unit distance [unit]
    n_units: int  # inlier units (corners, markers)
    sample_rms_before: np.ndarray  # (S_block,) per-axis RMS per sample [unit]
    sample_rms_after: np.ndarray
    outlier_views: list[tuple[int, int]]  # (sample, tag or marker id) of each view left out
    outlier_samples: np.ndarray  # (S_block,) bool: every view of the sample was left out


@dataclass
class Solution:
    values: np.ndarray  # (P,) [SI], every unknown of the problem (chain first)
    uncertainty: Uncertainty
    blocks: list[BlockResult]
    sigma_q: float  # joint reading noise of the noise model [rad]
    evaluations: int
    converged: bool

    @property
    def std(self) -> np.ndarray:
        return self.uncertainty.std


def view_rms(state: BlockState, lin: Linearization) -> np.ndarray:
    """(V,) whitened RMS of each view under the covariance of that view's own residuals."""
    block, residual = state.block, lin.residual
    views = row_groups(block.view_of_unit, block.dim)  # every view has a unit, so group k is view k
    rows = np.bincount(views, minlength=block.n_views)
    return np.sqrt(GroupedWhitening(views, state.shared_errors(lin)).group_norms(residual.ravel(), state.sigma) / rows)


def flag_outliers(state: BlockState, lin: Linearization) -> np.ndarray:
    """(V,) views the noise model explains far worse than the others and that are off by more than the floor
    (the block's `outlier_rule`: spread = whitened view RMS, size = per-axis view RMS [unit])."""
    block, residual = state.block, lin.residual
    size = rms_by(block.view_of_unit, residual, block.n_views)
    return block.outlier_rule.flags(view_rms(state, lin), size)


def residual_scale(state: BlockState, residual: np.ndarray, sigma: float, n_params: float) -> float:
    """Robust scale of the whitened inlier residuals (1 when the noise model fits), corrected for the degrees of
    freedom the free parameters take."""
    w = state.noise_model.whitened(residual.ravel(), sigma)
    if w.size <= n_params:
        return 1.0
    return float(MAD_TO_SIGMA * np.median(np.abs(w)) * np.sqrt(w.size / (w.size - n_params)))


def estimate_noise(state: BlockState, residual: np.ndarray, n_params: float, floor: float) -> float:
    """Set the block's noise level so that its whitened inlier residuals have unit scale (bisection on the log,
    not below `floor` [unit]); returns the residual scale reached."""
    lo, hi = np.log(floor), np.log(MAX_SIGMA[state.block.unit])
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if residual_scale(state, residual, float(np.exp(mid)), n_params) > 1.0:
            lo = mid
        else:
            hi = mid
    state.set_sigma(float(np.exp(hi)))
    return residual_scale(state, residual, state.sigma, n_params)


def _block_result(state: BlockState, before: np.ndarray, after: np.ndarray) -> BlockResult:
    block = state.block
    inlier = state.inlier_units
    n_samples = len(block.q_measured)
    view_sample = np.array([s for s, _ in block.view_labels], dtype=int)

    def per_sample(r: np.ndarray) -> np.ndarray:
        return rms_by(block.sample_of_unit, r, n_samples)

    def rms(r: np.ndarray) -> float:
        return float(np.sqrt(np.mean(r[inlier] ** 2))) if inlier.any() else float("nan")

    return BlockResult(
        name=block.name, system=block.system, unit=block.unit, sigma=state.sigma,
        rms_before=rms(before), rms_after=rms(after),
        max_after=float(np.max(np.linalg.norm(after[inlier], axis=1))) if inlier.any() else 0.0,
        n_units=int(inlier.sum()),
        sample_rms_before=per_sample(before), sample_rms_after=per_sample(after),
        outlier_views=[block.view_labels[v] for v in np.flatnonzero(state.excluded)],
        outlier_samples=np.bincount(view_sample[~state.excluded], minlength=n_samples) == 0,
    )  # fmt: skip


def _update_outliers(problem: Problem, lins: list[Linearization]) -> bool:
    """Flag each block's outlier views at these linearisations; whether any outlier set changed."""
    changed = False
    for state, lin in zip(problem.states, lins):
        outliers = flag_outliers(state, lin)
        changed |= not np.array_equal(outliers, state.excluded)
        state.excluded = outliers
    return changed


def _update_noise(
    problem: Problem, lins: list[Linearization], n_params: int, rows_total: int, min_sigma: dict[str, float]
) -> tuple[bool, list[str]]:
    """Re-estimate each block's noise level (its share of the free parameters by rows); whether every level
    settled (changed by less than 10 %), and one progress note per block."""
    settled, notes = True, []
    for state, lin in zip(problem.states, lins):
        previous = state.sigma
        share = n_params * lin.residual.size / rows_total
        scale = estimate_noise(state, lin.residual, share, min_sigma[state.block.unit])
        settled &= abs(state.sigma / previous - 1.0) < 0.1
        notes.append(
            f"{state.block.name}: {int(state.excluded.sum())} outlier view(s), noise {state.sigma:.3g} "
            f"{state.block.unit} (scale {scale:.2f})"
        )
    return settled, notes


def _update_round(
    problem: Problem, z: np.ndarray, rows_total: int, min_sigma: dict[str, float]
) -> tuple[bool, bool, list[str]]:
    """Outlier sets, noise groups and noise levels at z (`_update_outliers`, `_update_noise`); the linearisations
    live only here."""
    lins = problem.evaluate(z)
    changed = _update_outliers(problem, lins)
    problem.linearize(z)
    settled, notes = _update_noise(problem, lins, len(problem.params), rows_total, min_sigma)
    return changed, settled, notes


def solve(
    problem: Problem, max_rounds: int = 5, progress: Callable[[str], None] | None = None,
    min_sigma: dict[str, float] = MIN_SIGMA,
) -> Solution:
    """Solve with outlier rounds (module docstring); `min_sigma`: floor of each unit's estimated noise."""
    say = progress or (lambda _msg: None)
    z = np.zeros(len(problem.params))
    before = [r.copy() for r in problem.raw_residuals(z)]
    rows_total = sum(r.size for r in before)
    evaluations = 0
    for round_index in range(max_rounds):
        result = levenberg_marquardt(problem.residuals, problem.jacobian, z, cost_tol=ROUND_COST_TOL)
        z, evaluations = result.x, evaluations + result.nfev
        changed, settled, notes = _update_round(problem, z, rows_total, min_sigma)
        say(f"round {round_index + 1}: " + "; ".join(notes) + f"; joint noise {problem.sigma_q * 1000:.3f} mrad")
        if not changed and settled:
            break
    result = levenberg_marquardt(problem.residuals, problem.jacobian, z)
    z, evaluations = result.x, evaluations + result.nfev
    after = problem.raw_residuals(z)
    return Solution(
        values=problem.values(z),
        uncertainty=uncertainty(problem.data_jacobian(z), problem.params.prior_sigmas),
        blocks=[_block_result(s, b, a) for s, b, a in zip(problem.states, before, after)],
        sigma_q=problem.sigma_q,
        evaluations=evaluations,
        converged=result.status > 0,
    )
