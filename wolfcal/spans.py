"""One sample per still span of a plain recording: the frames of one still pose averaged.

A recording's camera sees each still pose in many frames (`wolfcal.io.recording.still_spans`). They share the joint
readings and the picture; only the detector's noise differs between them. Averaged, they tell the fit the same:
per tag corner the mean pixel position over the span's frames that saw the tag, how many frames those were, and their
scatter about the mean (what the pixel noise level is estimated from, `fit.solver.estimate_noise`). The span's joint
readings are each joint's median over its frames. The fit then weighs a mean by its frame count (`Block.unit_frames`:
noise sigma / sqrt(n) per corner, the detection error that repeats at one pose as before).

Before averaging, a frame's view of a tag (its four corners) far from the span's other frames (a misdetection) is left
out: spread = its per-axis RMS distance from the span's per-corner median, judged by `SPAN_FRAME_PX` against the
median spread of all such views (views of a tag seen in fewer than three frames of a span are never judged: no
majority to judge them by).

`still_span_observations` is the one place that decides which cameras' observations are summarised: the fit, the
evaluation (cross-validation and held-out recordings) and `wolfcal compare` all call it, so that a "sample" means
the same to each of them.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from wolfcal.config import RobotConfig
from wolfcal.observations import HEAD_CAMERA, Observations, SpanFrames
from wolfcal.outliers import SPAN_FRAME_PX, OutlierRule

MIN_JUDGED_FRAMES = 3  # frames of one tag in one span from which a frame's view can be judged against the others


def _group_median(group: np.ndarray, values: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups,) median of `values` (N,) per group (N,) 0..n_groups-1, each group non-empty."""
    order = np.lexsort((values, group))
    counts = np.bincount(group, minlength=n_groups)
    starts = np.cumsum(counts) - counts
    ordered = values[order]
    return 0.5 * (ordered[starts + (counts - 1) // 2] + ordered[starts + counts // 2])


def span_of_samples(obs: Observations) -> np.ndarray:
    """(S,) still span of each sample, 0, 1, ... in time order within each source: samples of one source with the
    same `span_of_sample` >= 0 that follow each other in time share one; any other sample is a span of its own."""
    assert obs.span_of_sample is not None
    codes = {name: k for k, name in enumerate(dict.fromkeys(obs.sources))}  # in order of first appearance
    source = np.array([codes[name] for name in obs.sources], dtype=np.int64)
    order = np.lexsort((obs.stamps_ns, source))
    key, src = obs.span_of_sample[order], source[order]
    new = np.ones(len(order), dtype=bool)
    new[1:] = (key[1:] != key[:-1]) | (src[1:] != src[:-1]) | (key[1:] < 0)
    span = np.empty(len(order), dtype=np.int64)
    span[order] = np.cumsum(new) - 1
    return span


def summarize_spans(obs: Observations, rule: OutlierRule = SPAN_FRAME_PX) -> Observations:
    """Observations with one sample per still span (module docstring), `span_frames` set; `obs` itself when it
    names no spans (a capture file) or every span is one frame. Samples in time order within each source; corners
    ordered by sample, tag and corner."""
    if obs.span_of_sample is None or obs.span_frames is not None or not len(obs.uv):
        return obs
    span = span_of_samples(obs)
    n_spans = int(span.max()) + 1
    if n_spans == obs.n_samples:
        return obs
    # a frame's view judged against the span's other frames of that tag
    _, group = np.unique(np.stack([span[obs.sample_index], obs.tag_ids, obs.corner_index], axis=1), axis=0,
                         return_inverse=True)  # fmt: skip
    group = group.ravel()
    n_groups = int(group.max()) + 1
    median = np.stack([_group_median(group, obs.uv[:, a], n_groups) for a in range(2)], axis=1)
    labels, view = obs.views()
    squared = np.bincount(view, np.sum((obs.uv - median[group]) ** 2, axis=1), len(labels))
    spread = np.sqrt(squared / (2 * np.bincount(view, minlength=len(labels))))
    frames_seen = np.bincount(group, minlength=n_groups)
    judged = np.zeros(len(labels), dtype=bool)
    judged[view] = frames_seen[group] >= MIN_JUDGED_FRAMES
    far = rule.flags(np.where(judged, spread, np.nan))
    keep = ~far[view]
    # the mean of each corner over the frames kept
    _, first_kept, kept_group = np.unique(group[keep], return_index=True, return_inverse=True)
    kept_group = kept_group.ravel()
    n_kept = len(first_kept)
    first = np.flatnonzero(keep)[first_kept]  # a row of each group: its span, tag and corner
    frames = np.bincount(kept_group, minlength=n_kept)
    uv = np.stack([np.bincount(kept_group, obs.uv[keep, a], n_kept) for a in range(2)], axis=1) / frames[:, None]
    deviation = obs.uv[keep] - uv[kept_group]
    scatter = np.stack([np.bincount(kept_group, deviation[:, a] ** 2, n_kept) for a in range(2)], axis=1)
    # the spans that keep a corner, renumbered; their readings (median per joint), first stamp and source
    spans_kept, sample_index = np.unique(span[obs.sample_index[first]], return_inverse=True)
    in_kept = np.isin(span, spans_kept)
    renumber = np.full(n_spans, -1)
    renumber[spans_kept] = np.arange(len(spans_kept))
    member = renumber[span[in_kept]]
    q = np.stack([_group_median(member, obs.q_measured[in_kept, j], len(spans_kept))
                  for j in range(obs.q_measured.shape[1])], axis=1).reshape(len(spans_kept), -1)  # fmt: skip
    stamps = np.full(len(spans_kept), np.iinfo(np.int64).max)
    np.minimum.at(stamps, member, obs.stamps_ns[in_kept])
    a_sample = np.flatnonzero(in_kept)[np.unique(member, return_index=True)[1]]  # its frames share one source
    return Observations(
        joint_names=list(obs.joint_names),
        q_measured=q,
        stamps_ns=stamps,
        sources=[obs.sources[i] for i in a_sample],
        camera=obs.camera,
        sample_index=sample_index.ravel(),
        tag_ids=obs.tag_ids[first],
        corner_index=obs.corner_index[first],
        uv=uv,
        camera_name=obs.camera_name,
        span_frames=SpanFrames(np.bincount(member, minlength=len(spans_kept)), frames, scatter, int(far.sum())),
    )


def still_span_observations(
    config: RobotConfig, observations: Mapping[str, Observations], external_moving: bool = False
) -> dict[str, Observations]:
    """Each camera's frames of plain recordings averaged per still span (`summarize_spans`; capture files' samples
    stay as they are). Not for a camera that sees floor tags (the floor block weighs single frames) nor for an
    external camera with one pose per sample (`external_moving`: --external-moving)."""
    floor_ids = config.floor.tag_ids if config.floor is not None else []
    out = {}
    for name, obs in observations.items():
        moving = name != HEAD_CAMERA and external_moving
        out[name] = obs if moving or np.isin(obs.tag_ids, floor_ids).any() else summarize_spans(obs)
    return out


def sample_count(obs: Observations) -> str:
    """How many samples, in words: 'N sample(s)', or 'N still span(s) of M frames' (`Observations.span_frames`)."""
    if obs.span_frames is None:
        return f"{obs.n_samples} sample(s)"
    return f"{obs.n_samples} still span(s) of {int(obs.span_frames.frames_of_sample.sum())} frames"
