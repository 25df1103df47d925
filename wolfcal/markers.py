"""Marker observations: motion-capture marker positions measured in still samples, ready for the estimation problem.

One row per measured marker (vectorised over everything): which sample, which configured marker, and where the
motion-capture system saw it, in its own frame [m]. A marker that was occluded (absent, NaN, or invalid in the file)
has no row in that sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class MarkerObservations:
    joint_names: list[str]
    q_measured: np.ndarray  # (S, J) encoder readings [rad]
    stamps_ns: np.ndarray  # (S,) middle of each still period, on the joint-state recording's clock [ns]
    sources: list[str]  # (S,) the marker source of each sample (recording or mocap file)
    marker_names: list[str]  # configured markers that were measured at least once (columns of marker_index)
    sample_index: np.ndarray  # (M,) int
    marker_index: np.ndarray  # (M,) int into marker_names
    xyz: np.ndarray  # (M, 3) measured position in the motion-capture frame [m]
    clock_offsets_s: dict[str, float] = field(default_factory=dict)  # per mocap file: t_recording = t_file + offset
    unknown_names: list[str] = field(default_factory=list)  # labels in the data that no configured marker has

    @property
    def n_samples(self) -> int:
        return int(self.q_measured.shape[0])

    def markers_in_sample(self, sample: int) -> list[str]:
        """The names of the markers measured in one sample, in column order."""
        return [self.marker_names[k] for k in sorted(self.marker_index[self.sample_index == sample])]

    def subset(self, samples: np.ndarray) -> MarkerObservations:
        """The observations of the given sample indices (renumbered 0..len-1)."""
        samples = np.asarray(samples, dtype=int)
        remap = np.full(self.n_samples, -1)
        remap[samples] = np.arange(len(samples))
        keep = remap[self.sample_index] >= 0
        return MarkerObservations(
            joint_names=list(self.joint_names), q_measured=self.q_measured[samples],
            stamps_ns=self.stamps_ns[samples], sources=[self.sources[i] for i in samples],
            marker_names=list(self.marker_names), sample_index=remap[self.sample_index[keep]],
            marker_index=self.marker_index[keep], xyz=self.xyz[keep], clock_offsets_s=dict(self.clock_offsets_s),
            unknown_names=list(self.unknown_names),
        )  # fmt: skip

    def only_markers(self, names: list[str]) -> MarkerObservations:
        """The rows of the given markers (columns renumbered in `names` order); samples keep their numbers."""
        column = {n: i for i, n in enumerate(names)}
        new = np.array([column.get(n, -1) for n in self.marker_names], dtype=int)
        keep = new[self.marker_index] >= 0
        return MarkerObservations(
            joint_names=list(self.joint_names), q_measured=self.q_measured, stamps_ns=self.stamps_ns,
            sources=list(self.sources), marker_names=list(names), sample_index=self.sample_index[keep],
            marker_index=new[self.marker_index[keep]], xyz=self.xyz[keep],
            clock_offsets_s=dict(self.clock_offsets_s), unknown_names=list(self.unknown_names),
        )  # fmt: skip
