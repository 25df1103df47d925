"""Marker observations for a fit: from the recordings' Markers topic, or from motion-capture files (C3D, Motive /
Vicon CSV) paired in order with the recordings that hold the joint states."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.io.mocap_clock import estimate_offset
from wolfcal.io.mocap_files import read_mocap_file
from wolfcal.io.mocap_samples import marker_samples, match_labels, read_recording
from wolfcal.markers import MarkerObservations


def load_marker_observations(
    config: RobotConfig,
    joint_names: list[str],
    recordings: list[Path],
    mocap_files: list[Path],
    offsets_s: list[float] | None = None,
) -> MarkerObservations:
    """Every still sample of the sources, concatenated; `offsets_s` (one per file) replaces the estimated offsets."""
    if config.markers is None:
        raise WolfcalError(
            f"{config.path}: no 'markers:' in the robot config; motion capture needs the markers "
            "(name, link, xyz) listed there"
        )
    if mocap_files and len(mocap_files) != len(recordings):
        raise WolfcalError(
            f"give one --mocap file per recording of joint states, in the same order ({len(mocap_files)}"
            f" --mocap file(s) for {len(recordings)} recording(s))"
        )
    if offsets_s and len(offsets_s) != len(mocap_files):
        raise WolfcalError("give one --mocap-offset per --mocap file, in the same order")
    parts = []
    for i, recording in enumerate(recordings):
        states, traj = read_recording(Path(recording), config, with_markers=not mocap_files)
        offset = 0.0
        if mocap_files:
            traj = read_mocap_file(Path(mocap_files[i]))
            columns = match_labels(traj, config)[1]
            offset = offsets_s[i] if offsets_s else estimate_offset(traj, columns, states)
        if traj is None:  # a recording read without its markers and no --mocap file: cannot happen (see above)
            raise WolfcalError(f"{recording}: no marker data")
        parts.append(marker_samples(traj, states, config, joint_names, offset))
    return concatenate(parts)


def concatenate(parts: list[MarkerObservations]) -> MarkerObservations:
    """One MarkerObservations of several, samples renumbered, marker columns merged in config order."""
    names = list(dict.fromkeys(n for p in parts for n in p.marker_names))
    sample_index, marker_index, xyz, start = [], [], [], 0
    for p in parts:
        column = np.array([names.index(n) for n in p.marker_names], dtype=int)
        sample_index.append(p.sample_index + start)
        marker_index.append(column[p.marker_index])
        xyz.append(p.xyz)
        start += p.n_samples
    first = parts[0]
    return MarkerObservations(
        joint_names=first.joint_names, q_measured=np.concatenate([p.q_measured for p in parts]),
        stamps_ns=np.concatenate([p.stamps_ns for p in parts]), sources=[s for p in parts for s in p.sources],
        marker_names=names, sample_index=np.concatenate(sample_index), marker_index=np.concatenate(marker_index),
        xyz=np.concatenate(xyz), clock_offsets_s={k: v for p in parts for k, v in p.clock_offsets_s.items()},
        unknown_names=sorted({n for p in parts for n in p.unknown_names}),
    )  # fmt: skip
