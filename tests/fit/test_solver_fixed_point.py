"""The fit's estimates are a function of the data, not of floating-point rounding or of where a solver round stopped.

The shipped `captures/legs_demo.mcap` fitted with `--free camera` (legs off: residuals of 0.5 px, far above the noise
floor, so the noise level is estimated and moves the weights) is the case where, before the fixed-point solve, the
order of the samples alone moved the camera pose by 0.05 of its standard deviation, 1e-9 px on the corners by 0.16,
and a tighter round tolerance by 0.07: the noise model came from wherever a round's solve happened to stop, and the
noise level's median jumped between two neighbouring residuals as float rounding decided a tie.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_mocap_block import WOLFGANG, simulate

from wolfcal.fit import solver
from wolfcal.fit.noise import weighted_median, weighted_median_above
from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples
from wolfcal.robot.robot import load_robot
from wolfcal.sim.mocap_scene import MocapNoise
from wolfcal.sim.observations import reordered
from wolfcal.vision.observe import detect_observations

ROOT = Path(__file__).resolve().parents[2]
TOLERANCE_STD = 0.01  # largest |difference| / reported std allowed between fits of the same data


def test_the_median_of_an_even_count_does_not_jump_with_rounding():
    values = 0.6 + 0.004 * np.arange(100)  # standardised residuals around a median, 0.004 apart
    exact = weighted_median(values, np.ones(100))
    weights = np.ones(100)
    weights[70] += 1e-12  # a weight's last bits
    assert exact == pytest.approx(0.798)  # between the middle two, as a plain median is
    # an order statistic jumps by the gap to the next value here: the cumulative weight passes half at it
    assert abs(weighted_median(values, weights) - exact) < 1e-9
    assert weighted_median(np.array([1.0, 2.0, 3.0, 4.0]), np.ones(4)) == pytest.approx(2.5)  # values far apart


def test_the_threshold_test_agrees_with_the_median():
    rng = np.random.default_rng(0)
    for _ in range(200):
        values, weights = np.abs(rng.normal(size=50)), rng.uniform(0.1, 2.0, 50)
        median = weighted_median(values, weights)
        for threshold in (median - 1e-6, median + 1e-6, median - 0.1, median + 0.1):
            assert weighted_median_above(values, weights, threshold) == (median > threshold)
    big = np.abs(rng.normal(size=200_000))
    assert weighted_median(big, np.ones_like(big)) == pytest.approx(np.median(big), rel=2e-3)  # the spread's bias


def sorted_weighted_median(values: np.ndarray, weights: np.ndarray, width: float = 0.05) -> float:
    """`weighted_median` by its definition over every value: all 2N edges of the spread weights sorted, the
    piecewise-linear cumulative weight walked from the lowest (the middle of a flat stretch at half)."""
    edges = np.concatenate([values - width, values + width])
    order = np.argsort(edges, kind="stable")
    slope = np.cumsum(np.concatenate([weights, -weights])[order] / (2.0 * width))
    edges = edges[order]
    cumulative = np.concatenate([[0.0], np.cumsum(slope[:-1] * np.diff(edges))])
    half = 0.5 * float(np.sum(weights))

    def at(level: float) -> float:
        k = min(int(np.searchsorted(cumulative, level)), len(edges) - 1)
        return (
            float(edges[k])
            if k == 0 or slope[k - 1] <= 0.0
            else float(edges[k - 1] + (level - cumulative[k - 1]) / slope[k - 1])
        )

    return 0.5 * (at(half * (1.0 - 1e-9)) + at(half * (1.0 + 1e-9)))


def test_the_median_found_in_a_window_is_the_median_over_all_values():
    """`weighted_median` sorts only the values near the plain median: the same number as the definition walked over
    all of them, for standardised numbers with their shares as weights (many values, heavy tails, an offset plain
    median), values far apart (a flat stretch at half), ties, one value and no weight."""
    rng = np.random.default_rng(4)
    cases = [
        (np.abs(rng.standard_t(3, 20_000)), rng.uniform(0.0, 1.0, 20_000)),
        (np.abs(rng.normal(size=3000)), np.where(rng.random(3000) < 0.3, 5.0, 0.1)),
        (np.array([1.0, 2.0, 3.0, 4.0]), np.ones(4)),
        (np.array([0.5, 0.5, 0.5, 2.0]), np.array([1.0, 1, 1, 3])),
        (np.array([0.7]), np.array([0.4])),
        (np.array([0.2, 0.9]), np.zeros(2)),
    ]
    cases += [(np.round(np.abs(rng.normal(size=400)), 1), rng.uniform(0.1, 2.0, 400)) for _ in range(20)]
    for values, weights in cases:
        assert weighted_median(values, weights) == pytest.approx(
            sorted_weighted_median(values, weights), rel=1e-12, abs=1e-12
        )


@pytest.fixture(scope="module")
def legs_demo():
    robot = load_robot(ROOT / "configs" / "wolfgang")
    samples, _ = load_samples(robot, [ROOT / "captures" / "legs_demo.mcap"], None)
    observations = detect_observations(samples, robot)[0]
    return robot, observations


def largest_change(a, b) -> tuple[float, float]:
    """Largest |difference| of the chain parameters in a's std, and largest relative difference of their std."""
    n = len(a.chain)
    std = a.solution.std[:n]
    moved = np.max(np.abs(a.solution.values[:n] - b.solution.values[:n]) / std)
    return float(moved), float(np.max(np.abs(b.solution.std[:n] / std - 1.0)))


