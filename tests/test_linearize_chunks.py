"""A camera block linearised chunk by chunk of samples (bounded memory on long recordings) gives every corner the
numbers of one pass over all samples, for the head camera and for an external camera with two placements."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest
from test_external_fit import WEBCAM, other_robot  # noqa: F401 (fixture)

from wolfcal.fit import camera_block
from wolfcal.fit.pipeline import FitOptions, fit_observations
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
