"""A fit of still spans (each still pose's frames averaged, `wolfcal.spans`) against the fit of every frame: still
poses seen in several frames with independent pixel noise of a known level and the same joint readings, the setting
in which the frames' means hold all the frames tell the fit. The pixel noise is estimated from the frames' scatter
about their means."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.sim.observations import synthetic_observations
from wolfcal.sim.scenario import synthetic_scenario
from wolfcal.spans import summarize_spans

FRAMES = 8  # per still pose
NOISE_PX = 0.3  # per frame and axis, above the fit's noise floor


def test_still_spans_fit_as_every_frame_does(robot, camera):
    scenario = synthetic_scenario(robot, camera, n=10, seed=31, offsets="all")
    obs = scenario.obs
    visible = np.zeros((obs.n_samples, len(robot.config.tag_ids)), dtype=bool)
    visible[obs.sample_index, [robot.config.tag_ids.index(t) for t in obs.tag_ids]] = True
    q_true, visible = np.repeat(scenario.q_true, FRAMES, axis=0), np.repeat(visible, FRAMES, axis=0)
    frames = synthetic_observations(robot, camera, scenario.truth, q_true, visible, NOISE_PX,
                                    np.random.default_rng(32))  # fmt: skip
    frames = replace(frames, span_of_sample=np.arange(frames.n_samples) // FRAMES)
    spans = summarize_spans(frames)
    assert spans.n_samples == obs.n_samples and spans.span_frames is not None
    assert np.all(spans.span_frames.frames == FRAMES)
    options = FitOptions(free="leg", side="both")
    every, averaged = fit_observations(robot, frames, options), fit_observations(robot, spans, options)
    sigma = averaged.solution.blocks[0].sigma
    assert sigma == pytest.approx(NOISE_PX, rel=0.1)  # the frames' noise, read from their scatter
    # every frame's fit reads the level lower: it counts the frames' mean about each corner's repeating detection
    # error (none here) among its numbers; its std are smaller by that much
    assert every.solution.blocks[0].sigma < sigma
    std = every.solution.std
    assert np.max(np.abs(averaged.solution.values - every.solution.values) / std) < 0.2
    ratio = averaged.solution.std / std
    assert np.all((ratio > 0.95) & (ratio < 1.25)), ratio
    truth = averaged.params.values_from(scenario.truth)
    assert np.max(np.abs(averaged.solution.values - truth) / averaged.solution.std) < 3.5
