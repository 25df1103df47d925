"""A camera block linearised chunk by chunk of samples (bounded memory on long recordings) gives every corner the
numbers of one pass over all samples, for the head camera and for an external camera with two placements; corners
in any order, or tags with fewer than four corners, get the numbers they get in whole tags in detection order."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest
from test_external_fit import WEBCAM, other_robot  # noqa: F401 (fixture)

from wolfcal.fit import camera_block
from wolfcal.fit.camera_block import CameraBlock
from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.robot.derivatives import ChainDerivatives, tag_key
from wolfcal.sim.scenario import synthetic_external_scenario, synthetic_scenario


def linearizations(fit, monkeypatch, chunk: int):
    values = fit.solution.values
    monkeypatch.setattr(camera_block, "CHUNK_SAMPLES", chunk)
    return [b.linearize(values[: len(fit.chain)], fit.problem.local_values(values, s), fit.chain)
            for b, s in zip(fit.blocks, fit.problem.states)]  # fmt: skip


def assert_same(fit, monkeypatch):
    n_samples = len(fit.blocks[0].q_measured)
    whole = linearizations(fit, monkeypatch, n_samples)
    chunked = linearizations(fit, monkeypatch, 7)  # several chunks, the last one short
    assert n_samples % 7 and n_samples > 14
    for a, b in zip(whole, chunked):
        for f in fields(a):
            x, y = getattr(a, f.name), getattr(b, f.name)
            assert (x is None) == (y is None), f.name
            if x is not None:
                assert x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y), f.name


def test_head_camera_linearised_in_chunks_equals_one_pass(robot, camera, monkeypatch):
    scenario = synthetic_scenario(robot, camera, n=40, seed=3, offsets="legs")
    assert_same(fit_observations(robot, scenario.obs, FitOptions(free="leg")), monkeypatch)


@pytest.mark.parametrize("placements", [2])
def test_external_camera_linearised_in_chunks_equals_one_pass(other_robot, placements, monkeypatch):  # noqa: F811
    scenario = synthetic_external_scenario(other_robot, WEBCAM, n=30, seed=2, placements=placements)
    fit = fit_observations(other_robot, scenario.obs, FitOptions(free="leg", system="external"))
    assert fit.blocks[0].external
    assert_same(fit, monkeypatch)


def test_corners_in_any_order_or_missing_get_their_numbers(robot, camera):
    scenario = synthetic_scenario(robot, camera, n=20, seed=4, offsets="legs")
    fit = fit_observations(robot, scenario.obs, FitOptions(free="leg"))
    obs, block, values = scenario.obs, fit.blocks[0], fit.solution.values
    chain_values = values[: len(fit.chain)]
    whole = block.linearize(chain_values, np.zeros(0), fit.chain)
    rng = np.random.default_rng(0)
    order = rng.permutation(len(obs.uv))  # corners shuffled, and one corner of every fifth view left out
    order = order[~np.isin(order, np.flatnonzero(obs.corner_index == 2)[::5])]
    picked = replace(obs, sample_index=obs.sample_index[order], tag_ids=obs.tag_ids[order],
                     corner_index=obs.corner_index[order], uv=obs.uv[order])  # fmt: skip
    other = CameraBlock(robot, picked, block.tag_ids).linearize(chain_values, np.zeros(0), fit.chain)
    for f in fields(whole):
        x, y = getattr(whole, f.name), getattr(other, f.name)
        if x is not None:
            np.testing.assert_allclose(y, x[order], rtol=1e-12, atol=1e-9 * np.abs(x).max(), err_msg=f.name)


def test_relative_twists_are_the_dense_twists_difference(robot, camera):
    """`ChainDerivatives.relative` (what the camera block multiplies) holds the numbers of twist(frame) -
    twist(viewer) in its columns, and every column it leaves out is exactly 0 there (joints above both), for the joint
    readings and for the chain parameters (joint offsets, the camera's frame, tag mounts)."""
    scenario = synthetic_scenario(robot, camera, n=12, seed=5, offsets="all")
    fit = fit_observations(robot, scenario.obs, FitOptions(free="leg", side="both"))
    block = fit.blocks[0]
    corrections = fit.chain.corrections(fit.solution.values[: len(fit.chain)])
    d = ChainDerivatives(robot, block.q_measured, corrections, fit.chain, [block.viewer], block.tag_ids)
    for key in [tag_key(t) for t in block.tag_ids]:
        for joints, dense in ((True, d.twist_q), (False, d.twist_p)):
            cols, twists = d.relative(key, block.viewer, joints)
            difference = np.swapaxes(dense(key) - dense(block.viewer), 1, 2)  # (S, 6, K)
            assert 0 < len(cols) < difference.shape[2]
            assert np.array_equal(twists, difference[:, :, cols])
            assert not np.any(np.delete(difference, cols, axis=2))
