"""A fit's reported std checked against how much its estimates move between groups of views (a grouped jackknife).

A block may ask for it (`Replicable`: `jackknife_groups` > 0, e.g. the field lines, whose detector errors the noise
model does not fully name). Its samples are dealt into G groups (sample k in group k mod G, `view_groups`); the
problem is solved G times more, each time with one group left out (`Replicable.without_samples`, the other blocks
kept), from the solution and under the fit's noise model (its levels and outlier sets held: the jackknife of the
fit's estimator with its weights, not of its outlier and noise rounds). The jackknife's covariance of the G
estimates, (G - 1) / G * sum (x_g - mean)(x_g - mean)^T, holds what differs from view to view whether or not the
noise model holds it. The rule: each unknown's std is the larger of the formal one and the jackknife's; the
covariance is scaled alike, D C D with D = diag(reported / formal), so the correlations (and the data shares) stay
the formal ones. Errors shared by every view (a marking's place) do not move between groups: the formal std keeps
holding them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from functools import partial
from typing import Protocol, runtime_checkable

import numpy as np

from wolfcal.fit.blocks import Block
from wolfcal.fit.lm import levenberg_marquardt, marginal_std
from wolfcal.fit.problem import Problem
from wolfcal.fit.solver import FINAL_DAMPING, FINAL_FTOL, FINAL_STD_TOL, Solution

JACKKNIFE_GROUPS = 6  # groups of views each left out once: one more solve each
RULE = (  # in words, for result.yaml
    "each unknown's std is the larger of the formal one (the noise model's) and a grouped jackknife's over the "
    "views (dealt into groups, each left out once, the fit solved again under its noise model): errors shared by "
    "the points of a view that the noise model misses are held by the jackknife"
)


@runtime_checkable
class Replicable(Protocol):
    """A block whose std is checked by a jackknife over groups of its samples."""

    jackknife_groups: int  # 0: not checked
    # set by `spread_checked`: per unknown of the fit, its jackknife std over its formal std
    jackknife_ratio: dict[str, float]

    @property
    def n_samples(self) -> int: ...

    def without_samples(self, keep: np.ndarray) -> Block:
        """The same block on the samples where keep (S,) is True, its own unknowns named and referenced as
        before (those of a placement left without samples dropped), weighted alike, not checked again."""
        ...

    def units_in(self, part: Block, keep: np.ndarray) -> np.ndarray:
        """(U_part,) this block's unit of each unit of `part` (`without_samples(keep)`)."""
        ...


def view_groups(n_samples: int, groups: int = JACKKNIFE_GROUPS) -> np.ndarray:
    """(S,) the group of each sample: sample k in group k mod min(S, groups)."""
    return np.arange(n_samples) % max(1, min(n_samples, groups))


def jackknife_covariance(replicates: np.ndarray) -> np.ndarray:
    """(P, P) the grouped jackknife's covariance of estimates from the G replicates (G, P), each with one group
    left out."""
    d = replicates - replicates.mean(axis=0)
    return (len(replicates) - 1) / len(replicates) * d.T @ d


def spread_checked(problem: Problem, solution: Solution, sigmas: Sequence[float],
                   say: Callable[[str], None] | None = None) -> tuple[Solution, dict[int, np.ndarray]]:  # fmt: skip
    """The solution with each unknown's std the larger of the formal and the jackknife's over the view groups of
    every `Replicable` block (module docstring); and per such block (its index in `problem.blocks`) the jackknife
    std of every unknown (P,) [SI]. `sigmas`: the blocks' starting noise levels, as the problem was built with.
    A block with fewer than 3 samples is not checked."""
    params = problem.params
    z = (solution.values - params.references) / params.prior_sigmas
    formal = solution.uncertainty.std
    reported = formal.copy()
    spreads: dict[int, np.ndarray] = {}
    at = {name: k for k, name in enumerate(params.names)}  # the fit's index of each unknown
    for i, block in enumerate(problem.blocks):
        if not isinstance(block, Replicable) or block.jackknife_groups <= 0 or block.n_samples < 3:
            continue
        groups = view_groups(block.n_samples, block.jackknife_groups)
        if say is not None:
            say(f"{block.name}: solving again with each of {groups.max() + 1} groups of its views left out ...")
        replicates = []
        for g in range(int(groups.max()) + 1):
            blocks = list(problem.blocks)
            blocks[i] = block.without_samples(groups != g)
            again = Problem(problem.chain, blocks, list(sigmas), problem.sigma_q, problem.huber_k)
            if not set(again.params.names) <= set(at):  # a placement left without samples renames the others
                continue
            # a placement whose samples all fell in the group left out has no unknowns there: it keeps the solution
            rows = np.array([at[name] for name in again.params.names])
            values = solution.values.copy()
            _start_where_solved(again, problem, i, block.units_in(blocks[i], groups != g), z[rows])
            values[rows] = again.values(_converged(again, z[rows]))
            replicates.append(values)
        spread = np.sqrt(np.clip(np.diag(jackknife_covariance(np.array(replicates))), 0.0, None))
        spreads[i] = spread
        block.jackknife_ratio = dict(zip(params.names, (spread / formal).tolist()))
        reported = np.maximum(reported, spread)
    if not spreads:
        return solution, spreads
    scale = reported / formal
    u = solution.uncertainty
    uncertainty = replace(u, std=reported, covariance=u.covariance * np.outer(scale, scale))
    return replace(solution, uncertainty=uncertainty), spreads


def _converged(problem: Problem, z: np.ndarray) -> np.ndarray:
    """The unknowns (prior-normalised) where `problem`'s cost under its present noise model is least, from z:
    Newton steps on the robust loss, converged as the fit's final solve (`wolfcal.fit.solver`)."""
    newton = partial(problem.normal_equations, curvature=True)
    std = marginal_std(problem.normal_equations(z)[0])
    return levenberg_marquardt(problem.residuals, newton, z, ftol=FINAL_FTOL, std_tol=FINAL_STD_TOL, std=std,
                               damping=FINAL_DAMPING).x  # fmt: skip


def _start_where_solved(again: Problem, problem: Problem, replicated: int, units: np.ndarray, z: np.ndarray) -> None:
    """The replicate `again` (block `replicated` on fewer samples, its units `units` of the fit's) under the fit's
    noise model: its noise levels, unit levels and outlier sets, the noise groups built at z."""
    for k, (state, solved) in enumerate(zip(again.states, problem.states)):
        own = units if k == replicated else np.arange(solved.block.n_units)
        state.excluded_units = solved.excluded_units[own]
        state.unit_scale = solved.unit_scale[own]
        views = np.zeros(state.block.n_views, dtype=bool)
        views[state.block.view_of_unit] = solved.excluded[solved.block.view_of_unit[own]]
        state.excluded, state.sigma = views, solved.sigma
    again.linearize(z)
