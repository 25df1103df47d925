"""Still spans of a plain ROS 2 recording (written with mcap_ros2, not wolfcal's writer): the reader names each kept
frame's span, one per still pose; a fit's summary of a span holds the mean of its frames' corners, their count and
scatter, the span's median readings; a misdetected frame is left out of its span's mean; a capture file's samples
stay as they are."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from wolfcal.encoders import RAD_PER_TICK
from wolfcal.io.reader import read_capture
from wolfcal.io.recording import still_spans
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.robot.robot import load_robot
from wolfcal.sim.recording import RecordingOptions, simulate_recording
from wolfcal.spans import summarize_spans
from wolfcal.vision.observe import detect_observations

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
POSES = 3


@pytest.fixture(scope="module")
def frames(tmp_path_factory) -> Observations:
    """The head camera's per-frame observations of a recording of POSES still poses (encoders flickering)."""
    robot = load_robot(WOLFGANG)
    path = tmp_path_factory.mktemp("spans") / "recording.mcap"
    simulate_recording(robot, path, POSES, options=RecordingOptions(hold_s=1.5, move_s=0.8, flicker=0.3, seed=4))
    capture = read_capture(path, robot.config)
    return detect_observations(capture.samples, robot, workers=1)[0][HEAD_CAMERA]


def test_still_spans_follow_the_kept_frames_and_the_encoder_tick():
    q = np.zeros(2)
    tick = np.array([RAD_PER_TICK, 0.0])
    readings = [q, q + tick, q, None, q, q + tick, q + 2 * tick, q + 2 * tick, None]
    # a frame left out ends a span; readings two ticks apart start a new one
    assert still_spans(readings) == [0, 0, 0, -1, 1, 1, 2, 2, -1]


def test_each_still_pose_is_one_span_of_consecutive_frames(frames):
    spans = frames.span_of_sample
    assert spans is not None
    order = np.argsort(frames.stamps_ns)
    assert np.all(np.diff(spans[order]) >= 0)  # spans numbered in time order, each a run of frames
    assert 2 <= len(np.unique(spans)) <= POSES  # one per pose in which a tag was seen
    for span in np.unique(spans):
        q = frames.q_measured[spans == span]
        assert np.ptp(q, axis=0).max() <= RAD_PER_TICK + 1e-12  # one still pose: readings within one tick


def test_a_span_summary_is_the_mean_of_its_frames_corners(frames):
    summary = summarize_spans(frames)
    spans = summary.span_frames
    assert spans is not None and summary.n_samples == len(np.unique(frames.span_of_sample)) and spans.left_out == 0
    assert spans.frames_of_sample.sum() == frames.n_samples
    assert len(summary.uv) == len(np.unique(np.stack([frames.span_of_sample[frames.sample_index], frames.tag_ids,
                                                      frames.corner_index], axis=1), axis=0))  # fmt: skip
    for m in range(len(summary.uv)):
        span = int(np.unique(frames.span_of_sample)[summary.sample_index[m]])
        rows = np.flatnonzero((frames.span_of_sample[frames.sample_index] == span)
                              & (frames.tag_ids == summary.tag_ids[m])
                              & (frames.corner_index == summary.corner_index[m]))  # fmt: skip
        seen = frames.uv[rows]
        assert spans.frames[m] == len(rows)
        np.testing.assert_allclose(summary.uv[m], seen.mean(axis=0), rtol=0, atol=1e-9)
        np.testing.assert_allclose(spans.scatter[m], ((seen - seen.mean(axis=0)) ** 2).sum(axis=0), atol=1e-9)
    for k, span in enumerate(np.unique(frames.span_of_sample)):
        mine = frames.span_of_sample == span
        np.testing.assert_array_equal(summary.q_measured[k], np.median(frames.q_measured[mine], axis=0))
        assert summary.stamps_ns[k] == frames.stamps_ns[mine].min()


def test_a_misdetected_frame_is_left_out_of_its_span(frames):
    sample = int(np.flatnonzero(frames.span_of_sample == frames.span_of_sample[0])[3])
    tag = int(frames.tag_ids[frames.sample_index == sample][0])
    bad = (frames.sample_index == sample) & (frames.tag_ids == tag)
    uv = frames.uv.copy()
    uv[bad] += [4.0, -3.0]  # the detector put that tag 5 px off in one frame
    summary = summarize_spans(replace(frames, uv=uv))
    clean = summarize_spans(frames)
    assert summary.span_frames is not None and clean.span_frames is not None
    assert summary.span_frames.left_out == 1
    mine = (summary.sample_index == 0) & (summary.tag_ids == tag)
    assert np.all(summary.span_frames.frames[mine] == clean.span_frames.frames[mine] - 1)
    others = np.flatnonzero((frames.span_of_sample[frames.sample_index] == frames.span_of_sample[0])
                            & (frames.tag_ids == tag) & ~bad)  # fmt: skip
    for m in np.flatnonzero(mine):
        rows = others[frames.corner_index[others] == summary.corner_index[m]]
        np.testing.assert_allclose(summary.uv[m], frames.uv[rows].mean(axis=0), atol=1e-9)
    rest = ~((summary.sample_index == 0) & (summary.tag_ids == tag))
    np.testing.assert_array_equal(summary.uv[rest], clean.uv[rest])


def test_samples_without_spans_stay_as_they_are(frames):
    alone = replace(frames, span_of_sample=np.full(frames.n_samples, -1))
    assert summarize_spans(alone) is alone
