"""Line points of field views: what the field block fits, whether read from captures or simulated."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from wolfcal.camera.model import CameraModel


@dataclass(frozen=True)
class FieldObservations:
    """Line points the head camera saw in standing samples, one robot placement per capture file."""

    joint_names: list[str]
    q_measured: np.ndarray  # (S, J) encoder readings [rad]
    stamps_ns: np.ndarray  # (S,)
    sources: list[str]  # (S,) capture file of each sample
    placement: np.ndarray  # (S,) index of the robot's placement (capture file) of each sample
    starts: np.ndarray  # (P, 3) the field pose each placement's search found: x, y [m], yaw [rad]
    camera: CameraModel
    sample_index: np.ndarray  # (M,) sample of each line point
    uv: np.ndarray  # (M, 2) line point [px]
    # (P, 3) where the config places each placement (`field.robot_at` or `field.check_at`); None: not known
    configured: np.ndarray | None = None
    # (P,) the camera pitch correction each placement's search placed the points best with [rad]; None: not searched
    pitches: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        return int(self.q_measured.shape[0])

    def only_points(self, keep: np.ndarray) -> FieldObservations:
        """The line points where keep (M,) is True; samples left without a point are dropped (points renumbered to
        the samples kept)."""
        keep = np.asarray(keep, bool)
        samples = np.unique(self.sample_index[keep])
        renumber = np.full(self.n_samples, -1)
        renumber[samples] = np.arange(len(samples))
        return replace(self, q_measured=self.q_measured[samples], stamps_ns=self.stamps_ns[samples],
                       sources=[self.sources[s] for s in samples], placement=self.placement[samples],
                       sample_index=renumber[self.sample_index[keep]], uv=self.uv[keep])  # fmt: skip

    def only_samples(self, keep: np.ndarray) -> FieldObservations:
        """The samples where keep (S,) is True and their line points, renumbered; placements left without a sample
        are dropped (the others renumbered in order)."""
        keep = np.asarray(keep, bool)
        index = np.cumsum(keep) - 1
        points = keep[self.sample_index]
        placements, placement = np.unique(self.placement[keep], return_inverse=True)
        configured = None if self.configured is None else self.configured[placements]
        pitches = None if self.pitches is None else self.pitches[placements]
        return replace(self, q_measured=self.q_measured[keep], stamps_ns=self.stamps_ns[keep],
                       sources=[s for s, k in zip(self.sources, keep) if k], placement=placement.ravel(),
                       starts=self.starts[placements], sample_index=index[self.sample_index[points]],
                       uv=self.uv[points], configured=configured, pitches=pitches)  # fmt: skip


MAX_POINTS_PER_VIEW = 120  # line points kept per view, spread over what it found


def spread(points: np.ndarray, n: int = MAX_POINTS_PER_VIEW) -> np.ndarray:
    """Indices of at most n of the points (in detection order), evenly spread."""
    if not len(points):
        return np.zeros(0, dtype=int)
    return np.unique(np.linspace(0, len(points) - 1, min(len(points), n)).astype(int))
