"""Observations: tag corners detected in the samples of one or more captures, ready for the estimation problem.

One `Observations` holds what one camera saw: the head camera (`HEAD_CAMERA`) or an external camera of the robot
config (its `name`). One row per detected corner (vectorised over everything): which sample, which tag, which corner
(aruco order: top-left, top-right, bottom-right, bottom-left) and where it was seen, in pixels (OpenCV convention).
A view is one tag in one image (`Observations.views`): the unit the fit leaves out as an outlier and the unit of
the tag-grid metric.

The frames of a plain recording name their still span (`span_of_sample`); `wolfcal.spans.summarize_spans` turns the
frames of each span into one sample whose corners are the means over the frames that saw them (`SpanFrames`: how
many frames and their scatter about the mean, per corner).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.camera.model import CameraModel

HEAD_CAMERA = "head"  # camera name of the robot's own camera (config `camera:`); external cameras use their names


def rms_by(group: np.ndarray, values: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups,) per-axis RMS of vectors (M, D) (pixels: D = 2) grouped by `group` (M,); NaN for empty groups."""
    sq = np.bincount(group, weights=np.sum(values**2, axis=1), minlength=n_groups)
    count = np.bincount(group, minlength=n_groups) * values.shape[1]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(sq / count)


@dataclass
class SpanFrames:
    """The frames behind each sample and corner of observations summarised by still span."""

    frames_of_sample: np.ndarray  # (S,) int frames of each sample (its still span's frames with a tag seen)
    frames: np.ndarray  # (M,) int frames averaged into each corner
    scatter: np.ndarray  # (M, 2) sum of squared deviations of those frames' corners about the mean, per axis [px^2]
    left_out: int = 0  # tag views of single frames left out of their span's mean (far from its other frames)

    def subset(self, samples: np.ndarray, keep: np.ndarray) -> SpanFrames:
        """Of the samples `samples` (indices) and the corners `keep` (M,) bool."""
        return SpanFrames(self.frames_of_sample[samples], self.frames[keep], self.scatter[keep], self.left_out)


@dataclass
class Observations:
    joint_names: list[str]
    q_measured: np.ndarray  # (S, J) encoder readings [rad]
    stamps_ns: np.ndarray  # (S,)
    sources: list[str]  # (S,) capture file of each sample
    camera: CameraModel
    sample_index: np.ndarray  # (M,) int
    tag_ids: np.ndarray  # (M,) int
    corner_index: np.ndarray  # (M,) int in 0..3
    uv: np.ndarray  # (M, 2) detected corner [px]
    camera_name: str = HEAD_CAMERA  # which camera saw these corners
    span_of_sample: np.ndarray | None = None  # (S,) int still span of each frame of a recording, -1: none
    span_frames: SpanFrames | None = None  # set when each sample is a still span's frames averaged

    @classmethod
    def of_views(
        cls,
        joint_names: list[str],
        q_measured: np.ndarray,
        stamps_ns: np.ndarray,
        sources: list[str],
        camera: CameraModel,
        sample: np.ndarray,
        tag_ids: np.ndarray,
        uv: np.ndarray,
        camera_name: str = HEAD_CAMERA,
        span_of_sample: np.ndarray | None = None,
    ) -> Observations:
        """Observations of whole views: view v is tag `tag_ids[v]` in sample `sample[v]` (V,), its four corners
        `uv` (V, 4, 2) [px] in aruco order; the sample fields as in the class."""
        return cls(joint_names, q_measured, stamps_ns, sources, camera, np.repeat(sample, 4), np.repeat(tag_ids, 4),
                   np.tile(np.arange(4), len(sample)), uv.reshape(-1, 2), camera_name, span_of_sample)  # fmt: skip

    @property
    def n_samples(self) -> int:
        return int(self.q_measured.shape[0])

    def views(self) -> tuple[np.ndarray, np.ndarray]:
        """The views (one tag in one image): (V, 2) int rows (sample, tag id), sorted by sample then tag id, and
        the view of each corner (M,)."""
        labels, view_of_corner = np.unique(
            np.stack([self.sample_index, self.tag_ids], axis=1).astype(np.int64), axis=0, return_inverse=True
        )
        return labels.reshape(-1, 2), view_of_corner.ravel()

    def tags_in_sample(self, sample: int) -> list[int]:
        """The ids of the tags detected in one sample (its views), ascending."""
        labels, _ = self.views()
        return [int(t) for t in labels[labels[:, 0] == sample, 1]]

    def tags_by_sample(self) -> list[list[int]]:
        """`tags_in_sample` of every sample at once (one sort of the views, not one per sample)."""
        labels, _ = self.views()
        ends = np.searchsorted(labels[:, 0], np.arange(self.n_samples + 1))
        tags = labels[:, 1].tolist()
        return [tags[a:b] for a, b in zip(ends[:-1], ends[1:])]

    def per_sample_rms(self, values: np.ndarray) -> np.ndarray:
        """(S,) per-axis RMS of per-corner 2-vectors (M, 2) (e.g. pixel residuals), NaN for samples without
        corners."""
        return rms_by(self.sample_index, values, self.n_samples)

    @property
    def observed_tag_ids(self) -> list[int]:
        return sorted(int(t) for t in np.unique(self.tag_ids))

    def subset(self, samples: np.ndarray, tag_ids: list[int] | None = None) -> Observations:
        """The observations of the given sample indices (renumbered 0..len-1), optionally of some tags only."""
        samples = np.asarray(samples, dtype=int)
        remap = np.full(self.n_samples, -1)
        remap[samples] = np.arange(len(samples))
        keep = remap[self.sample_index] >= 0
        if tag_ids is not None:
            keep &= np.isin(self.tag_ids, tag_ids)
        return Observations(
            joint_names=list(self.joint_names),
            q_measured=self.q_measured[samples],
            stamps_ns=self.stamps_ns[samples],
            sources=[self.sources[i] for i in samples],
            camera=self.camera,
            sample_index=remap[self.sample_index[keep]],
            tag_ids=self.tag_ids[keep],
            corner_index=self.corner_index[keep],
            uv=self.uv[keep],
            camera_name=self.camera_name,
            span_of_sample=None if self.span_of_sample is None else self.span_of_sample[samples],
            span_frames=None if self.span_frames is None else self.span_frames.subset(samples, keep),
        )

    def repeated_samples(self) -> int:
        """How many samples show exactly (to the bit) the tags and corners of the sample before them in time, from
        the same file: the same image again, since two exposures never give the same refined corners."""
        order = np.lexsort((self.corner_index, self.tag_ids, self.sample_index))
        ends = np.searchsorted(self.sample_index[order], np.arange(self.n_samples + 1))
        rows = np.column_stack([self.tag_ids[order], self.corner_index[order]]).astype(np.float64)
        rows = np.column_stack([rows, self.uv[order]])
        keys = [rows[a:b].tobytes() for a, b in zip(ends[:-1], ends[1:])]
        by_time = np.argsort(self.stamps_ns, kind="stable")
        return sum(
            1 for a, b in zip(by_time[:-1], by_time[1:])
            if keys[b] and keys[a] == keys[b] and self.sources[a] == self.sources[b]
        )  # fmt: skip

    def only_tags(self, tag_ids: list[int]) -> Observations:
        """The corners of the given tags; samples that see none of them are dropped."""
        seen = np.unique(self.sample_index[np.isin(self.tag_ids, tag_ids)])
        return self.subset(seen, tag_ids)