@pytest.mark.slow
def test_a_fit_does_not_depend_on_sample_order_or_the_last_bits_of_the_corners(legs_demo):
    robot, observations = legs_demo
    options = FitOptions(free="camera")
    fit = fit_observations(robot, observations, options)
    assert fit.solution.blocks[0].sigma > 0.3  # the noise level is estimated (far above its 0.05 px floor)
    for seed in range(1, 5):
        jittered = {k: replace(o, uv=o.uv + 1e-7 * np.random.default_rng(seed).standard_normal(o.uv.shape))
                    for k, o in observations.items()}  # fmt: skip
        reordered_observations = {name: reordered(obs, seed) for name, obs in observations.items()}
        for other in (reordered_observations, jittered):
            moved, std_change = largest_change(fit, fit_observations(robot, other, options))
            assert moved < TOLERANCE_STD and std_change < TOLERANCE_STD


@pytest.mark.slow
def test_a_fit_does_not_depend_on_where_a_round_stopped(legs_demo, monkeypatch):
    robot, observations = legs_demo
    options = FitOptions(free="camera")
    fit = fit_observations(robot, observations, options)
    monkeypatch.setattr(solver, "ROUND_STD_TOL", 0.03)  # rounds converge further, so stop elsewhere
    monkeypatch.setattr(solver, "ROUND_COST_TOL", 1e-4)
    moved, std_change = largest_change(fit, fit_observations(robot, observations, options))
    assert moved < TOLERANCE_STD and std_change < TOLERANCE_STD


def test_the_marker_noise_levels_are_the_ones_at_the_solution():
    """Re-estimating the motion-capture block's noise model (its level and one per marker) at the solution changes
    none of it: the levels are a fixed point, not a step on the way to one."""
    robot = load_robot(WOLFGANG)
    obs, *_ = simulate(robot, 25, seed=5, noise=MocapNoise(reflections=0.02))
    fit = fit_observations(robot, {}, FitOptions(free="leg", system="mocap"), markers=obs)
    problem, state = fit.problem, fit.problem.states[0]
    z = (fit.solution.values - problem.params.references) / problem.params.prior_sigmas
    sigma, levels = state.sigma, state.unit_scale.copy()
    lin = problem.evaluate(z)[0]
    state.rebuild(lin)
    assert solver.estimate_class_scales(state, lin, problem) < 2 * solver.FIXED_POINT_TOL
    np.testing.assert_allclose(state.unit_scale, levels, rtol=2 * solver.FIXED_POINT_TOL)
    assert state.sigma == sigma
