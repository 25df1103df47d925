"""Solve the problem and report how far to trust each number.

Rounds, from `Problem.start` (the references, or where a block asks the robot model to start): robust
Levenberg-Marquardt solve (analytic Jacobian) -> per block, flag outlier views (one tag in one
image: its residuals, whitened with the covariance of that view alone so that no other view's error leaks in, far
above the other views' and off by more than the block's floor; they get zero weight; then in the views kept, single
units far off where the block has a unit rule: floor-tag corners, `flag_units`) -> per block, estimate the
noise level from the whitened inlier residuals (the encoder noise is a known property of the servos and stays
fixed), and the level of each noise class relative to it (`estimate_class_scales`: one per motion-capture marker)
-> rebuild the weights at the new estimate; until the outlier sets and noise levels settle. Then the final solves:
converge fully (Newton steps on the Huber loss), re-estimate the outlier sets and noise levels at the solution, and
solve again until they no longer change (a fixed point: the solution depends on the data, not on where a round's
solve happened to stop), and `uncertainty` at the solution.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wolfcal.fit.blocks import BlockResult, Linearization
from wolfcal.fit.lm import levenberg_marquardt, marginal_std
from wolfcal.fit.noise import GroupedWhitening, row_groups, weighted_median, weighted_median_above
from wolfcal.fit.problem import MAD_TO_SIGMA, BlockState, Problem
from wolfcal.fit.uncertainty import Uncertainty, information_uncertainty
from wolfcal.observations import rms_by

Standardizer = Callable[[float], tuple[np.ndarray, np.ndarray]]  # `GroupedWhitening.standardizer`

# A round's solve (before its outlier and noise update) stops once a step gains less than this in cost (half the
# whitened sum of squares): within about 0.05 standard deviations of the round's optimum, where the robust loss's
# linear arms would otherwise take many small steps. The solve after the last round converges fully.
ROUND_COST_TOL = 1e-3
# Every solve also stops once the undamped step moves no unknown by more than this many of its standard deviations
# (`levenberg_marquardt`'s std_tol): a round's by ROUND_STD_TOL, a final one by FINAL_STD_TOL. Along the Huber
# loss's linear arms (a view far off while the noise sits at its floor) the rounds' steps (J^T J of the square-root
# residuals) fall short and zigzag for ~200 evaluations, moving the solution by 0.03 standard deviations in all; the
# final solves take Newton steps on the loss itself (`Problem.normal_equations` with curvature) and converge in a
# few. Their cost-change stop (FINAL_FTOL, relative) only guards against a stall: at 1e-8 it stopped a 400-sample
# fit 0.03 standard deviations short.
ROUND_STD_TOL = 0.1
FINAL_STD_TOL = 0.003
FINAL_FTOL = 1e-12
FINAL_DAMPING = 1e-9
# The rounds end once no outlier set changed and no noise level moved by ROUND_NOISE_TOL (relative). The final
# solve is then repeated under the noise model re-estimated at its solution until no outlier set changes and no
# level moves by FIXED_POINT_TOL (a level 0.1 % off moves the estimates by far less than 0.01 standard deviations),
# at most MAX_FINAL_SOLVES times (an outlier set flip-flopping between two solutions: the last solve stands).
ROUND_NOISE_TOL = 0.1
FIXED_POINT_TOL = 1e-3
MAX_FINAL_SOLVES = 4
# A block's noise classes (e.g. its motion-capture markers) each get their own level relative to the block's
# (`_class_level`): the one at which the class's standardised residuals within CLASS_CUT of their median-based spread
# (a reflection does not count, a noisy marker's own scatter does; rows up to CLASS_FADE beyond it count in part)
# have unit RMS, drawn towards the block's level as if CLASS_PRIOR_ROWS residuals had it (25 samples' 75 numbers
# scatter by 8 % in RMS: one marker weighted up by chance pulls the fit to itself and shrinks its residuals further),
# only from at least MIN_CLASS_UNITS units (else the block's level), and never below CLASS_SCALE_FLOOR of the
# block's level.
MIN_CLASS_UNITS = 8
CLASS_CUT = 3.5
CLASS_FADE = 1.0
GROSS_FACTOR = 10.0  # units off by this many unit-rule limits are kept out of their view's estimate
CLASS_PRIOR_ROWS = 30
CLASS_SCALE_FLOOR = 1.0


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
    """(V,) whitened RMS of each view under the covariance of that view's own residuals, over the view's units not
    left out one by one (`flag_units`); NaN for a view without such units."""
    block, residual = state.block, lin.residual
    counted = ~state.excluded_units
    views = row_groups(block.view_of_unit, block.dim, counted)  # group k: the k-th view with a unit counted
    present = np.unique(block.view_of_unit[counted])
    rows = np.bincount(views[views >= 0], minlength=len(present))
    w = GroupedWhitening(views, state.shared_errors(lin), state.row_scale)
    out = np.full(block.n_views, np.nan)
    out[present] = np.sqrt(w.group_norms(residual.ravel(), state.sigma) / rows)
    return out


def flag_outliers(state: BlockState, lin: Linearization) -> np.ndarray:
    """(V,) views the noise model explains far worse than the others and that are off by more than the floor
    (the block's `outlier_rule`: spread = whitened view RMS, size = per-axis view RMS [unit]), judged without the
    units left out one by one (a stray point does not take its view with it)."""
    block, residual = state.block, lin.residual
    counted = ~state.excluded_units
    size = rms_by(block.view_of_unit[counted], residual[counted], block.n_views)
    return block.outlier_rule.flags(view_rms(state, lin), size)


def conditional_residuals(state: BlockState, lin: Linearization, apart: np.ndarray | None = None) -> np.ndarray:
    """(U, dim) each unit's residual less what the view's share of the joint-reading errors explains [unit]: the
    noise part of the best estimate of the view's errors under the covariance of that view alone,
    sigma^2 D C_v^-1 D^-1 r (D: the rows' own noise levels, `BlockState.row_scale`; C_v: the view's covariance in
    the whitened rows' scale). What floor_ground's measurement leaves of a corner once it fits each sample's reading
    errors as unknowns: where the fitted model puts the corner, the view's reading errors taken into account.
    `apart` (U,): units kept out of the view's estimate, which keep their plain residual."""
    block, r = state.block, lin.residual.ravel()
    views = row_groups(block.view_of_unit, block.dim, None if apart is None else ~apart)
    w = GroupedWhitening(views, state.shared_errors(lin), state.row_scale)
    D = state.row_scale
    e = (state.sigma**2 * D * w.apply(D * w.apply(r, state.sigma), state.sigma)).reshape(-1, block.dim)
    if apart is not None:
        e[apart] = lin.residual[apart]
    return e


def flag_units(state: BlockState, lin: Linearization) -> np.ndarray:
    """(U,) single units that are off by more than the block's `unit_rule` allows, in every view (a view left out
    for a few such units comes back without them): size = the norm of the unit's `conditional_residuals` [unit],
    limit = `OutlierRule.limit` of their robust per-axis scale (MAD of the units kept in the views kept). None
    flagged without a unit rule. On a small, strongly foreshortened far floor tag one corner slides along an edge by
    pixels while the view's other corners fit: too little for the view rule. Units off by more than GROSS_FACTOR
    limits (a stray field-line point tens of pixels off) are kept out of their view's estimate, which they would
    spoil for the others."""
    block = state.block
    if block.unit_rule is None:
        return np.zeros(block.n_units, dtype=bool)
    kept_view = ~state.excluded[block.view_of_unit]
    e = conditional_residuals(state, lin)
    counted = kept_view & ~state.excluded_units
    if not counted.any():
        return np.zeros(block.n_units, dtype=bool)
    limit = block.unit_rule.limit(np.array(MAD_TO_SIGMA * float(np.median(np.abs(e[counted])))))
    gross = np.linalg.norm(lin.residual, axis=1) > GROSS_FACTOR * limit
    if gross.any():
        e = conditional_residuals(state, lin, gross)
    return np.linalg.norm(e, axis=1) > limit


def residual_scale(state: BlockState, residual: np.ndarray, sigma: float, n_params: float) -> float:
    """Robust scale of the whitened inlier residuals (1 when the noise model fits): the median over their degrees of
    freedom of the standardised numbers (`GroupedWhitening.standardized`: what the robust fit weighs, independent of
    how a group is decomposed), corrected for the degrees of freedom the free parameters take."""
    return _robust_scale(*state.noise_model.standardized(residual.ravel(), sigma), n_params)


def _robust_scale(w: np.ndarray, dof: np.ndarray, n_params: float) -> float:
    """`residual_scale` of the standardised numbers w with their degrees of freedom dof."""
    n = float(np.sum(dof))
    if n <= n_params:
        return 1.0
    return float(MAD_TO_SIGMA * weighted_median(np.abs(w, out=w), dof) * np.sqrt(n / (n - n_params)))


def _scale_above_one(w: np.ndarray, dof: np.ndarray, n_params: float) -> bool:
    """Whether `residual_scale` of these standardised numbers exceeds 1, without sorting them
    (`weighted_median_above`)."""
    n = float(np.sum(dof))
    if n <= n_params:
        return False
    return weighted_median_above(np.abs(w, out=w), dof, 1.0 / (MAD_TO_SIGMA * np.sqrt(n / (n - n_params))))


def _pooled_scale(w: np.ndarray, dof: np.ndarray, n_params: float, scatter: tuple[float, float], sigma: float) -> float:
    """The scale of a block whose units are means of frames: the squares of `_robust_scale` of its standardised
    numbers and of the frames' scatter about their means at the level `sigma` (sum of squares / sigma^2 per degree
    of freedom), pooled by their degrees of freedom."""
    squares, frame_dof = scatter
    n = float(np.sum(dof))
    model = _robust_scale(w, dof, n_params) ** 2 * max(n - n_params, 0.0)
    return float(np.sqrt((model + squares / sigma**2) / (max(n - n_params, 0.0) + frame_dof)))


def _scale_at(standardized: Standardizer, sigma: float, n_params: float, scatter: tuple[float, float]) -> float:
    """The scale `estimate_noise` brings to 1, at the level `sigma` (`standardized`: `GroupedWhitening.standardizer`
    of the residuals; `scatter`: `BlockState.frame_scatter`)."""
    if scatter[1] > 0:
        return _pooled_scale(*standardized(sigma), n_params, scatter, sigma)
    return _robust_scale(*standardized(sigma), n_params)


def _above_one(standardized: Standardizer, sigma: float, n_params: float, scatter: tuple[float, float]) -> bool:
    """Whether `_scale_at` exceeds 1 (without a sort when the units are single measurements)."""
    if scatter[1] > 0:
        return _scale_at(standardized, sigma, n_params, scatter) > 1.0
    return _scale_above_one(*standardized(sigma), n_params)


def estimate_noise(state: BlockState, residual: np.ndarray, n_params: float) -> float:
    """Set the block's noise level so that its whitened inlier residuals have unit scale (bisection on the log,
    within the block's `noise_min` .. `noise_max` [unit]); returns the residual scale reached (`residual_scale`,
    from the search's own standardised numbers unless setting the level decomposed the groups again). Units that
    are means of frames (`Block.unit_frames`) add the frames' scatter about their means (`_pooled_scale`): the
    frame-to-frame noise that the means no longer show."""
    standardized = state.noise_model.standardizer(residual.ravel())
    scatter = state.frame_scatter()
    lo, hi = np.log(state.block.noise_min), np.log(state.block.noise_max)
    # The scale falls as the level grows: at or below 1 at the floor, every step of the search goes down (the same
    # steps, without evaluating them; the level of a block more precise than the floor, e.g. rendered captures).
    at_floor = not _above_one(standardized, float(np.exp(lo)), n_params, scatter)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if not at_floor and _above_one(standardized, float(np.exp(mid)), n_params, scatter):
            lo = mid
        else:
            hi = mid
    sigma = float(np.exp(hi))
    scale = _scale_at(standardized, sigma, n_params, scatter)
    del standardized  # its arrays are not kept while set_sigma may decompose the groups again
    if state.set_sigma(sigma):  # another noise model: its own standardised numbers
        return _scale_at(state.noise_model.standardizer(residual.ravel()), state.sigma, n_params, scatter)
    return scale


def estimate_class_scales(state: BlockState, lin: Linearization, problem: Problem) -> float:
    """Set each noise class's level relative to the block's (`unit_scale`; see MIN_CLASS_UNITS ff.): the robust
    scale of its units' residuals standardised by their current noise (own level and joint-reading error, per row)
    and by how much of it the fit absorbs (1 - leverage), over all of its units (left-out ones too, so that a marker
    left out for its noise comes back), normalised so the median unit keeps the block's level, floored. Returns
    the largest relative change of a unit's level."""
    classes = state.classes
    if classes.max(initial=0) == 0:
        return 0.0
    dim = state.block.dim
    A = lin.joint_sensitivity.reshape(-1, lin.joint_sensitivity.shape[-1])
    reading = state.sigma_q**2 * np.sum(A**2, axis=1)  # (R,) the joint readings' share of each row's variance
    variance = (state.sigma * state.row_scale) ** 2 + reading
    absorbed = 1.0 - _leverages(state, lin, problem, variance)
    z = np.abs(lin.residual.ravel()) / np.sqrt(variance * absorbed)
    row_class = np.repeat(classes, dim)
    level = np.ones(int(classes.max()) + 1)
    for c in range(len(level)):
        rows = row_class == c
        zc = z[rows]
        if zc.size >= MIN_CLASS_UNITS * dim:
            # the class's own outliers apart, rows past the cut fading out over CLASS_FADE (a hard cut would jump
            # by a whole row's square as its residual crosses it: the levels would never settle)
            spread = MAD_TO_SIGMA * float(np.median(zc))
            weight = np.clip((CLASS_CUT + CLASS_FADE - zc / spread) / CLASS_FADE, 0.0, 1.0)
            level[c] = _class_level(
                weight * lin.residual.ravel()[rows] ** 2 / absorbed[rows],
                state.sigma**2,
                reading[rows],
                float(np.sum(weight)),
            )
    scale = level[classes]
    scale = np.maximum(scale / np.median(scale), CLASS_SCALE_FLOOR)
    change = float(np.max(np.abs(scale / state.unit_scale - 1.0)))
    state.unit_scale = scale
    return change


def _class_level(weighted_sq: np.ndarray, sigma2: float, reading: np.ndarray, rows: float) -> float:
    """The level s of one noise class relative to the block's noise sigma (sigma2 = sigma^2) at which its rows'
    weighted squared residuals (weighted_sq (R,), divided by 1 - leverage) are as large as their variance says,
    sigma^2 s^2 + the joint readings' share `reading` (R,), with CLASS_PRIOR_ROWS more rows at the block's level:
    sum(weighted_sq / (sigma^2 s^2 + reading)) + CLASS_PRIOR_ROWS / s^2 = rows + CLASS_PRIOR_ROWS, by bisection on
    log s (the left side falls as s grows). Solved outright rather than moved by the ratio of residual to modelled
    variance once per round: where the joint readings make up most of a row's variance that ratio moves the level
    by a few percent of the way per round, and the solution would depend on the round the solver stopped at."""
    lo, hi = np.log(1e-3), np.log(1e3)
    target = rows + CLASS_PRIOR_ROWS
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        s2 = float(np.exp(2.0 * mid))
        if float(np.sum(weighted_sq / (sigma2 * s2 + reading))) + CLASS_PRIOR_ROWS / s2 > target:
            lo = mid
        else:
            hi = mid
    return float(np.exp(0.5 * (lo + hi)))


def _leverages(state: BlockState, lin: Linearization, problem: Problem, variance: np.ndarray) -> np.ndarray:
    """(R,) leverage of each residual row of the block on the chain and the block's own unknowns, rows weighted by
    1 / variance (R,) (their correlation through the joint readings left aside), priors included; left-out rows
    carry no weight and get 0. Below 1 by the priors."""
    rows = lin.residual.size
    sig = problem.params.prior_sigmas
    n_local = len(state.block.nuisance)
    J = np.zeros((rows, problem.n_chain + n_local))
    J[:, : problem.n_chain] = lin.jac_chain.reshape(rows, problem.n_chain)
    if lin.jac_local is not None and lin.local_cols is not None:
        L = lin.jac_local.shape[-1]
        cols = problem.n_chain + np.repeat(lin.local_cols, state.block.dim, axis=0).ravel()
        np.add.at(J, (np.repeat(np.arange(rows), L), cols), lin.jac_local.reshape(rows, L).ravel())
    J *= np.concatenate([sig[: problem.n_chain], sig[state.start : state.start + n_local]])
    J *= (np.repeat(state.inlier_units, state.block.dim) / np.sqrt(variance))[:, None]
    M = J.T @ J + np.eye(J.shape[1])
    return np.einsum("ij,ji->i", J, np.linalg.solve(M, J.T))


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
        class_sigma=state.sigma * _class_scale(state),
    )  # fmt: skip


def _class_scale(state: BlockState) -> np.ndarray:
    """(C,) each noise class's level relative to the block's (1 for a class without units)."""
    classes = state.classes
    out = np.ones(int(classes.max(initial=0)) + 1)
    out[classes] = state.unit_scale
    return out


def _update_outliers(problem: Problem, lins: list[Linearization]) -> bool:
    """Flag the single units left out (`flag_units`), then each block's outlier views judged without them, at these
    linearisations; whether any outlier set changed."""
    changed = False
    for state, lin in zip(problem.states, lins):
        units = flag_units(state, lin)
        changed |= not np.array_equal(units, state.excluded_units)
        state.excluded_units = units
        outliers = flag_outliers(state, lin)
        changed |= not np.array_equal(outliers, state.excluded)
        state.excluded = outliers
    return changed


def _update_noise(
    problem: Problem, lins: list[Linearization], n_params: int, rows_total: int
) -> tuple[float, list[str]]:
    """Re-estimate each block's noise level (its share of the free parameters by rows); the largest relative change
    of a block's level or of a unit's level within it, and one progress note per block."""
    largest, notes = 0.0, []
    for state, lin in zip(problem.states, lins):
        previous = state.sigma
        share = n_params * lin.residual.size / rows_total
        scale = estimate_noise(state, lin.residual, share)
        change = estimate_class_scales(state, lin, problem)
        if change > 0.0:  # the noise model changed shape: decompose again, then the block's level
            state.rebuild(lin)
            scale = estimate_noise(state, lin.residual, share)
        largest = max(largest, abs(state.sigma / previous - 1.0), change)
        notes.append(
            f"{state.block.name}: {int(state.excluded.sum())} outlier view(s)"
            + (
                f" and {int(state.excluded_units.sum())} single {state.block.unit_name}(s)"
                if state.excluded_units.any()
                else ""
            )
            + f", noise {state.sigma:.3g} "
            f"{state.block.unit} (scale {scale:.2f})"
        )
    return largest, notes


def _update_round(problem: Problem, z: np.ndarray, rows_total: int) -> tuple[bool, float, list[str]]:
    """Outlier sets, noise groups and noise levels at z (`_update_outliers`, `_update_noise`): whether an outlier
    set changed, the largest relative change of a noise level, progress notes. The linearisations live only here."""
    lins = problem.evaluate(z)
    for state in problem.states:  # rebuilt below: not kept beside the per-view noise models of the outlier flags
        state.whitening = None
    changed = _update_outliers(problem, lins)
    problem.linearize(z)
    change, notes = _update_noise(problem, lins, len(problem.params), rows_total)
    return changed, change, notes


def solve(problem: Problem, max_rounds: int = 5, progress: Callable[[str], None] | None = None) -> Solution:
    """Solve with outlier rounds (module docstring); each block's noise level stays within its `noise_min` ..
    `noise_max`."""
    say = progress or (lambda _msg: None)
    before = [r.copy() for r in problem.raw_residuals(np.zeros(len(problem.params)))]  # the nominal model's
    z = problem.start.copy()
    rows_total = sum(r.size for r in before)
    evaluations = 0
    for round_index in range(max_rounds):
        result = levenberg_marquardt(
            problem.residuals, problem.normal_equations, z, cost_tol=ROUND_COST_TOL, std_tol=ROUND_STD_TOL
        )
        z, evaluations = result.x, evaluations + result.nfev
        changed, change, notes = _update_round(problem, z, rows_total)
        say(f"round {round_index + 1}: " + "; ".join(notes) + f"; joint noise {problem.sigma_q * 1000:.3f} mrad")
        if not changed and change < ROUND_NOISE_TOL:
            break

    # The final solves: converge under the noise model, then re-estimate it at the converged point, until it is
    # the one the solution was solved under (a fixed point: the estimate no longer depends on where a round stopped).
    def newton(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return problem.normal_equations(z, curvature=True)

    std = marginal_std(problem.normal_equations(z)[0])  # what the final solves' std_tol counts in
    for final_index in range(MAX_FINAL_SOLVES):
        result = levenberg_marquardt(
            problem.residuals, newton, z, ftol=FINAL_FTOL, std_tol=FINAL_STD_TOL, std=std, damping=FINAL_DAMPING
        )
        z, evaluations = result.x, evaluations + result.nfev
        if final_index == MAX_FINAL_SOLVES - 1:
            say(
                f"the noise model did not settle in {MAX_FINAL_SOLVES} final solves (last change: "
                f"{'an outlier set' if changed else f'noise {change:.1%}'}); the solution is the last solve's"
            )
            break
        changed, change, notes = _update_round(problem, z, rows_total)
        if not changed and change < FIXED_POINT_TOL:
            break
        say(
            f"final solve {final_index + 1}: the noise model at its solution differs ("
            f"{'outlier set changed' if changed else f'noise {change:.2%}'}): " + "; ".join(notes) + "; solving again"
        )
    after = problem.raw_residuals(z)
    information, _, _ = problem.information(z)
    return Solution(
        values=problem.values(z),
        uncertainty=information_uncertainty(
            information,
            problem.params.prior_sigmas,
            lambda: problem.information(z, triangular=True)[2],
            conditioned=np.array([p.kind != "marking" for p in problem.params.parameters], bool),
        ),
        blocks=[_block_result(s, b, a) for s, b, a in zip(problem.states, before, after)],
        sigma_q=problem.sigma_q,
        evaluations=evaluations,
        converged=result.status > 0,
    )
